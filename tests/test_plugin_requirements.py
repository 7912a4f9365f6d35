"""The plugin end to end: ``sal.require`` / ``sal.sweep`` / ``sal.at`` tests run by inner
pytest sessions (``pytester``) on ``FakeSlam``, whose boundaries are exactly predictable, once
without xdist and once with ``-n 2``: verdicts and boundaries, failure messages, flakiness, the
cache, sweeps, the ``sal`` mark, parametrised systems, JUnit XML, Markdown and HTML
reports (the real ORB-SLAM3 search through the plugin is in test_plugin_orbslam3.py).

On the default 60-frame urban world ``FakeSlam(tracked="min(1, v / 40)")`` meets
``tracking_rate >= 0.5`` exactly from 20 m on; on the 20-frame world most suites here use
(``SMALL_DATASET``), from 19 m on. History, warm start and ``--sal-compare-fail`` are in
``test_plugin_history.py``, misuse and options in ``test_plugin_usage.py``; the shared
helpers in ``plugin_suites.py``.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from plugin_suites import (
    HEADER,
    MODES,
    SMALL_DATASET,
    calls,
    check_all,
    check_bracket,
    has_line,
    junit,
    outcomes,
    output,
    predicted,
    project,
    run,
)

# -- 1-3, 11, 12: verdicts, boundaries, the summary table, JUnit properties, reports ------------
VERDICT_TESTS = """

@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25, tolerance=1)
def test_pass(sal_outcome):
    assert sal_outcome.verdict == "passed" and sal_outcome.system == "fake"
    assert [t.value for t in sal_outcome.trials] == [25, 1, 5, 15, 20, 17.5, 18.75, 19.375]
    assert (sal_outcome.boundary.pass_value, sal_outcome.boundary.fail_value) == (20, 19.375)
    assert sal_outcome.termination == "tolerance" and sal_outcome.margin == 5
    assert sal_outcome.trials[0].metrics["tracking_rate"] == 38 / 60  # round(60 * 25 / 40)
    assert sal_outcome.trials[4].metrics["tracking_rate"] == 0.5


@sal.require(tracking_rate >= 0.8, fog.visibility_m >= 25)
def test_fail(sal_outcome):
    raise AssertionError("BODY-RAN: the body of a failed requirement must not run")


@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25)
def test_passes_everywhere(sal_outcome):
    assert sal_outcome.termination == "not_bracketed"
    assert [t.value for t in sal_outcome.trials] == [25, 1]
    assert (sal_outcome.boundary.pass_value, sal_outcome.boundary.fail_value) == (1, None)


@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25)
def test_fails_everywhere(sal_outcome):
    raise AssertionError("BODY-RAN")
