"""The plugin with the real ORB-SLAM3 (pyorbslam3): one ``sal.require`` search of a noisy system
(at most 6 runs, reliability 0.5) in an inner pytest session (``pytester``), the session's
vocabulary passed through the environment.
The plugin's behaviour on ``FakeSlam`` is in test_plugin_requirements.py."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import pytest
from plugin_suites import HEADER, has_line, outcomes, run

ORB_CONFTEST = """
import os

import pytest
from sal_wrappers import create


@pytest.fixture
def sal_system():
    return create("orbslam3", vocabulary=os.environ["SAL_ORB_VOCABULARY"])
"""


@pytest.mark.skipif(importlib.util.find_spec("pyorbslam3") is None, reason="pyorbslam3 is not installed")
def test_orbslam3_through_the_plugin(pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch, orb_vocabulary: Path) -> None:
    monkeypatch.setenv("SAL_ORB_VOCABULARY", str(orb_vocabulary))
    pytester.makeconftest(ORB_CONFTEST)
    pytester.makepyfile(
        test_orb=HEADER
        + """

@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 200, reliability=0.5, max_runs=6)
def test_mild_fog(sal_outcome):
    assert sal_outcome.system == "orbslam3" and sal_outcome.verdict == "passed"
    edge = sal_outcome.trials[0]
    assert edge.value == 200 and edge.passed and not edge.cached
    assert edge.runs[0]["tracking_rate"] > 0.5
    boundary = sal_outcome.boundary
    assert boundary.noisy and boundary.reliability == 0.5 and boundary.holds_at_edge >= 0.9
    assert boundary.runs == sum(len(t.runs) for t in sal_outcome.trials) <= 6
"""
    )
    result = run(pytester, [], "-v", "--junitxml=out.xml")
    result.assert_outcomes(passed=1)
    found = outcomes(pytester.path / "out.xml")["test_mild_fog"]
    assert found["system"] == "orbslam3" and found["system_options"]["vocabulary"] == str(orb_vocabulary)
    has_line(result, "test_mild_fog", "PASSED (fog.visibility_m boundary s50/90")
    assert math.isfinite(found["trials"][0]["metrics"]["tracking_rate"])
