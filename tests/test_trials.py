"""TrialRunner on its own: metrics aggregated over runs, the cache, perturbed frames cached once."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from pytest_sal import tracking_rate
from pytest_sal.engine.execution.run_job import cached_sequence
from pytest_sal.engine.execution.trial_runner import TrialRunner
from pytest_sal.engine.outcomes.outcome import Trial, TrialMetrics
from pytest_sal.engine.requirements import Requirement
from pytest_sal.store.content_cache import ContentCache
from pytest_sal.testing import FakeSlam, applied_value
from sal_adapters import open_dataset
from sal_modules import create, fog, perturb


def runner(tmp_path: Path, system: FakeSlam, **options) -> TrialRunner:
    dataset = open_dataset("synthetic", scene="indoor", frames=8, sensor="rgbd")
    requirement = Requirement.build([tracking_rate >= 0.5, fog.visibility_m >= 25])
    cache = ContentCache(tmp_path / "cache")
    return TrialRunner(dataset, fog.visibility_m.ref(), system, requirement, cache=cache, workdir=tmp_path / "work", **options)


def test_median_over_runs_and_a_metric_missing_in_most_runs_is_missing() -> None:
    runs = [
        {"ate_rmse": 1.0, "tracking_rate": 0.5},
        {"ate_rmse": 3.0, "tracking_rate": None},
        {"ate_rmse": 2.0, "tracking_rate": None, "failure": "killed by SIGSEGV"},
    ]
    metrics = TrialMetrics.of(runs)
    assert metrics["ate_rmse"] == 2.0 and metrics["tracking_rate"] is None
    assert metrics["failures"] == ["killed by SIGSEGV"]


def test_a_trial_is_judged_and_read_back_from_the_cache(tmp_path: Path) -> None:
    calls = tmp_path / "calls.jsonl"
    first = runner(tmp_path, FakeSlam(calls_file=str(calls))).run_trial(20.0)
    assert first.metrics["tracking_rate"] == 0.5 and first.passed and not first.cached  # round(8 * 20/40) = 4 of 8
    assert len(first.runs) == 1  # a deterministic system: one run a trial
    again = runner(tmp_path, FakeSlam(calls_file=str(calls))).run_trial(20.0)
    assert again.cached and again.metrics == first.metrics
    assert len(calls.read_text().splitlines()) == 1  # one SLAM run for both
    other = runner(tmp_path, FakeSlam(tracked="min(1, v / 80)", calls_file=str(calls))).run_trial(20.0)
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
        trial = runner(tmp_path, FakeSlam(tracked=tracked, calls_file=str(calls)), cache_frames=True).run_trial(30.0)
        assert not trial.cached
    assert [json.loads(line)["value"] for line in calls.read_text().splitlines()] == [30.0, 30.0]
    assert ContentCache(tmp_path / "cache").stats()["folders"] == 1


def test_a_noisy_systems_runs_are_added_one_by_one_and_read_back(tmp_path: Path) -> None:
    # the flaky fake alternates 0.5 and 0.5 + 0.3 tracked at 20 m: against tracking_rate >= 0.6
    # its runs fail, pass, fail, pass, ...; the trial's verdict is their majority
    calls = tmp_path / "calls.jsonl"
    noisy = runner(tmp_path, FakeSlam(flaky=0.3, calls_file=str(calls)))
    noisy.requirement = Requirement.build([tracking_rate >= 0.6, fog.visibility_m >= 25])
    assert noisy.policy.noisy and noisy.policy.max_runs == 5
    trial = Trial(value=20.0, passed=False)
    added = [run for _ in range(5) for run in noisy.add_runs(trial, 1)]  # one at a time: the fake alternates by its run count
    assert [r["passed"] for r in added] == [r["passed"] for r in trial.runs] == [False, True, False, True, False]
    assert not trial.passed and trial.votes() == "3 of 5 runs failed" and not trial.cached
    # each run is its own cache entry: another session reads all five back, together
    again = runner(tmp_path, FakeSlam(flaky=0.3, calls_file=str(calls)))
    again.requirement = noisy.requirement
    before = len(calls.read_text().splitlines())
    reread = Trial(value=20.0, passed=False)
    again.add_runs(reread, 5)
    assert reread.cached and [r["passed"] for r in reread.runs] == [False, True, False, True, False]
    assert len(calls.read_text().splitlines()) == before


def test_a_starved_run_does_not_vote_against_the_system(tmp_path: Path) -> None:
    from sal_wrappers import RunResult

    class Starved(FakeSlam):
        """Every other run falls behind the sensor clock and tracks nothing."""

        def run(self, sequence, workdir, timeout=None):  # type: ignore[no-untyped-def]
            result = super().run(sequence, workdir, timeout)
            if self._runs % 2:
                data = result.to_dict()
                data.update(states=["lost"] * len(result.states), trajectory=None, fell_behind=True)
                return RunResult.from_dict(data)
            return result

    starved = runner(tmp_path, Starved(tracked="1"))
    trial = Trial(value=40.0, passed=False)
    for _ in range(4):  # one at a time: the fake starves every other run by its run count
        starved.add_runs(trial, 1)
    assert [r["abstained"] for r in trial.runs] == [True, False, True, False]  # runs 1 and 3 were starved
    assert trial.passed and trial.passes == 2 and trial.fails == 0 and trial.abstained == 2
    assert trial.votes() == "2 of 2 runs passed (2 starved by the machine, not counted)"


def test_an_edge_that_leaves_the_dataset_unchanged_is_refused_before_any_run(tmp_path: Path) -> None:
    # fog at 100 km in a room (depths under 10 m): 255 x (1 - exp(-3.912 x 10 / 1e5)) = 0.1 grey levels
    import pytest

    from pytest_sal.engine.requirements import InvalidRequirement
    from pytest_sal.engine.search.requirement_search import SearchSettings, search_outcome

    calls = tmp_path / "calls.jsonl"
    room = runner(tmp_path, FakeSlam(calls_file=str(calls)))
    requirement = Requirement.build([tracking_rate >= 0.5, fog.visibility_m >= 100_000])
    with pytest.raises(
        InvalidRequirement, match=r"fog.visibility_m >= 100000 m: the envelope's edge leaves the frames of .* unchanged \(frames 0, 4, 7"
    ):
        search_outcome(room, requirement, SearchSettings(), "test_room")
    assert not calls.exists()
    assert room.unchanged_frames(25.0) is None  # 25 m fog does change the room


def test_the_kitti_segments_key_the_run_and_score_t_rel(tmp_path: Path) -> None:
    short = runner(tmp_path, FakeSlam(), kitti_segments=(0.02,))
    assert short.key(40.0) != runner(tmp_path, FakeSlam()).key(40.0)  # another scoring is another run record
    trial = short.run_trial(40.0)  # every frame tracked, poses from the ground truth
    assert trial.metrics["t_rel"] < 1e-6 and trial.metrics["r_rel"] < 1e-6 and trial.metrics["kitti_missing"] is None
    default = runner(tmp_path, FakeSlam()).run_trial(40.0)
    assert default.metrics["t_rel"] is None and "too short for a segment of 100 m" in default.metrics["kitti_missing"]


def test_each_value_builds_and_validates_its_module_once(tmp_path: Path, monkeypatch) -> None:
    """The cache keys of its runs, their jobs and the unchanged-frames check share the module at a value."""
    from pytest_sal.engine.search.requirement_search import SearchSettings, search_outcome

    param_ref = type(fog.visibility_m.ref())  # the class, wherever it lives
    room, noisy = runner(tmp_path, FakeSlam()), runner(tmp_path, FakeSlam(), runs=3)  # Requirement.build checks its edge
    built: list[float] = []
    build = param_ref.module

    def counted(ref, value: float):
        built.append(value)
        return build(ref, value)

    monkeypatch.setattr(param_ref, "module", counted)
    outcome = search_outcome(room, room.requirement, SearchSettings(max_trials=4), "test_room")
    assert built == [t.value for t in outcome.trials] and len(outcome.trials) == 4  # the edge first: checked, keyed, run
    built.clear()
    noisy.add_runs(Trial(value=30.0, passed=False), 3)  # three runs at once, each with its key
    assert noisy.cached(30.0) and built == [30.0]
