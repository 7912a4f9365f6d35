"""Early stop: ``StopRule`` decides exactly when a run's requirement can no longer hold, and the
trial runner keeps stopped runs apart in the cache (a fake system; real frames are in
test_early_stop_real.py and test_early_stop_orbslam3.py)."""

from __future__ import annotations

import dataclasses
import itertools
import json
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pytest_sal import ate_rmse, tracking_rate
from pytest_sal.engine.execution.early_stop import StopRule
from pytest_sal.engine.execution.trial_runner import TrialRunner
from pytest_sal.engine.outcomes.outcome import Trial
from pytest_sal.engine.requirements import Requirement
from pytest_sal.report.formatting import trial_line
from pytest_sal.store.content_cache import ContentCache
from pytest_sal.testing import FakeSlam
from sal_adapters import Sequence, open_dataset
from sal_wrappers import RunResult, TrackState
from sal_wrappers.base import StopCheck

OK, LOST, NOT_INIT = TrackState.OK, TrackState.LOST, TrackState.NOT_INITIALISED


def rule(*criteria: Any) -> StopRule:
    made = StopRule.of(Requirement.build(list(criteria)))
    assert made is not None
    return made


def states(*runs: tuple[TrackState, int]) -> np.ndarray:
    """``states((OK, 25), (LOST, 15))``: runs of one state, in order."""
    return np.concatenate([np.zeros(0, np.int8), *(np.full(count, state, np.int8) for state, count in runs)])


# -- the rule ----------------------------------------------------------------------------------
def test_at_the_exact_bound_126_of_140_still_holds_and_125_does_not() -> None:
    at_least = rule(tracking_rate >= 0.9)
    assert at_least.check(states((OK, 26), (LOST, 14)), 140) is None  # 126/140 = 0.9 is still possible
    assert at_least.check(states((OK, 25), (LOST, 15)), 140) == (
        "tracking_rate >= 0.9 can no longer hold: 15 of 140 frames not tracked by frame 40 (0.8929 at best)"
    )
    # the full runs agree: RunResult's rate and the criterion
    for tracked, holds in ((126, True), (125, False)):
        result = RunResult("s", "q", "mono", np.arange(140) / 10, states((OK, tracked), (LOST, 140 - tracked)))
        assert Requirement.build([tracking_rate >= 0.9]).holds({"tracking_rate": result.tracking_rate}) is holds


def test_a_strict_bound_stops_one_frame_earlier() -> None:
    above = rule(tracking_rate > 0.9)
    assert above.check(states((OK, 26), (LOST, 13)), 140) is None  # 127/140 > 0.9 is still possible
    assert above.check(states((OK, 26), (LOST, 14)), 140) is not None  # 126/140 = 0.9 is not above


def test_a_system_that_never_initialises_stops_when_too_few_frames_are_left() -> None:
    at_least = rule(tracking_rate >= 0.9)
    assert at_least.check(states((NOT_INIT, 14)), 140) is None
    assert at_least.check(states((NOT_INIT, 15)), 140) == (
        "tracking_rate >= 0.9 can no longer hold: not initialised by frame 15 of 140 (0.8929 at best)"
    )


def test_an_upper_bound_stops_once_too_many_frames_were_tracked() -> None:
    at_most = rule(tracking_rate <= 0.5)
    assert at_most.check(states((OK, 70), (LOST, 10)), 140) is None
    assert at_most.check(states((OK, 71), (LOST, 9)), 140) == (
        "tracking_rate <= 0.5 can no longer hold: 71 of 140 frames tracked by frame 80 (0.5071 at least)"
    )


def test_the_rule_decides_exactly_what_every_completion_of_the_run_would() -> None:
    """For every prefix of every run of up to 7 frames: the rule stops iff no way of going on
    meets the criterion (the full run's verdict, by RunResult.tracking_rate and Criterion.holds)."""
    for criterion in (tracking_rate >= 0.6, tracking_rate > 0.5, tracking_rate <= 0.4, tracking_rate < 0.75):
        stop = rule(criterion)
        for frames in range(1, 8):
            for seen in range(frames + 1):
                for prefix in itertools.product((OK, LOST), repeat=seen):
                    ends = itertools.product((OK, LOST), repeat=frames - seen)
                    verdicts = {
                        criterion.holds(
                            {"tracking_rate": RunResult("s", "q", "mono", np.arange(frames), np.array([*prefix, *end])).tracking_rate}
                        )
                        for end in ends
                    }
                    assert (stop.check(np.array(prefix, np.int8), frames) is not None) == (verdicts == {False}), (criterion, prefix, frames)


