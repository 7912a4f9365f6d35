"""``sal.sweep`` items as users address them: ids that carry the level name (``-k``, ``--lf``,
the report), and ``sal_trial.metrics`` read like ``RunMetrics`` in a test body. Inner sessions
on ``FakeSlam`` (``plugin_suites``), which tracks ``min(1, v / 40)`` of the frames at fog
visibility ``v``: on the 20-frame world 100 m -> 1.0, 30 m -> 0.75, 10 m -> 0.25."""

from __future__ import annotations

import pytest
from plugin_suites import has_line, output, project, run

LEVEL_TESTS = """

@sal.sweep(fog.visibility_m, L=100, M=30, H=10)
@sal.require(tracking_rate >= 0.5)
def test_levels(sal_trial):
    assert sal_trial.metrics.tracking_rate >= 0.5
    assert sal_trial.metrics.tracking_rate == sal_trial.metrics["tracking_rate"]
    assert sal_trial.metrics.scale_error is None  # stereo: no scale error, read as None
    with pytest.raises(AttributeError, match="did you mean 'tracking_rate'"):
        sal_trial.metrics.tracking_rte


@sal.at(fog.visibility_m, 30)
@sal.require(tracking_rate >= 0.7)
def test_point(sal_trial):
    assert sal_trial.metrics.tracking_rate == 0.75
"""

IDS = [
    "test_levels[L-fog.visibility_m=100]",
    "test_levels[M-fog.visibility_m=30]",
    "test_levels[H-fog.visibility_m=10]",
    "test_point[fog.visibility_m=30]",
]


def test_level_names_in_ids_select_with_k(pytester: pytest.Pytester) -> None:
    project(pytester, LEVEL_TESTS)
    collected = run(pytester, [], "--collect-only", "-q")
    assert [line.split("::")[-1] for line in collected.outlines if "::" in line] == IDS
    for expression, selected in (("[H-", IDS[2:3]), ("test_levels and not [L-", IDS[1:3]), ("M-fog", IDS[1:2])):
        only = run(pytester, [], "--collect-only", "-q", "-k", expression)
        assert [line.split("::")[-1] for line in only.outlines if "::" in line] == selected, expression


def test_metrics_by_attribute_in_the_body_and_lf_reruns_the_failed_level(pytester: pytest.Pytester) -> None:
    project(pytester, LEVEL_TESTS)
    folders = (f"--sal-cache-dir={pytester.path / 'cache'}", f"--sal-history-dir={pytester.path / 'history'}")
    first = pytester.runpytest("-p", "no:hypothesispytest", *folders, "-v")  # with pytest's cache: --lf reads it
    first.assert_outcomes(passed=3, failed=1)  # H (10 m) tracks 0.25 < 0.5: fails before the body
    has_line(first, "test_levels[M-fog.visibility_m=30]", "PASSED (fog.visibility_m = 30 m: tracking_rate 0.75)")
    has_line(first, "test_levels[H-fog.visibility_m=10]", "FAILED")
    assert "AttributeError" not in output(first)
    again = pytester.runpytest("-p", "no:hypothesispytest", *folders, "-v", "--lf")
    again.assert_outcomes(failed=1)
    assert "run-last-failure: rerun previous 1 failure" in output(again) and "PASSED" not in output(again)
    has_line(again, "test_levels[H-fog.visibility_m=10]", "FAILED")
