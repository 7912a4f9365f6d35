"""Helpers of the plugin's end-to-end tests (``test_plugin_requirements.py``,
``test_plugin_history.py``): inner pytest suites on ``FakeSlam`` run by ``pytester``, once
without xdist and once with ``-n 2`` (in a subprocess), and readers of their results.

``FakeSlam(tracked="min(1, v / 40)")`` tracks ``round(n * v / 40)`` of ``n`` frames at fog
visibility ``v``, so ``predicted`` says the verdict of any trial exactly.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

#: one inner run without xdist, one with two workers (subprocess mode)
MODES = [pytest.param([], id="serial"), pytest.param(["-n", "2"], id="xdist")]

#: conftest of the inner suites: the fake per test name from tracked.json (a tracked
#: expression, or FakeSlam keyword arguments, or BernoulliSlam's with "held"), every SLAM run
#: appended to calls.jsonl
CONFTEST = """
import json
from pathlib import Path

import pytest
from pytest_sal.testing import BernoulliSlam, FakeSlam

HERE = Path(__file__).parent


@pytest.fixture
def sal_system(request):
    path = HERE / "tracked.json"
    table = json.loads(path.read_text()) if path.exists() else {}
    spec = table.get(request.node.originalname, table.get("*", "min(1, v / 40)"))
    options = {"tracked": spec} if isinstance(spec, str) else dict(spec)
    system = BernoulliSlam if "held" in options else FakeSlam
    return system(calls_file=str(HERE / "calls.jsonl"), **options)
"""

#: a 20-frame urban world instead of the default 60 frames (cheaper trials)
SMALL_DATASET = """

@pytest.fixture(scope="session")
def sal_dataset():
    from sal_adapters import open_dataset

    return open_dataset("synthetic", scene="urban", frames=20, sensor="stereo")
"""

HEADER = """
import pytest
import pytest_sal as sal
from pytest_sal import ate_rmse, tracking_rate
from sal_modules import fog, rain
"""


# -- helpers ---------------------------------------------------------------------------------
def project(
    pytester: pytest.Pytester, tests: str, tracked: dict[str, Any] | None = None, small: bool = True, name: str = "test_suite"
) -> None:
    """An inner suite: the FakeSlam conftest, ``tracked.json`` and one test module."""
    pytester.makeconftest(CONFTEST + (SMALL_DATASET if small else ""))
    write_tracked(pytester, tracked or {})
    pytester.makepyfile(**{name: HEADER + tests})


def write_tracked(pytester: pytest.Pytester, tracked: dict[str, Any]) -> None:
    (pytester.path / "tracked.json").write_text(json.dumps(tracked))


def run(pytester: pytest.Pytester, mode: list[str], *args: str) -> pytest.RunResult:
    """The inner session with its own cache and history folders; ``-n 2`` in a subprocess.
    Hypothesis' plugin is left out: it costs every inner interpreter a second of CPU."""
    options = [
        "-p",
        "no:cacheprovider",
        "-p",
        "no:hypothesispytest",
        f"--sal-cache-dir={pytester.path / 'cache'}",
        f"--sal-history-dir={pytester.path / 'history'}",
        *args,
    ]
    if mode:
        return pytester.runpytest_subprocess(*mode, *options, timeout=300)
    return pytester.runpytest(*options)


def calls(pytester: pytest.Pytester) -> int:
    """SLAM runs made so far by the inner suites (FakeSlam's calls_file)."""
    path = pytester.path / "calls.jsonl"
    return len(path.read_text().splitlines()) if path.exists() else 0


def junit(path: Path) -> dict[str, dict[str, str]]:
    """``{test name: {property: value}}`` from a JUnit XML file (``sal_outcome`` as JSON)."""
    found = {}
    for case in ET.parse(path).getroot().iter("testcase"):
        found[case.get("name", "")] = {p.get("name", ""): p.get("value", "") for p in case.iter("property")}
    return found


def outcomes(path: Path) -> dict[str, dict[str, Any]]:
    return {name: json.loads(props["sal_outcome"]) for name, props in junit(path).items() if "sal_outcome" in props}


def output(result: pytest.RunResult) -> str:
    return result.stdout.str() + "\n" + result.stderr.str()


def has_line(result: pytest.RunResult, *parts: str) -> None:
    """Some output line holds every part (verbose lines differ with xdist: ``[gw0] PASSED ... id``)."""
    lines = output(result).splitlines()
    assert any(all(p in line for p in parts) for line in lines), f"no line with {parts}:\n{output(result)}"


def predicted(n: int = 20, threshold: float = 0.5, share: Callable[[float], float] = lambda v: min(1.0, v / 40)) -> Callable[[float], bool]:
    """FakeSlam's verdict at ``v``: ``round(n * share(v)) / n >= threshold``."""
    return lambda v: round(n * min(1.0, max(0.0, share(v)))) / n >= threshold


def check_bracket(outcome: dict[str, Any], verdict: Callable[[float], bool], tolerance: float | None = None) -> None:
    """Every trial's verdict is the fake's; the bracket passes at its pass end, fails at its fail
    end, and is within ``tolerance`` when the search stopped on it."""
    for trial in outcome["trials"]:
        assert trial["passed"] == verdict(trial["value"]), trial
    pass_value, fail_value = outcome["boundary"]["pass_value"], outcome["boundary"]["fail_value"]
    assert verdict(pass_value) and not verdict(fail_value)
    if tolerance is not None:
        assert outcome["termination"] == "tolerance"
        assert abs(pass_value - fail_value) <= tolerance


def check_all(checks: dict[str, Callable[[], object]]) -> None:
    """Run every check, then fail naming each one that failed, with its message: one failing
    check does not hide the others. (The inner sessions they read are too costly to run once
    per test function, and ``pytester`` cannot be shared between tests.)"""
    failed = []
    for name, check in checks.items():
        try:
            check()
        except (AssertionError, pytest.fail.Exception) as exc:
            failed.append(f"{name}: {exc}")
    assert not failed, f"{len(failed)} of {len(checks)} checks failed:\n\n" + "\n\n".join(failed)