def test_only_tracking_rate_makes_a_rule_and_its_key_ignores_the_other_criteria() -> None:
    assert StopRule.of(Requirement.build([ate_rmse < 1.5])) is None
    both = rule(ate_rmse < 1.5, tracking_rate >= 0.9)
    assert both.key() == [["tracking_rate", ">=", 0.9]] == rule(ate_rmse < 0.1, tracking_rate >= 0.9).key()
    assert rule(tracking_rate >= 0.5).key() != both.key()
    assert str(both) == "tracking_rate >= 0.9"


def test_a_conjunction_stops_on_its_first_hopeless_criterion() -> None:
    window = rule(tracking_rate >= 0.25, tracking_rate <= 0.75)
    assert window.check(states((OK, 3), (LOST, 3)), 8) is None  # 3/8 .. 5/8 is still inside
    assert window.check(states((OK, 7)), 8).startswith("tracking_rate <= 0.75 can no longer hold")  # type: ignore[union-attr]
    assert window.check(states((LOST, 7)), 8).startswith("tracking_rate >= 0.25 can no longer hold")  # type: ignore[union-attr]


def test_a_rule_pickles_and_is_the_stop_callable_systems_take() -> None:
    at_least: StopCheck = pickle.loads(pickle.dumps(rule(tracking_rate >= 0.9)))
    assert at_least(states((LOST, 15)), 140) == rule(tracking_rate >= 0.9).check(states((LOST, 15)), 140)
    assert at_least(states(), 140) is None and at_least(states(), 0) is None


# -- the run result and the trial line ----------------------------------------------------------
def test_a_stopped_run_result_round_trips_and_old_records_read_as_not_stopped() -> None:
    stopped = RunResult("s", "q", "mono", np.arange(4) / 10, states((OK, 1), (LOST, 3)), stopped="why")
    back = RunResult.from_json(stopped.to_json())
    assert back.stopped == "why" and back.failure is None and back.ok
    assert back.summary().endswith("; STOPPED early: why")
    old = stopped.to_dict()
    del old["stopped"]
    assert RunResult.from_dict(old).stopped is None


def test_the_trial_line_says_why_runs_were_stopped() -> None:
    runs: list[dict[str, Any]] = [{"passed": False, "stopped": "tracking_rate >= 0.9 can no longer hold: x"}, {"passed": False}]
    trial = Trial(value=20.0, passed=False, runs=runs, wall_time_s=1.0)
    line = trial_line(trial, "fog.visibility_m", "m", ["tracking_rate"])
    assert line.endswith("1.0 s  stopped early (1 of 2 runs): tracking_rate >= 0.9 can no longer hold: x")
    assert "stopped" not in trial_line(Trial(value=20.0, passed=True, runs=[{"passed": True}]), "fog.visibility_m", "m", [])


# -- the trial runner and the cache --------------------------------------------------------------
class StoppableFake(FakeSlam):
    """``FakeSlam`` that honours ``stop`` frame by frame (the frames after the stop are LOST
    already: it tracks the first frames only)."""

    stoppable = True

    def run(self, sequence: Sequence, workdir: Path, timeout: float | None = None, stop: StopCheck | None = None) -> RunResult:
        result = super().run(sequence, workdir, timeout)
        for seen in range(1, result.frames if stop is not None else 0):
            if stop is not None and (reason := stop(result.states[:seen], result.frames)) is not None:
                return dataclasses.replace(result, stopped=reason)
        return result


def runner(tmp_path: Path, criterion: Any, system: FakeSlam, **options: Any) -> TrialRunner:
    from sal_modules import fog

    dataset = open_dataset("synthetic", scene="indoor", frames=8, sensor="rgbd")
    requirement = Requirement.build([criterion, fog.visibility_m >= 25])
    cache = ContentCache(tmp_path / "cache")
    return TrialRunner(dataset, fog.visibility_m.ref(), system, requirement, cache=cache, workdir=tmp_path / "work", **options)


def calls(path: Path) -> int:
    return len(path.read_text().splitlines()) if path.exists() else 0


def test_a_stopped_run_is_recorded_and_kept_apart_from_full_runs_in_the_cache(tmp_path: Path) -> None:
    log = tmp_path / "calls.jsonl"
    strict = runner(tmp_path, tracking_rate >= 0.9, StoppableFake(calls_file=str(log)))
    trial = strict.run_trial(20.0)  # tracks 4 of 8: the 5th frame decides
    assert not trial.passed and trial.failed == ["tracking_rate >= 0.9"]
    assert trial.runs[0]["stopped"] == "tracking_rate >= 0.9 can no longer hold: 1 of 8 frames not tracked by frame 5 (0.875 at best)"
    assert strict.cache.get(strict.key(20.0)) is None  # type: ignore[union-attr]  # not under the full run's key
    assert strict.cache.get(strict.key(20.0, stop=strict.stop_rule))["metrics"]["stopped"]  # type: ignore[union-attr,index]
    # a milder rule does not read the stopped run: it runs, finishes, and stores under the full key
    mild = runner(tmp_path, tracking_rate >= 0.5, StoppableFake(calls_file=str(log)))
    milder = mild.run_trial(20.0)
    assert milder.passed and not milder.cached and "stopped" not in milder.runs[0] and calls(log) == 2
    assert mild.cache.get(mild.key(20.0))["metrics"]["tracking_rate"] == 0.5  # type: ignore[union-attr,index]
    # now the strict rule finds the full run first: read back, not stopped, still failed
    again = runner(tmp_path, tracking_rate >= 0.9, StoppableFake(calls_file=str(log))).run_trial(20.0)
    assert again.cached and not again.passed and "stopped" not in again.runs[0] and calls(log) == 2