"""


@pytest.mark.parametrize("mode", MODES)
def test_verdicts_boundaries_summary_junit_and_reports(pytester: pytest.Pytester, mode: list[str]) -> None:
    # the default dataset (60 frames): the documented 19.38-20 m bracket; each check reads the one session
    project(pytester, VERDICT_TESTS, {"test_passes_everywhere": "1", "test_fails_everywhere": "0"}, small=False)
    result = run(pytester, mode, "-v", "--junitxml=out.xml", "--sal-report-md=summary.md", "--sal-report-html=html")
    result.assert_outcomes(passed=2, failed=2)
    assert "BODY-RAN" not in output(result)
    found = outcomes(pytester.path / "out.xml")
    check_all(
        {
            "1. pass: verbose status and the summary table": lambda: check_passed_lines(result),
            "2. fail: the requirement, the bracket with its metrics, the reproduction": lambda: check_failure_message(result, found),
            "3. not bracketed either way": lambda: check_not_bracketed(result, found),
            "11. JUnit properties": lambda: check_junit_properties(pytester.path / "out.xml", found),
            "12. the Markdown summary and the HTML report": lambda: check_reports(pytester.path, found),
            "13. the summary ends naming each file written, as given or from the cwd": lambda: check_files_named(result, pytester.path),
        }
    )


def check_passed_lines(result: pytest.RunResult) -> None:
    has_line(result, "test_pass", "PASSED (fog.visibility_m boundary 19.38-20 m)")
    has_line(result, "test_passes_everywhere", "PASSED (fog.visibility_m boundary beyond 1 m (passed everywhere searched))")
    result.stdout.fnmatch_lines(
        [
            "*pytest-sal robustness boundaries*",
            "test * system * parameter * requirement * boundary * trials * margin * change * verdict",
        ]
    )
    has_line(result, "test_pass ", "fake", "fog.visibility_m", ">= 25 m", "19.38-20 m", " 8 ", "+5 m", "passed")
    has_line(result, "test_fail ", "fake", "fog.visibility_m", ">= 25 m", "FAILED")


def check_failure_message(result: pytest.RunResult, found: dict[str, dict]) -> None:
    failed = found["test_fail"]
    check_bracket(failed, predicted(n=60, threshold=0.8))
    assert failed["verdict"] == "failed" and failed["termination"] == "max_trials" and len(failed["trials"]) == 8
    pass_end, fail_end = failed["boundary"]["pass_value"], failed["boundary"]["fail_value"]
    assert fail_end < 95 / 3 <= pass_end  # round(60 v / 40) >= 48 from v = 31.67 m on
    result.stdout.fnmatch_lines(
        [
            "*requirement not met: tracking_rate >= 0.8 wherever fog.visibility_m >= 25 m",
            "*  at fog.visibility_m = 25 m: *tracking_rate 0.6333*; failed: tracking_rate >= 0.8",
            f"*  boundary: fog.visibility_m {fail_end:.4g}-{pass_end:.4g} m (8 trials, 8 runs, max_trials); 1 run per trial",
            f"*  pass end {pass_end:g} m: *tracking_rate *",
            f"*  fail end {fail_end:g} m: *tracking_rate *",
            "*  reproduce: @sal.at(fog.visibility_m, 25)  # m; seed 0, up to 1 run(s), system fake, dataset *",
        ]
    )


def check_not_bracketed(result: pytest.RunResult, found: dict[str, dict]) -> None:
    assert found["test_passes_everywhere"]["termination"] == "not_bracketed"
    everywhere = found["test_fails_everywhere"]
    assert everywhere["verdict"] == "failed" and everywhere["termination"] == "not_bracketed"
    assert [t["value"] for t in everywhere["trials"]] == [25, 100000]
    assert everywhere["boundary"]["pass_value"] is None
    assert "failed everywhere searched) (2 trials, 2 runs, not_bracketed)" in output(result)


def check_junit_properties(path: Path, found: dict[str, dict]) -> None:
    props = junit(path)
    assert [props["test_pass"][k] for k in ("sal_boundary_pass", "sal_boundary_fail", "sal_trials")] == ["20", "19.375", "8"]
    pass_end = found["test_fail"]["boundary"]["pass_value"]
    assert props["test_fail"]["sal_boundary_pass"] == f"{pass_end:g}" and props["test_fail"]["sal_trials"] == "8"
    assert props["test_passes_everywhere"]["sal_boundary_fail"] == "" and props["test_passes_everywhere"]["sal_trials"] == "2"
    assert props["test_fails_everywhere"]["sal_boundary_pass"] == "" and props["test_fails_everywhere"]["sal_boundary_fail"] == "100000"


def check_reports(folder: Path, found: dict[str, dict]) -> None:
    markdown = (folder / "summary.md").read_text()
    assert "4 robustness requirements: 2 passed, 2 failed" in markdown
    assert all(name in markdown for name in found) and "19.38-20 m" in markdown
    index = folder / "html" / "index.html"
    page = index.read_text()
    assert all(name in page for name in found)
    images = [src for src in re.findall(r"src='([^']+)'", page) if src.endswith(".png")]
    assert len(images) >= 4, page[:2000]  # a metric plot per search, example frames
    for src in images:
        image = index.parent / src
        assert image.is_file() and image.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", src


def check_files_named(result: pytest.RunResult, folder: Path) -> None:
    (history,) = (folder / "history").glob("*.json")
    result.stdout.fnmatch_lines(
        [
            "*pytest-sal robustness boundaries*",
            f"pytest-sal: wrote history/{history.name}",
            "pytest-sal: wrote summary.md",
            "pytest-sal: wrote html/index.html",
        ]
    )


# -- 4: a noisy system ------------------------------------------------------------------------
NOISY_TESTS = """

@sal.require(tracking_rate >= 0.46, fog.visibility_m >= 18)
def test_noisy(sal_outcome):
    raise AssertionError("BODY-RAN")


@sal.require(tracking_rate >= 0.46, fog.visibility_m >= 18, reliability=0.5, max_runs=1)
def test_noisy_short(sal_outcome):
    raise AssertionError("BODY-RAN")


