"""The regression gate on a noisy system: ``boundary:10%`` refits both outcomes' curves from
their runs and declares a regression only when s_R moved beyond the limit with the outcome's
confidence; a baseline measured by bisection is not compared with a statistical boundary."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from pytest_sal import tracking_rate
from pytest_sal.engine.execution.trial_runner import TrialRunner
from pytest_sal.engine.outcomes.outcome import Outcome
from pytest_sal.engine.requirements import Requirement
from pytest_sal.engine.search.requirement_search import SearchSettings, search_outcome
from pytest_sal.history.regression import parse_compare_fail, regressions
from pytest_sal.testing import BernoulliSlam
from sal_adapters import open_dataset
from sal_modules import fog

REQUIREMENT = Requirement.build([tracking_rate >= 0.9, fog.visibility_m >= 25])
CHECK = parse_compare_fail("boundary:10%")


@pytest.fixture(scope="module")
def dataset():  # type: ignore[no-untyped-def]
    return open_dataset("synthetic", scene="indoor", frames=8, sensor="rgbd")


def session(dataset, tmp_path: Path, held: str, seed: int) -> Outcome:  # type: ignore[no-untyped-def]
    """One fresh session (no cache) of a noisy fake that holds with probability ``held(v)``."""
    runner = TrialRunner(dataset, fog.visibility_m.ref(), BernoulliSlam(held=held, seed=seed), REQUIREMENT, workdir=tmp_path / str(seed))
    return search_outcome(runner, REQUIREMENT, SearchSettings(), "test_fog")


def test_an_unchanged_noisy_system_passes_the_gate_and_one_whose_s80_doubled_is_caught(dataset, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    # below 20 m half the runs initialise late; from 20 m on every run holds: s80 = 20 m
    baseline = session(dataset, tmp_path, "1 if v >= 20 else 0.5", 0)
    assert baseline.boundary.noisy and baseline.verdict == "passed"
    for seed in (1, 2):
        assert regressions([CHECK], session(dataset, tmp_path, "1 if v >= 20 else 0.5", seed), baseline) == []
    # the same system now needs 40 m: s80 moved toward the mild side by about 100 %
    worse = session(dataset, tmp_path, "1 if v >= 40 else 0.5", 3)
    (message,) = regressions([CHECK], worse, baseline)
    assert message.startswith("fog.visibility_m s80 moved toward the mild side by more than 10 % with probability ")
    assert f"({baseline.boundary.runs} runs), now" in message
    # a limit wider than the move is not exceeded
    assert regressions([parse_compare_fail("boundary:300%")], worse, baseline) == []


def test_a_bisected_baseline_is_not_compared_with_a_statistical_boundary(dataset, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    noisy = session(dataset, tmp_path, "1 if v >= 20 else 0.5", 0)
    old = dataclasses.replace(noisy, boundary=dataclasses.replace(noisy.boundary, reliability=None, confidence=None), verdict="flaky")
    (message,) = regressions([CHECK], noisy, old)
    assert message.startswith(
        "not compared: the baseline's fog.visibility_m boundary is a bisection's failure point, this run's is statistical"
    )
    assert message.endswith("save a new baseline with --sal-save")
    # the old outcome still reads back from its JSON (history written before)
    again = Outcome.from_dict(old.to_dict())
    assert again.verdict == "flaky" and not again.boundary.noisy


def test_a_noisy_outcome_round_trips_through_json_with_its_statistical_boundary(dataset, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    outcome = session(dataset, tmp_path, "1 if v >= 20 else 0.5", 0)
    data = outcome.to_dict()
    for key in ("estimate", "bound", "interval", "reliability", "confidence", "runs"):
        assert data["boundary"][key] is not None
    assert data["boundary"]["runs"] == sum(len(t["runs"]) for t in data["trials"])
    again = Outcome.from_dict(data)
    assert again.boundary == outcome.boundary and again.boundary.text() == outcome.boundary.text()
    assert regressions([CHECK], again, outcome) == []
