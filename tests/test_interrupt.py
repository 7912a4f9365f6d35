"""Ctrl-C during a boundary search ends in pytest's interrupted summary, not a traceback
(issue 12: the search ran in fixture setup, and ``tmp_path``'s teardown raised a 60-line
``KeyError: <StashKey>``).

The inner session is started with SIGINT at its default: a test run started in the background
of a non-interactive shell (``.ci/run &``, ``nohup``) ignores SIGINT, the inner session
inherited that and slept on through the search (issue 23, item 16). No clock bounds the wait:
the sleepy system wakes after 60 s a run, so a lost interrupt ends in a passed session, which
fails the test."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

#: a fake system whose first run announces itself and then sleeps until interrupted
CONFTEST = """
import time
from pathlib import Path

import pytest
from pytest_sal.testing import FakeSlam


class SleepySlam(FakeSlam):
    def run(self, sequence, workdir, timeout=None):
        Path(__file__).with_name("running").touch()
        time.sleep(60)
        return super().run(sequence, workdir, timeout)


@pytest.fixture
def sal_system():
    return SleepySlam()


@pytest.fixture(scope="session")
def sal_dataset():
    from sal_adapters import open_dataset

    return open_dataset("synthetic", scene="indoor", frames=8)
"""

SUITE = """
import pytest_sal as sal
from pytest_sal import tracking_rate
from sal_modules import fog


@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25)
def test_fog(sal_outcome):
    pass


@sal.at(fog.visibility_m, 30)
@sal.require(tracking_rate >= 0.5)
def test_point(sal_trial):
    pass
"""


def _default_sigint() -> None:
    """In the child before exec: SIGINT at its default, so Python installs KeyboardInterrupt."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize("test", ["test_fog", "test_point"])
def test_ctrl_c_during_the_search_is_pytests_interrupted_summary(tmp_path: Path, test: str) -> None:
    (tmp_path / "conftest.py").write_text(CONFTEST)
    (tmp_path / "test_suite.py").write_text(SUITE)
    command = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", f"--sal-cache-dir={tmp_path / 'cache'}", f"test_suite.py::{test}"]
    process = subprocess.Popen(
        command,
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=dict(os.environ, PYTHONDONTWRITEBYTECODE="1"),
        preexec_fn=_default_sigint,
    )
    try:
        while not (tmp_path / "running").exists():
            assert process.poll() is None, process.communicate()[0]
            time.sleep(0.05)
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate()
    finally:
        process.kill()
    assert process.returncode == pytest.ExitCode.INTERRUPTED, output
    assert "!!! KeyboardInterrupt !!!" in output, output
    assert "KeyError" not in output and "Traceback" not in output and "teardown" not in output, output