@sal.require(tracking_rate >= 0.49, fog.visibility_m >= 20, tolerance=1)
def test_near_but_steady(sal_outcome):
    first = sal_outcome.trials[0]
    assert first.value == 20 and len(first.runs) == 1  # a deterministic system: one run per trial
    assert first.metrics["tracking_rate"] == 0.5 and sal_outcome.verdict == "passed"
"""


@pytest.mark.parametrize("mode", MODES)
def test_a_noisy_edge_that_holds_half_the_time_fails_and_a_short_budget_is_inconclusive(pytester: pytest.Pytester, mode: list[str]) -> None:
    # below 18.4 m the noisy fake initialises late in half of its runs and tracks 0.45 of the
    # frames then: p(18 m) = 0.5 for tracking_rate >= 0.46, below the default reliability 0.8.
    # From 18.4 m on every run holds. At reliability 0.5, one run cannot settle whether p(18 m)
    # >= 0.5, whatever it gives.
    noisy = {"held": "1 if v >= 18.4 else 0.5", "late": 0.45}
    project(pytester, NOISY_TESTS, {"test_noisy": noisy, "test_noisy_short": {**noisy, "seed": 1}})
    result = run(pytester, mode, "-v", "--sal-no-history", "--junitxml=out.xml")
    result.assert_outcomes(passed=1, failed=2)
    assert "BODY-RAN" not in output(result)
    result.stdout.fnmatch_lines(
        [
            "*requirement not met: tracking_rate >= 0.46 wherever fog.visibility_m >= 18 m: at fog.visibility_m = 18 m fewer than "
            "80 % of runs hold it (confidence * >= 90 %; * runs)",
            "*at 18 m: * of * runs held; * initialised late (first pose at frame 11)",
        ]
    )
    result.stdout.fnmatch_lines(["*INCONCLUSIVE: tracking_rate >= 0.46 wherever fog.visibility_m >= 18 m: after 1 run, the chance*"])
    found = outcomes(pytester.path / "out.xml")
    noisy_outcome, short = found["test_noisy"], found["test_noisy_short"]
    assert noisy_outcome["verdict"] == "failed" and short["verdict"] == "inconclusive"
    boundary = noisy_outcome["boundary"]
    assert boundary["reliability"] == 0.8 and boundary["confidence"] == 0.9
    assert boundary["runs"] == sum(len(t["runs"]) for t in noisy_outcome["trials"]) <= 30
    assert boundary["holds_at_edge"] <= 0.1  # p(18 m) < 0.8 with confidence 90 %
    low, high = sorted(boundary["interval"])
    # s80 is 18.4 m (every run holds from there on), resolved to the location grid: half a grid step of
    # 1/128 of 5 decades, 4.6 %
    assert low <= 18.4 * 1.046 and high >= 18.4 and boundary["bound"] >= 18.4
    edge = noisy_outcome["trials"][0]
    assert edge["value"] == 18 and {r["tracking_rate"] for r in edge["runs"]} == {0.45, 1.0}
    has_line(result, "test_noisy ", "bern", ">= 18 m", "FAILED")
    has_line(result, "noisy_short ", "bern", ">= 18 m", "INCONCLUSIVE")

    # the same cache again (a session without xdist): the same runs are read back, nothing runs
    before = calls(pytester)
    again = run(pytester, [], "--sal-no-history", "--junitxml=again.xml")
    again.assert_outcomes(passed=1, failed=2)
    assert calls(pytester) == before
    assert outcomes(pytester.path / "again.xml")["test_noisy"]["boundary"] == boundary


SESSION_RUNS_TESTS = """

@sal.sweep(fog.visibility_m, A=18)
@sal.require(tracking_rate >= 0.46, max_runs=8)
def test_a_level(sal_trial):
    pass


@sal.require(tracking_rate >= 0.46, fog.visibility_m >= 18, max_runs=3)
def test_b_search(sal_outcome):
    pass
