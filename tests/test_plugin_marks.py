"""The requirement travels by the marks: a test marked by hand with ``pytest.mark.sal_require``
(and ``sal_sweep``), on the function or on its class, is the same robustness test as one
decorated with ``sal.require`` (``sal.at``), and the decorators leave no attribute on the
function. Inner sessions on ``FakeSlam`` (``plugin_suites``): on the 20-frame world
``tracking_rate >= 0.5`` holds from 19 m on, and 30 m tracks 0.75 of the frames."""

from __future__ import annotations

import pytest
from plugin_suites import has_line, project, run

MARK_TESTS = """
from pytest_sal.engine.requirements import Requirement

FOG = Requirement.build([tracking_rate >= 0.5, fog.visibility_m >= 25], tolerance=1)


def check(outcome):
    assert outcome.verdict == "passed" and outcome.requirement == str(FOG)
    assert outcome.boundary.fail_value < 19 <= outcome.boundary.pass_value <= outcome.boundary.fail_value + 1


@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25, tolerance=1)
def test_decorated(sal_outcome):
    check(sal_outcome)
    assert not hasattr(test_decorated, "sal_requirement")  # the mark is the requirement


@pytest.mark.sal_require(FOG)
def test_marked_by_hand(sal_outcome):
    check(sal_outcome)


class TestMarkedClass:
    pytestmark = [pytest.mark.sal_require(FOG)]

    def test_in_the_class(self, sal_outcome):
        check(sal_outcome)


@pytest.mark.sal_sweep(fog.visibility_m.ref(), {"at": 30.0})
@pytest.mark.sal_require(Requirement.build([tracking_rate >= 0.7]))
def test_point_by_hand(sal_trial):
    assert sal_trial.metrics.tracking_rate == 0.75
    assert not hasattr(test_point_by_hand, "sal_levels")
"""


def test_a_requirement_marked_by_hand_is_searched_like_a_decorated_one(pytester: pytest.Pytester) -> None:
    project(pytester, MARK_TESTS)
    result = run(pytester, [], "-v")
    result.assert_outcomes(passed=4)
    has_line(result, "test_point_by_hand[fog.visibility_m=30]", "PASSED (fog.visibility_m = 30 m: tracking_rate 0.75)")
