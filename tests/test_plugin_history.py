"""The plugin and the run history end to end (inner pytest sessions on ``FakeSlam``, with and
without ``-n 2``): each session appends one run, the next search starts from the previous
boundary (three trials for an unchanged system), ``--sal-compare-fail`` fails a test whose
boundary regressed and no other, and ``sal history`` lists the tests."""

from __future__ import annotations

import json

import pytest
from plugin_suites import (
    MODES,
    calls,
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


@pytest.mark.parametrize("mode", MODES)
def test_history_warm_start_and_compare_fail(pytester: pytest.Pytester, mode: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    project(pytester, HISTORY_TESTS, {name: "min(1, v / 40)" for name in NAMES})

    # run 1: cold searches; one run file (written by the controller only under xdist)
    first = run(pytester, mode, "--junitxml=first.xml")
    first.assert_outcomes(passed=3)
    assert len(runs_saved(pytester)) == 1
    cold = outcomes(pytester.path / "first.xml")
    for outcome in cold.values():
        check_bracket(outcome, predicted(), tolerance=1)  # from 19 m on
        assert len(outcome["trials"]) > 3
    saved = json.loads((pytester.path / "history" / runs_saved(pytester)[0]).read_text())
    assert sorted(o["test_id"] for o in saved["outcomes"]) == sorted(f"test_suite.py::{n}" for n in NAMES)

    # run 2, SLAM runs again (no cache): the previous boundary still brackets -> 3 trials each
    before = calls(pytester)
    second = run(pytester, mode, "--sal-no-cache", "--junitxml=second.xml", "--sal-save=main")
    second.assert_outcomes(passed=3)
    assert calls(pytester) - before == 3 * 3
    warm = outcomes(pytester.path / "second.xml")
    for name, outcome in warm.items():
        assert [t["value"] for t in outcome["trials"]] == [30, cold[name]["boundary"]["pass_value"], cold[name]["boundary"]["fail_value"]]
        assert outcome["boundary"] == cold[name]["boundary"] and outcome["termination"] == "tolerance"
        assert not any(t["cached"] for t in outcome["trials"])
    assert len(runs_saved(pytester)) == 2 and runs_saved(pytester)[1].endswith("_main.json")

    # run 3 (bare --sal-compare: against the baseline named main): one fake got worse (boundary 23.75 m), one better (14.25 m), one is unchanged
    write_tracked(pytester, {"test_worse": "min(1, v / 50)", "test_better": "min(1, v / 30)", "test_same": "min(1, v / 40)"})
    third = run(pytester, mode, "-v", "--sal-compare", "--sal-compare-fail=boundary:10%", "--junitxml=third.xml")
    third.assert_outcomes(passed=2, failed=1)
    has_line(third, "test_worse", "FAILED")
    before_pass = warm["test_worse"]["boundary"]["pass_value"]
    compared = outcomes(pytester.path / "third.xml")
    now_pass = compared["test_worse"]["boundary"]["pass_value"]
    check_bracket(compared["test_worse"], predicted(share=lambda v: v / 50), tolerance=1)
    check_bracket(compared["test_better"], predicted(share=lambda v: v / 30), tolerance=1)
    assert now_pass > 23.75 > 1.1 * before_pass
    third.stdout.fnmatch_lines(
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
    assert compared["test_worse"]["verdict"] == "passed" and compared["test_worse"]["regression"]
    assert compared["test_worse"]["previous"] == warm["test_worse"]["boundary"]
    for name in ("test_better", "test_same"):  # an improvement, and no change, do not fail
        assert compared[name]["regression"] is None and compared[name]["previous"] == warm[name]["boundary"]
        has_line(third, name, "PASSED (fog.visibility_m boundary")
    assert compared["test_better"]["boundary"]["pass_value"] < 15
    assert compared["test_same"]["boundary"] == warm["test_same"]["boundary"] and len(compared["test_same"]["trials"]) == 3
    has_line(third, "test_worse ", "REGRESSED", "FAILED")  # the summary table
    for name in NAMES:
        assert compared[name]["comparison"].startswith("main (run 0002"), compared[name]["comparison"]
    assert len(runs_saved(pytester)) == 3

    # the same regressed commit again, against main and against 'last': the regressed run 3 is
    # not a baseline, so retrying cannot pass the gate; and it cannot take the name main
    for ref in ("", "=last"):
        again = run(pytester, mode, f"--sal-compare{ref}", "--sal-compare-fail=boundary:10%", "--sal-save=main", "--junitxml=again.xml")
        again.assert_outcomes(passed=2, failed=1)
        assert outcomes(pytester.path / "again.xml")["test_worse"]["previous"] == warm["test_worse"]["boundary"]
        again.stdout.fnmatch_lines(["pytest-sal: this run is saved without the name 'main': 1 test(s) failed the --sal-compare gate*"])
    assert len(runs_saved(pytester)) == 5 and not any(p.endswith("_main.json") for p in runs_saved(pytester)[2:])

    # `sal history` lists every test of the folder
    capsys.readouterr()
    assert cli.main(["history", "--history-dir", str(pytester.path / "history")]) == 0
    listing = capsys.readouterr().out
    assert "5 runs, 0001" in listing and "0005" in listing
    for name in NAMES:
        assert f"test_suite.py::{name}" in listing
    plot = pytester.path / "worse.png"
    assert cli.main(["history", "test_worse", "--history-dir", str(pytester.path / "history"), "-o", str(plot)]) == 0
    trend = capsys.readouterr().out
    assert "test_suite.py::test_worse" in trend and plot.is_file()
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
