"""The plugin and the run history end to end (inner pytest sessions on ``FakeSlam``, with and
without ``-n 2``): each session appends one run, the next search starts from the previous
boundary (three trials for an unchanged system), ``--sal-compare-fail`` fails a test whose
boundary regressed and no other, and ``sal history`` lists the tests."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from plugin_suites import (
    MODES,
    calls,
    check_all,
    check_bracket,
    has_line,
    outcomes,
    predicted,
    project,
    run,
    write_tracked,
)

from pytest_sal.cli import main as cli

HISTORY_TESTS = """

@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 30, tolerance=1, max_trials=10)
def test_worse(sal_outcome):
    pass


@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 30, tolerance=1, max_trials=10)
def test_better(sal_outcome):
    pass


@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 30, tolerance=1, max_trials=10)
def test_same(sal_outcome):
    pass
"""

NAMES = ("test_worse", "test_better", "test_same")


def runs_saved(pytester: pytest.Pytester) -> list[str]:
    folder = pytester.path / "history"
    return sorted(p.name for p in folder.glob("*.json")) if folder.is_dir() else []


@dataclass
class HistorySessions:
    """Five inner sessions on one history folder and what each left: run 1 cold, run 2 warm
    (``--sal-save=main``), run 3 with one fake worse, one better (``--sal-compare``), the same
    commit against main and against 'last'; then ``sal history`` on the folder."""

    first: pytest.RunResult
    cold: dict[str, Any]
    saved_after_first: list[str]
    first_run_file: dict[str, Any]
    second: pytest.RunResult
    second_slam_runs: int
    warm: dict[str, Any]
    saved_after_second: list[str]
    third: pytest.RunResult
    compared: dict[str, Any]
    saved_after_third: list[str]
    again: list[tuple[pytest.RunResult, dict[str, Any]]]
    saved_after_again: list[str]
    listing: tuple[int, str]
    trend: tuple[int, str]
    plot: Path


def run_sessions(pytester: pytest.Pytester, mode: list[str], capsys: pytest.CaptureFixture[str]) -> HistorySessions:
    project(pytester, HISTORY_TESTS, {name: "min(1, v / 40)" for name in NAMES})
    first = run(pytester, mode, "--junitxml=first.xml")  # one run file, written by the controller only under xdist
    saved_after_first = runs_saved(pytester)
    first_run_file = json.loads((pytester.path / "history" / saved_after_first[0]).read_text()) if saved_after_first else {}
    before = calls(pytester)
    second = run(pytester, mode, "--sal-no-cache", "--junitxml=second.xml", "--sal-save=main")  # SLAM runs again
    second_slam_runs = calls(pytester) - before
    saved_after_second = runs_saved(pytester)
    # one fake gets worse (boundary 23.75 m), one better (14.25 m), one is unchanged
    write_tracked(pytester, {"test_worse": "min(1, v / 50)", "test_better": "min(1, v / 30)", "test_same": "min(1, v / 40)"})
    third = run(pytester, mode, "-v", "--sal-compare", "--sal-compare-fail=boundary:10%", "--junitxml=third.xml")
    saved_after_third = runs_saved(pytester)
    again = []
    for ref in ("", "=last"):
        result = run(pytester, mode, f"--sal-compare{ref}", "--sal-compare-fail=boundary:10%", "--sal-save=main", "--junitxml=again.xml")
        again.append((result, outcomes(pytester.path / "again.xml")))
    saved_after_again = runs_saved(pytester)
    capsys.readouterr()
    listing = cli.main(["history", "--history-dir", str(pytester.path / "history")]), capsys.readouterr().out
    plot = pytester.path / "worse.png"
    trend = cli.main(["history", "test_worse", "--history-dir", str(pytester.path / "history"), "-o", str(plot)]), capsys.readouterr().out
    return HistorySessions(
        first,
        outcomes(pytester.path / "first.xml"),
        saved_after_first,
        first_run_file,
        second,
        second_slam_runs,
        outcomes(pytester.path / "second.xml"),
        saved_after_second,
        third,
        outcomes(pytester.path / "third.xml"),
        saved_after_third,
        again,
        saved_after_again,
        listing,
        trend,
        plot,
    )


@pytest.mark.parametrize("mode", MODES)
def test_history_warm_start_and_compare_fail(pytester: pytest.Pytester, mode: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    sessions = run_sessions(pytester, mode, capsys)
    check_all(
        {
            "run 1: cold searches, one run file": lambda: check_cold_run(sessions),
            "run 2: the previous boundary still brackets, 3 trials each": lambda: check_warm_run(sessions),
            "run 3: --sal-compare-fail fails the regressed test only": lambda: check_compared_run(sessions),
            "run 3: the failure says what regressed": lambda: check_regression_message(sessions),
            "runs 4-5: the regressed commit cannot pass the gate, nor take the name main": lambda: check_reruns(sessions),
            "sal history lists every test and plots one": lambda: check_history_command(sessions),
        }
    )


def check_cold_run(sessions: HistorySessions) -> None:
    sessions.first.assert_outcomes(passed=3)
    assert len(sessions.saved_after_first) == 1
    for outcome in sessions.cold.values():
        check_bracket(outcome, predicted(), tolerance=1)  # from 19 m on
        assert len(outcome["trials"]) > 3
    assert sorted(o["test_id"] for o in sessions.first_run_file["outcomes"]) == sorted(f"test_suite.py::{n}" for n in NAMES)


def check_warm_run(sessions: HistorySessions) -> None:
    sessions.second.assert_outcomes(passed=3)
    assert sessions.second_slam_runs == 3 * 3
    for name, outcome in sessions.warm.items():
        cold = sessions.cold[name]["boundary"]
        assert [t["value"] for t in outcome["trials"]] == [30, cold["pass_value"], cold["fail_value"]]
        assert outcome["boundary"] == cold and outcome["termination"] == "tolerance"
        assert not any(t["cached"] for t in outcome["trials"])
    assert len(sessions.saved_after_second) == 2 and sessions.saved_after_second[1].endswith("_main.json")


def check_compared_run(sessions: HistorySessions) -> None:
    """Bare --sal-compare compares with the baseline named main: worse fails, better and same pass."""
    sessions.third.assert_outcomes(passed=2, failed=1)
    has_line(sessions.third, "test_worse", "FAILED")
    check_bracket(sessions.compared["test_worse"], predicted(share=lambda v: v / 50), tolerance=1)
    check_bracket(sessions.compared["test_better"], predicted(share=lambda v: v / 30), tolerance=1)
    assert sessions.compared["test_worse"]["verdict"] == "passed" and sessions.compared["test_worse"]["regression"]
    assert sessions.compared["test_worse"]["previous"] == sessions.warm["test_worse"]["boundary"]
    for name in ("test_better", "test_same"):  # an improvement, and no change, do not fail
        assert sessions.compared[name]["regression"] is None and sessions.compared[name]["previous"] == sessions.warm[name]["boundary"]
        has_line(sessions.third, name, "PASSED (fog.visibility_m boundary")
    assert sessions.compared["test_better"]["boundary"]["pass_value"] < 15
    assert (
        sessions.compared["test_same"]["boundary"] == sessions.warm["test_same"]["boundary"]
        and len(sessions.compared["test_same"]["trials"]) == 3
    )
    has_line(sessions.third, "test_worse ", "REGRESSED", "FAILED")  # the summary table
    for name in NAMES:
        assert sessions.compared[name]["comparison"].startswith("main (run 0002"), sessions.compared[name]["comparison"]
    assert len(sessions.saved_after_third) == 3


def check_regression_message(sessions: HistorySessions) -> None:
    before_pass = sessions.warm["test_worse"]["boundary"]["pass_value"]
    now_pass = sessions.compared["test_worse"]["boundary"]["pass_value"]
    assert now_pass > 23.75 > 1.1 * before_pass
    sessions.third.stdout.fnmatch_lines(
        [
            "*test_worse*",
            "regressed against the history (the requirement is met): tracking_rate >= 0.5 wherever fog.visibility_m >= 30 m",
            "  at fog.visibility_m = 30 m: *tracking_rate 0.6*",
            (
                "*regression: fog.visibility_m boundary moved toward the requirement: passed down to "
                f"{before_pass:.4g} m before, now only down to {now_pass:.4g} m (+* %, limit 10 %)"
            ),
        ]
    )


def check_reruns(sessions: HistorySessions) -> None:
    """The regressed run 3 is not a baseline, so retrying cannot pass the gate; and it cannot take the name main."""
    for result, found in sessions.again:
        result.assert_outcomes(passed=2, failed=1)
        assert found["test_worse"]["previous"] == sessions.warm["test_worse"]["boundary"]
        result.stdout.fnmatch_lines(["pytest-sal: this run is saved without the name 'main': 1 test(s) failed the --sal-compare gate*"])
    assert len(sessions.saved_after_again) == 5 and not any(p.endswith("_main.json") for p in sessions.saved_after_again[2:])


def check_history_command(sessions: HistorySessions) -> None:
    status, listing = sessions.listing
    assert status == 0 and "5 runs, 0001" in listing and "0005" in listing
    for name in NAMES:
        assert f"test_suite.py::{name}" in listing
    status, trend = sessions.trend
    assert status == 0 and "test_suite.py::test_worse" in trend and sessions.plot.is_file()
    assert sum(line.startswith(("0001", "0002", "0003", "0004", "0005")) for line in trend.splitlines()) == 5, trend
    run_3 = next(line for line in trend.splitlines() if line.startswith("0003"))
    assert "failed (regressed)" in run_3, run_3  # as pytest reported it


def test_compare_against_a_named_run_and_no_history(pytester: pytest.Pytester) -> None:
    mode: list[str] = []  # as with xdist (workers read the history the same way): kept short
    project(pytester, HISTORY_TESTS.split("\n\n\n@sal.require")[0], {"test_worse": "min(1, v / 40)"})
    run(pytester, mode, "--sal-save", "baseline").assert_outcomes(passed=1)
    (saved,) = runs_saved(pytester)
    assert saved.endswith("_baseline.json")
    write_tracked(pytester, {"test_worse": "min(1, v / 50)"})
    # --sal-no-history: a session that writes nothing; it still compares with the named run
    result = run(pytester, mode, "--sal-no-history", "--sal-compare=baseline", "--sal-compare-fail=boundary:10%")
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(["*regression: fog.visibility_m boundary moved toward the requirement*"])
    assert runs_saved(pytester) == [saved]
    # a name that is no run is said, naming the known runs; --sal-compare-missing=fail fails it
    unknown = run(pytester, mode, "--sal-no-history", "--sal-compare=nightly")
    unknown.assert_outcomes(passed=1)
    has_line(unknown, "test_worse ", "no baseline", "passed")
    has_line(
        unknown,
        "pytest-sal: 1 of 1 tests not compared with 'nightly' (passed without a comparison",
        "no run 'nightly' in the history",
        "0001 (baseline)",
    )
    strict = run(pytester, mode, "--sal-no-history", "--sal-compare=nightly", "--sal-compare-missing=fail")
    strict.assert_outcomes(failed=1)
    has_line(strict, "test_worse ", "NO BASELINE", "FAILED")
    strict.stdout.fnmatch_lines(["*not compared: no run 'nightly' in the history*(--sal-compare-missing=fail)*"])
