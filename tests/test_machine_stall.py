"""A run the machine stalled is not the system's failure (issue 23, item 4): a run stopped by
SIGSTOP (a frozen VM, a throttled container) times out having had almost no CPU, whatever the
load average said when it started; its timeout is not cached, so the next session on an idle
machine runs it again instead of failing from the cache. A run that used its time is too slow:
its timeout is the system's.

The stalled runs here stop themselves, so their CPU time is near zero on any machine, however
loaded; the deadline is only the product's timeout under test."""

from __future__ import annotations

import signal
import sys
from pathlib import Path

import pytest
from command_programs import indoor, tiny  # noqa: F401 (fixtures)

from pytest_sal import tracking_rate
from pytest_sal.engine.execution.run_job import STALLED_CPU_SHARE, machine_failure
from pytest_sal.engine.execution.trial_runner import TrialRunner
from pytest_sal.engine.requirements import Requirement
from pytest_sal.store.content_cache import ContentCache
from sal_adapters import Sequence
from sal_modules import fog
from sal_wrappers import create
from sal_wrappers.child_process import run_child

QUIET = {"loadavg": [0.1, 0.1, 0.1], "cpus": 16, "usable_cpus": 16}

#: a SLAM program that stops itself before tracking: what a frozen machine does to a run
STOPS_ITSELF = """
import os, signal, sys
print("stopping myself", flush=True)
os.kill(os.getpid(), signal.SIGSTOP)
"""

#: a child entry point (``run_child``) that stops itself the same way
STOPPING_ENTRY = """
import os, signal

def track(header, frames, result_path):
    next(iter(frames))
    os.kill(os.getpid(), signal.SIGSTOP)
"""


@pytest.fixture(autouse=True)
def quiet_machine(monkeypatch: pytest.MonkeyPatch) -> None:
    """The load average at a run's start says the machine is idle: only the run's own CPU may
    tell that it was stalled."""
    monkeypatch.setattr("pytest_sal.engine.execution.run_job.machine_load", lambda: QUIET)


def stopping_program(tmp_path: Path) -> list[str]:
    script = tmp_path / "stops_itself.py"
    script.write_text(STOPS_ITSELF)
    return [sys.executable, str(script), "{sequence}"]


def test_a_command_run_stopped_by_the_machine_is_not_cached_and_runs_again(tmp_path: Path, tiny: Sequence) -> None:  # noqa: F811
    system = create("command", argv=stopping_program(tmp_path), sensor="mono", layout="folder")
    requirement = Requirement.build([tracking_rate >= 0.5, fog.visibility_m >= 25])
    cache = ContentCache(tmp_path / "cache")

    def session() -> dict:
        runner = TrialRunner(tiny, fog.visibility_m.ref(), system, requirement, cache=cache, workdir=tmp_path / "work", timeout=2.0)
        trial = runner.run_trial(40.0)
        assert not trial.passed  # this session's verdict stands: the run did time out
        return trial.runs[0]

    first = session()
    assert first["failure"] == "timed out after 2 s and was killed"
    assert first["not_cached"].startswith("timed out while stalled: it had "), first
    assert not first["cached"]
    second = session()  # the cache holds nothing for it: run again, not read back
    assert not second["cached"] and second["not_cached"].startswith("timed out while stalled")


def test_an_orbslam3_style_child_stopped_by_the_machine_reports_its_cpu_at_the_deadline(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "stopping_entry.py").write_text(STOPPING_ENTRY)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    outcome = run_child("stopping_entry:track", {}, iter([{"frame": 0}, {"frame": 1}]), tmp_path / "w", timeout=2.0)
    assert outcome.timed_out and outcome.exit_status == -signal.SIGKILL
    assert outcome.cpu_at_timeout_s is not None and outcome.cpu_at_timeout_s < STALLED_CPU_SHARE * outcome.wall_time_s


def test_a_timeout_that_used_its_time_is_the_systems(tmp_path: Path, tiny: Sequence) -> None:  # noqa: F811
    """The same timed-out run, told apart only by the CPU it had: the rule itself, so that no
    machine's load decides it."""
    system = create("command", argv=stopping_program(tmp_path), sensor="mono", layout="folder")
    result = system.run(tiny, tmp_path / "w", timeout=1.0)
    assert result.failure == "timed out after 1 s and was killed" and "cpu_at_timeout_s" in result.info
    stalled = machine_failure(result, QUIET)
    assert stalled is not None and stalled.startswith("timed out while stalled")
    busy = result.info | {"cpu_at_timeout_s": 0.9 * result.wall_time_s}
    assert machine_failure(type(result)(**{**vars(result), "info": busy}), QUIET) is None
