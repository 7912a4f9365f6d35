"""Live progress under ``pytest -v``: one line per trial as it finishes (value with unit, the
requirement's metrics, verdict, seconds, ``(cached)``), printed while the search runs, with and
without output capture and under ``-n 2`` (from the worker, on the controller's terminal);
nothing extra without ``-v``.

Liveness is measured, not assumed: the inner suite's system (``Watching``) reads, before each
of its runs, what the inner session has printed so far (pytester's subprocess writes its
stdout and stderr to files in the project folder), so run ``k`` of a test must already see
that test's first ``k`` trial lines.
"""

from __future__ import annotations

import json
import re

import pytest
from plugin_suites import HEADER, SMALL_DATASET, outcomes, output, run

from pytest_sal.engine.outcomes.outcome import Trial, TrialMetrics
from pytest_sal.report.formatting import trial_line

CONFTEST = '''
import json
from pathlib import Path

import pytest
from pytest_sal.testing import FakeSlam

HERE = Path(__file__).parent


class Watching(FakeSlam):
    """FakeSlam noting, before each run, how many trial lines of its test the session has shown."""

    def __init__(self, test, **options):
        super().__init__(**options)
        self.test = test

    def run(self, sequence, workdir, timeout=None):
        marker = f"::{self.test}  fog.visibility_m = "
        shown = sum(path.read_text().count(marker) for path in (HERE / "stdout", HERE / "stderr") if path.exists())
        with open(HERE / "seen.jsonl", "a") as handle:
            handle.write(json.dumps([self.test, shown]) + "\\n")
        return super().run(sequence, workdir, timeout)


@pytest.fixture
def sal_system(request):
    return Watching(request.node.name)
'''

TESTS = """
from pytest_sal import rpe_trans


@sal.require(tracking_rate >= 0.5, ate_rmse < 1, fog.visibility_m >= 25, tolerance=4)
def test_live(sal_outcome):
    pass


@sal.require(tracking_rate >= 0.8, rpe_trans < 5, fog.visibility_m >= 25, max_trials=2)
def test_live_fail(sal_outcome):
    pass
"""

NAMES = ("test_live", "test_live_fail")
#: each test's trials (values, verdicts) on the 20-frame world: FakeSlam tracks round(20 v / 40) frames
TRIALS: dict[str, list[tuple[float, str]]] = {
    "test_live": [(25, "pass"), (1, "FAIL"), (5, "FAIL"), (15, "FAIL"), (20, "pass"), (17.5, "FAIL")],
    "test_live_fail": [(25, "FAIL"), (100000, "pass")],
}


def make_suite(pytester: pytest.Pytester) -> None:
    pytester.makeconftest(CONFTEST + SMALL_DATASET)
    pytester.makepyfile(test_suite=HEADER + TESTS)


def trial_lines(text: str, test: str) -> list[str]:
    return [line for line in text.splitlines() if f"::{test}  fog.visibility_m = " in line]


def seen(pytester: pytest.Pytester) -> dict[str, list[int]]:
    """Per test, the trial lines already shown when each of its runs began."""
    path = pytester.path / "seen.jsonl"
    found: dict[str, list[int]] = {}
    for line in path.read_text().splitlines() if path.exists() else []:
        test, shown = json.loads(line)
        found.setdefault(test, []).append(shown)
    return found


def check_lines(lines: list[str], test: str, trials: list[dict], cached: bool) -> None:
    """One line per trial, in order: value with unit, verdict, ATE and tracking rate and the
    criteria's other metrics, seconds."""
    assert [line.split("fog.visibility_m = ", 1)[1].split(":", 1)[0] for line in lines] == [f"{v:g} m" for v, _ in TRIALS[test]]
    for line, (value, verdict), trial in zip(lines, TRIALS[test], trials):
        assert f"test_suite.py::{test}  fog.visibility_m = {value:g} m: {verdict}  " in line, line
        assert trial["passed"] == (verdict == "pass")
        assert f"tracking_rate {trial['metrics']['tracking_rate']:.3g}" in line, line
        assert "ate_rmse " in line and ("rpe_trans " in line) == (test == "test_live_fail"), line  # and the requirement's others
        assert re.search(r"  \d+\.\d s( \(cached\))?$", line), line
        assert line.endswith(" (cached)") == cached, line


