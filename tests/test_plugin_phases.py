"""The boundary search runs in the test's call phase (``pytest_pyfunc_call``), not in fixture
setup: an error in it fails the test (FAILED, not ERROR), ``--durations`` books its time under
``call``, and a Ctrl-C in it ends the session without a fixture teardown traceback. Inner
sessions run in process (``pytester``) on ``FakeSlam`` variants defined in their conftest."""

from __future__ import annotations

import re

import pytest
from plugin_suites import HEADER, SMALL_DATASET, output, run

#: fake systems per test: one that raises, one that is slow, one that is interrupted
CONFTEST = """
import time

import pytest
from pytest_sal.testing import FakeSlam


class BrokenSlam(FakeSlam):
    def run(self, sequence, workdir, timeout=None):
        raise RuntimeError("SYSTEM-BROKE")


class SlowSlam(FakeSlam):
    def run(self, sequence, workdir, timeout=None):
        time.sleep(SLEEP_S)
        return super().run(sequence, workdir, timeout)


class InterruptedSlam(FakeSlam):
    def run(self, sequence, workdir, timeout=None):
        raise KeyboardInterrupt


@pytest.fixture
def sal_system(request):
    name = request.node.originalname
    return BrokenSlam() if "broken" in name else InterruptedSlam() if "interrupted" in name else SlowSlam()
"""

#: seconds each run of SlowSlam sleeps
SLEEP_S = 0.3

SUITE = """

@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25)
def test_search_broken(sal_outcome):
    raise AssertionError("BODY-RAN")


@sal.at(fog.visibility_m, 30)
@sal.require(tracking_rate >= 0.5)
def test_point_broken(sal_trial):
    raise AssertionError("BODY-RAN")


@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25, max_trials=3)
def test_search_slow(sal_outcome):
    assert len(sal_outcome.trials) == 3


@sal.at(fog.visibility_m, 30)
@sal.require(tracking_rate >= 0.5)
def test_point_slow(sal_trial):
    assert sal_trial.passed


@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25)
def test_search_interrupted(sal_outcome):
    pass


@sal.at(fog.visibility_m, 30)
@sal.require(tracking_rate >= 0.5)
def test_point_interrupted(sal_trial):
    pass
"""


@pytest.fixture
def suite(pytester: pytest.Pytester) -> pytest.Pytester:
    pytester.makeconftest(CONFTEST.replace("SLEEP_S", repr(SLEEP_S)) + SMALL_DATASET)
    pytester.makepyfile(test_suite=HEADER + SUITE)
    return pytester


def test_a_search_whose_system_raises_is_failed_not_error(suite: pytest.Pytester) -> None:
    result = run(suite, [], "-k", "broken", "-rA")
    result.assert_outcomes(failed=2)
    text = output(result)
    assert "SYSTEM-BROKE" in text and "BODY-RAN" not in text, text
    assert "at setup of" not in text and "at teardown of" not in text, text
    result.stdout.fnmatch_lines(["FAILED test_suite.py::test_search_broken*", "FAILED test_suite.py::test_point_broken*"])


def test_durations_book_the_search_under_call(suite: pytest.Pytester) -> None:
    result = run(suite, [], "-k", "slow", "--durations=0", "--durations-min=0", "-vv")
    result.assert_outcomes(passed=2)
    booked = {
        (when, test): float(seconds)
        for seconds, when, test in re.findall(r"^([\d.]+)s (setup|call|teardown)\s+test_suite\.py::(\w+)", output(result), re.M)
    }
    runs = {"test_search_slow": 3, "test_point_slow": 1}  # a SLAM run per trial
    for test, count in runs.items():
        assert booked[("call", test)] >= count * SLEEP_S, booked
        assert booked.get(("setup", test), 0.0) < SLEEP_S, booked


@pytest.mark.parametrize("test", ["test_search_interrupted", "test_point_interrupted"])
def test_ctrl_c_in_the_search_is_not_raised_from_fixture_teardown(suite: pytest.Pytester, test: str) -> None:
    # pytester re-raises a Ctrl-C of its inner session unless told not to
    options = ["-p", "no:cacheprovider", "-p", "no:hypothesispytest", f"--sal-cache-dir={suite.path / 'cache'}"]
    result = suite.runpytest(*options, f"test_suite.py::{test}", no_reraise_ctrlc=True)
    text = output(result)
    assert result.ret == pytest.ExitCode.INTERRUPTED, text
    assert "!!! KeyboardInterrupt !!!" in text, text
    assert "KeyError" not in text and "Traceback" not in text, text
    # where it was raised: the system's run, not a fixture's teardown
    result.stdout.fnmatch_lines(["*!!! KeyboardInterrupt !!!*", "*/conftest.py:*: KeyboardInterrupt"])
