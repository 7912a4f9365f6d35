"""TrialRunner on its own: metrics aggregated over runs, the cache, perturbed frames cached once."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from pytest_sal import tracking_rate
from pytest_sal.cache import ContentCache
from pytest_sal.requirements import Requirement
from pytest_sal.testing import FakeSlam, applied_value
from pytest_sal.trials import TrialRunner, aggregate_metrics, cached_sequence
from sal_adapters import open_dataset
from sal_modules import create, fog, perturb


def runner(tmp_path: Path, system: FakeSlam, **options) -> TrialRunner:
    dataset = open_dataset("synthetic", scene="indoor", frames=8, sensor="rgbd")
    requirement = Requirement.build([tracking_rate >= 0.5, fog.visibility_m >= 25])
    cache = ContentCache(tmp_path / "cache")
    return TrialRunner(dataset, fog.visibility_m.ref(), system, requirement, cache=cache, workdir=tmp_path / "work", **options)


def test_median_over_runs_and_a_metric_missing_in_most_runs_is_missing() -> None:
    runs = [{"ate_rmse": 1.0, "tracking_rate": 0.5}, {"ate_rmse": 3.0, "tracking_rate": None}, {"ate_rmse": 2.0, "tracking_rate": None, "failure": "killed by SIGSEGV"}]
    metrics = aggregate_metrics(runs)
    assert metrics["ate_rmse"] == 2.0 and metrics["tracking_rate"] is None
    assert metrics["failures"] == ["killed by SIGSEGV"]


def test_a_trial_is_judged_and_read_back_from_the_cache(tmp_path: Path) -> None:
    calls = tmp_path / "calls.jsonl"
    first = runner(tmp_path, FakeSlam(calls_file=str(calls))).evaluate(20.0)
    assert first.metrics["tracking_rate"] == 0.5 and first.passed and not first.cached  # round(8 * 20/40) = 4 of 8
    again = runner(tmp_path, FakeSlam(calls_file=str(calls))).evaluate(20.0)
    assert again.cached and again.metrics == first.metrics
    assert len(calls.read_text().splitlines()) == 1  # one SLAM run for both
    other = runner(tmp_path, FakeSlam(tracked="min(1, v / 80)", calls_file=str(calls))).evaluate(20.0)
    assert not other.cached and not other.passed  # another system is another trial


def test_perturbed_frames_are_cached_once_and_read_back_identical(tmp_path: Path) -> None:
    clean = open_dataset("synthetic", scene="indoor", frames=6, sensor="rgbd")
    foggy = perturb(clean, create("fog", visibility_m=4.0), seed=3)
    cache = ContentCache(tmp_path / "cache")
    copy = cached_sequence(foggy, cache)
    assert cache.stats()["folders"] == 1 and len(copy) == len(foggy)
    for k in (0, 5):
        np.testing.assert_array_equal(copy[k].image, foggy[k].image)
        np.testing.assert_allclose(copy[k].depth, foggy[k].depth, atol=1e-6)
    assert applied_value(copy, "fog.visibility_m") == 4.0 and copy.groundtruth_is_per_frame
    cached_sequence(foggy, cache)
    assert cache.stats()["folders"] == 1  # the second system reads the same folder


def test_cache_frames_gives_systems_the_stored_copy(tmp_path: Path) -> None:
    calls = tmp_path / "calls.jsonl"
    for tracked in ("min(1, v / 40)", "min(1, v / 80)"):  # two systems, one perturbed copy
        trial = runner(tmp_path, FakeSlam(tracked=tracked, calls_file=str(calls)), cache_frames=True).evaluate(30.0)
        assert not trial.cached
    assert [json.loads(line)["value"] for line in calls.read_text().splitlines()] == [30.0, 30.0]
    assert ContentCache(tmp_path / "cache").stats()["folders"] == 1