"""


def test_a_noisy_search_counts_the_runs_of_a_sweep_level_earlier_in_the_session(pytester: pytest.Pytester) -> None:
    # the sweep level at 18 m runs first (up to 8 runs); the search of the same system, dataset and
    # parameter starts from those runs, numbers its own on from them and adds at most 3
    project(pytester, SESSION_RUNS_TESTS, {"*": {"held": "1 if v >= 18.4 else 0.5", "late": 0.45}})
    result = run(pytester, [], "--sal-no-history", "--junitxml=out.xml")
    result.assert_outcomes(failed=2)
    found = outcomes(pytester.path / "out.xml")
    level, search = found["test_a_level[A-fog.visibility_m=18]"], found["test_b_search"]
    level_runs = len(level["trials"][0]["runs"])
    edge = search["trials"][0]

    def seen(runs: list[dict]) -> list[tuple]:
        return [(r["tracking_rate"], r["first_tracked"], r["passed"]) for r in runs]

    assert edge["value"] == 18 and seen(edge["runs"][:level_runs]) == seen(level["trials"][0]["runs"])
    assert search["boundary"]["runs"] == level_runs + 3 == sum(len(t["runs"]) for t in search["trials"])
    assert calls(pytester) == level_runs + 3


# -- 5: the cache ----------------------------------------------------------------------
CACHE_TESTS = """

@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25, tolerance=1)
def test_meets(sal_outcome):
    pass


@sal.require(tracking_rate >= 0.8, fog.visibility_m >= 25)
def test_misses(sal_outcome):
    pass
"""


@pytest.mark.parametrize("mode", MODES)
def test_second_run_reads_every_trial_from_the_cache(pytester: pytest.Pytester, mode: list[str]) -> None:
    project(pytester, CACHE_TESTS)
    first = run(pytester, mode, "--sal-no-history", "--junitxml=first.xml")
    first.assert_outcomes(passed=1, failed=1)
    cold = outcomes(pytester.path / "first.xml")
    trials = sum(len(o["trials"]) for o in cold.values())
    # the two tests share the trial at their common edge (25 m): the second reads the first's
    assert [t["cached"] for t in cold["test_meets"]["trials"] + cold["test_misses"]["trials"]].count(True) == 1
    assert calls(pytester) == trials - 1
    check_bracket(cold["test_meets"], predicted(), tolerance=1)
    check_bracket(cold["test_misses"], predicted(threshold=0.8))

    second = run(pytester, mode, "--sal-no-history", "--junitxml=second.xml")
    second.assert_outcomes(passed=1, failed=1)
    assert calls(pytester) == trials - 1  # no SLAM run at all
    assert not (pytester.path / "history").exists()  # --sal-no-history
    warm = outcomes(pytester.path / "second.xml")
    for name, outcome in warm.items():
        assert all(t["cached"] for t in outcome["trials"])
        same = ("verdict", "boundary", "termination", "margin", "requirement")
        assert {k: outcome[k] for k in same} == {k: cold[name][k] for k in same}
        assert [(t["value"], t["passed"], t["metrics"]) for t in outcome["trials"]] == [
            (t["value"], t["passed"], t["metrics"]) for t in cold[name]["trials"]
        ]
    n_meets = len(cold["test_meets"]["trials"])
    has_line(second, "test_meets", f"{n_meets} ({n_meets} cached)")

    # --sal-no-cache runs every trial again (a session without xdist, to keep this short)
    third = run(pytester, [], "--sal-no-history", "--sal-no-cache", "--junitxml=third.xml")
    third.assert_outcomes(passed=1, failed=1)
    assert calls(pytester) == 2 * trials - 1
    assert not any(t["cached"] for o in outcomes(pytester.path / "third.xml").values() for t in o["trials"])


# -- 8, 9: sweep levels, explicit points, the sal mark ---------------------------------------
SWEEP_TESTS = """

@sal.sweep(fog.visibility_m, L=100, M=30, H=10)
@sal.require(tracking_rate >= 0.5)
def test_levels(sal_trial, sal_level):
    expected = {100: 1.0, 30: 0.75, 10: 0.25}[sal_trial.value]
    assert sal_trial.metrics["tracking_rate"] == expected and sal_trial.passed
    assert sal_level[1:] == ({100: "L", 30: "M"}[sal_trial.value], sal_trial.value)


@sal.at(fog.visibility_m, 30)
@sal.require(tracking_rate >= 0.7)
def test_point(sal_trial):
    assert (sal_trial.value, sal_trial.metrics["tracking_rate"]) == (30, 0.75)


@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 100, max_trials=2)
def test_search(sal_outcome):
    assert [t.value for t in sal_outcome.trials] == [100, 1] and sal_outcome.termination == "max_trials"


def test_plain():
    pass