def test_a_failed_tests_message_says_its_edge_runs_were_stopped(tmp_path: Path) -> None:
    """The metrics of a stopped run cover the frames it ran: the failure message says so."""
    from pytest_sal.engine.search.requirement_search import SearchSettings, failure_message, search_outcome

    strict = runner(tmp_path, tracking_rate >= 0.9, StoppableFake(calls_file=str(tmp_path / "calls.jsonl")))
    outcome = search_outcome(strict, strict.requirement, SearchSettings(max_trials=3), "test_x")
    message = failure_message(outcome)
    assert outcome.verdict == "failed"
    assert "failed: tracking_rate >= 0.9; 1 of 1 run(s) stopped early: tracking_rate >= 0.9 can no longer hold: 1 of 8 frames" in message


def test_the_same_rule_reads_its_stopped_run_back(tmp_path: Path) -> None:
    log = tmp_path / "calls.jsonl"
    first = runner(tmp_path, tracking_rate >= 0.9, StoppableFake(calls_file=str(log))).run_trial(20.0)
    # another requirement with the same tracking criterion: the same rule, the same stopped run
    second = runner(tmp_path, tracking_rate >= 0.9, StoppableFake(calls_file=str(log))).run_trial(20.0)
    assert second.cached and second.runs[0]["stopped"] == first.runs[0]["stopped"] and calls(log) == 1


def test_full_run_keys_are_unchanged_and_early_stop_can_be_turned_off(tmp_path: Path) -> None:
    log = tmp_path / "calls.jsonl"
    on = runner(tmp_path, tracking_rate >= 0.9, StoppableFake(calls_file=str(log)))
    off = runner(tmp_path, tracking_rate >= 0.9, StoppableFake(calls_file=str(log)), early_stop=False)
    plain = runner(tmp_path, tracking_rate >= 0.9, FakeSlam(calls_file=str(log)))  # cannot stop: never given a rule
    assert on.key(20.0) == off.key(20.0) and off.stop_rule is None and plain.stop_rule is None
    assert on.key(20.0, stop=on.stop_rule) != on.key(20.0)
    full = off.run_trial(20.0)
    assert not full.passed and "stopped" not in full.runs[0] and full.metrics["tracking_rate"] == 0.5
    assert off.cache.get(off.key(20.0)) is not None  # type: ignore[union-attr]
    assert "stopped" not in plain.run_trial(30.0).runs[0]


def test_without_a_cache_the_rule_still_stops(tmp_path: Path) -> None:
    strict = runner(tmp_path, tracking_rate >= 0.9, StoppableFake())
    strict.cache = None
    assert strict.run_trial(20.0).runs[0]["stopped"].startswith("tracking_rate >= 0.9 can no longer hold")


def test_records_say_stopped_only_when_stopped(tmp_path: Path) -> None:
    strict = runner(tmp_path, tracking_rate >= 0.9, StoppableFake())
    assert "stopped" not in strict.run_trial(40.0).runs[0]  # tracks all 8: never stopped
    stored = json.dumps(strict.cache.get(strict.key(40.0)))  # type: ignore[union-attr]
    assert '"stopped"' not in stored


@pytest.mark.parametrize("value", ["false", "no", "0", "off"])
def test_ini_sal_early_stop_false_turns_it_off(pytester: pytest.Pytester, value: str) -> None:
    pytester.makeini(f"[pytest]\nsal_early_stop = {value}\n")
    config = pytester.parseconfig()
    from pytest_sal.options import read_options

    assert read_options(config).early_stop is False


def test_the_option_and_a_bad_ini_value(pytester: pytest.Pytester) -> None:
    from pytest_sal.options import read_options

    assert read_options(pytester.parseconfig()).early_stop is True
    assert read_options(pytester.parseconfig("--sal-no-early-stop")).early_stop is False
    pytester.makeini("[pytest]\nsal_early_stop = maybe\n")
    with pytest.raises(pytest.UsageError, match=r"ini option sal_early_stop = 'maybe': expected true or false"):
        read_options(pytester.parseconfig())