LIVE_MODES = [
    pytest.param(["-v"], id="verbose"),
    pytest.param(["-v", "-s"], id="no-capture"),
    pytest.param(["-v", "-n", "2"], id="xdist"),
]


@pytest.mark.parametrize("mode", LIVE_MODES)
def test_a_line_per_trial_as_it_finishes(pytester: pytest.Pytester, mode: list[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("PYTHONUNBUFFERED", raising=False)  # a user's terminal: the lines must be flushed
    make_suite(pytester)
    result = run(pytester, mode, "--sal-no-cache", "--sal-no-history", "--junitxml=out.xml")  # a subprocess
    result.assert_outcomes(passed=1, failed=1)
    found = outcomes(pytester.path / "out.xml")
    xdist = "-n" in mode
    text = result.stderr.str() if xdist else result.stdout.str()  # a worker's stdout is not the terminal
    for test in NAMES:
        lines = trial_lines(text, test)
        check_lines(lines, test, found[test]["trials"], cached=False)
        assert all(line.startswith("[gw") if xdist else line.startswith("  test_suite.py::") for line in lines)
        # live: each run began after every earlier trial of its test was on the terminal
        assert seen(pytester)[test] == list(range(len(TRIALS[test])))
    if not xdist:  # between the item's id and its verdict
        stdout = [line.rstrip() for line in result.stdout.lines]
        for test, word in (("test_live", "PASSED"), ("test_live_fail", "FAILED")):
            shown = [i for i, line in enumerate(stdout) if f"::{test}  fog.visibility_m = " in line]
            start = stdout.index(f"test_suite.py::{test}")
            verdict = next(i for i, line in enumerate(stdout) if line.startswith(f"test_suite.py::{test} {word}"))
            assert start < shown[0] and shown[-1] < verdict, "\n".join(stdout)


def test_nothing_extra_without_verbose_and_cached_trials_say_so(pytester: pytest.Pytester) -> None:
    make_suite(pytester)
    quiet = run(pytester, [], "--sal-no-history", "--junitxml=out.xml")
    quiet.assert_outcomes(passed=1, failed=1)
    assert all(not trial_lines(output(quiet), test) for test in NAMES)  # (the failure's report section has its own)
    runs = sum(map(len, seen(pytester).values()))

    again = run(pytester, [], "-v", "--sal-no-history", "--junitxml=out.xml")  # every trial from the cache
    again.assert_outcomes(passed=1, failed=1)
    assert sum(map(len, seen(pytester).values())) == runs  # no SLAM run
    found = outcomes(pytester.path / "out.xml")
    for test in NAMES:
        check_lines(trial_lines(output(again), test), test, found[test]["trials"], cached=True)


def test_trial_line_shows_votes_units_and_missing_metrics() -> None:
    runs = [{"passed": True}, {"passed": False}, {"passed": False}]
    trial = Trial(value=0.5, passed=False, metrics=TrialMetrics({"ate_rmse": None, "tracking_rate": 0.25}), runs=runs, wall_time_s=12.34)
    line = trial_line(trial, "rain.intensity_mm_h", "mm/h", ["ate_rmse", "tracking_rate"])
    assert line == "rain.intensity_mm_h = 0.5 mm/h: FAIL (2 of 3 runs failed)  ate_rmse -, tracking_rate 0.25  12.3 s"
    single = Trial(value=3, passed=True, metrics=TrialMetrics({"ate_rmse": 0.04123}), runs=[{"passed": True}], cached=True)
    assert trial_line(single, "jpeg.quality", "", ["ate_rmse"]) == "jpeg.quality = 3: pass  ate_rmse 0.0412 m  0.0 s (cached)"