"""


@pytest.mark.parametrize("mode", MODES)
def test_sweep_items_per_level_and_the_sal_mark(pytester: pytest.Pytester, mode: list[str]) -> None:
    project(pytester, SWEEP_TESTS)
    result = run(pytester, mode, "-m", "sal", "--strict-markers", "-v", "--junitxml=out.xml")
    result.assert_outcomes(passed=4, failed=1, **({} if mode else {"deselected": 1}))  # xdist reports no deselection
    assert "test_plain" not in output(result)
    has_line(result, "test_levels[L-fog.visibility_m=100]", "PASSED (fog.visibility_m = 100 m: tracking_rate 1)")
    has_line(result, "test_levels[M-fog.visibility_m=30]", "PASSED (fog.visibility_m = 30 m: tracking_rate 0.75)")
    has_line(result, "test_point[fog.visibility_m=30]", "PASSED (fog.visibility_m = 30 m: tracking_rate 0.75)")
    has_line(result, "test_levels[H-fog.visibility_m=10]", "FAILED")
    has_line(result, "test_search", "PASSED (fog.visibility_m boundary 1-100 m)")
    result.stdout.fnmatch_lines(
        [
            "*requirement not met: tracking_rate >= 0.5",
            "*at fog.visibility_m = 10 m: *tracking_rate 0.25*; failed: tracking_rate >= 0.5",
            "*boundary: fog.visibility_m beyond 10 m (failed everywhere searched) (1 trials, 1 runs, single); 1 run per trial",
            "*reproduce: @sal.at(fog.visibility_m, 10)*",
        ]
    )
    props = junit(pytester.path / "out.xml")
    assert props["test_levels[H-fog.visibility_m=10]"]["sal_boundary_fail"] == "10"
    assert props["test_levels[L-fog.visibility_m=100]"]["sal_boundary_pass"] == "100"
    assert {name: p["sal_trials"] for name, p in props.items()} == {
        "test_levels[L-fog.visibility_m=100]": "1",
        "test_levels[M-fog.visibility_m=30]": "1",
        "test_levels[H-fog.visibility_m=10]": "1",
        "test_point[fog.visibility_m=30]": "1",
        "test_search": "2",
    }
    # trials at the same value are shared (the point and level M; the search's edge and level L)
    assert calls(pytester) == 4

    others = run(pytester, [], "-m", "not sal", "-v")  # deselection is the same without xdist
    others.assert_outcomes(passed=1, deselected=5)
    has_line(others, "test_plain", "PASSED")
    assert "pytest-sal robustness boundaries" not in output(others)
    assert calls(pytester) == 4


# -- 10: one item per system -----------------------------------------------------------------
SYSTEMS_CONFTEST = (
    """
import pytest
from pytest_sal.testing import FakeSlam


@pytest.fixture(params=["min(1, v / 40)", "min(1, v / 20)"], ids=["slow", "fast"])
def sal_system(request):
    return FakeSlam(tracked=request.param)
"""
    + SMALL_DATASET
)


@pytest.mark.parametrize("mode", MODES)
def test_parametrised_system_gives_one_item_and_boundary_per_system(pytester: pytest.Pytester, mode: list[str]) -> None:
    pytester.makeconftest(SYSTEMS_CONFTEST)
    pytester.makepyfile(
        test_suite=HEADER
        + """

@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25, tolerance=1)
def test_fog(sal_outcome):
    pass
"""
    )
    result = run(pytester, mode, "-v", "--junitxml=out.xml")
    result.assert_outcomes(passed=2)
    found = outcomes(pytester.path / "out.xml")
    assert set(found) == {"test_fog[slow]", "test_fog[fast]"}
    check_bracket(found["test_fog[slow]"], predicted(share=lambda v: v / 40), tolerance=1)  # from 19 m on
    check_bracket(found["test_fog[fast]"], predicted(share=lambda v: v / 20), tolerance=1)  # from 9.5 m on
    assert found["test_fog[fast]"]["boundary"]["pass_value"] <= 10 and found["test_fog[slow]"]["boundary"]["fail_value"] >= 18
    for name, outcome in found.items():
        has_line(
            result,
            name,
            f"PASSED (fog.visibility_m boundary {outcome['boundary']['fail_value']:.4g}-{outcome['boundary']['pass_value']:.4g} m)",
        )
        has_line(result, f"{name} ", "fake", "passed")
