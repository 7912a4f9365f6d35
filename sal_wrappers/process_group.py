"""Running an external program in its own process group, with a log and a timeout, so that
nothing it starts outlives the run, nor the process that started it.

``RunGuard`` is shared with ``sal_wrappers.child_process``: it marks a run's environment, starts the
run's watchdog (``sal_wrappers.watchdog``: it kills the run when the parent dies without
cleaning up) and, at the end of the run, kills every marked process that is left.
"""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType
from typing import NamedTuple

from sal_wrappers import watchdog

__all__ = ["KILL_GRACE_S", "GroupRun", "RunGuard", "process_cpu_seconds", "run_process_group", "wait_unreaped"]

#: Seconds between SIGTERM and SIGKILL when a run times out.
KILL_GRACE_S = 3.0


class GroupRun(NamedTuple):
    """What ``run_process_group`` saw: ``status`` (exit status; ``None`` when it never started),
    ``timed_out``, ``wall_time_s``, ``start_error`` (why it did not start) and
    ``cpu_at_timeout_s`` (``RunGuard.cpu_seconds`` when the deadline killed it, else ``None``)."""

    status: int | None
    timed_out: bool
    wall_time_s: float
    start_error: str | None
    cpu_at_timeout_s: float | None = None


class RunGuard:
    """The processes of one run die with it and with the process that started it.

    >>> with RunGuard() as guard:                                    # doctest: +SKIP
    ...     process = subprocess.Popen(argv, env=guard.environ(env), start_new_session=True)
    ...     guard.watch(process.pid)
    ...     ...  # wait; kill the process group; reap the process

    Entering starts the watchdog; ``environ`` marks the child's environment with the run's
    token; ``watch`` tells the watchdog the run's process group. Leaving SIGKILLs every process
    still marked (descendants that left the process group: double forks, ``setsid()``) and lets
    the watchdog go. Killing the process group itself stays with the caller, before it reaps
    the group leader (so that the group id cannot be reused meanwhile).
    """

    def __init__(self) -> None:
        self.token = uuid.uuid4().hex
        self._pipe: int | None = None
        self._watchdog: subprocess.Popen[bytes] | None = None

    def __enter__(self) -> RunGuard:
        read, self._pipe = os.pipe()  # neither end is inherited by the run (close_fds)
        try:
            self._watchdog = subprocess.Popen(
                [sys.executable, "-I", "-S", watchdog.__file__, self.token],
                stdin=read,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                start_new_session=True,
            )
        except BaseException:
            os.close(self._pipe)
            raise
        finally:
            os.close(read)
        return self

    def environ(self, env: Mapping[str, str]) -> dict[str, str]:
        """``env`` with the run's mark added."""
        return {**env, watchdog.mark(self.token): "1"}

    def watch(self, group: int) -> None:
        """Tell the watchdog the run's process group id."""
        self._tell(f"{group}\n")

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None) -> None:
        watchdog.kill_marked(self.token)
        self._tell("done\n")
        assert self._pipe is not None and self._watchdog is not None
        os.close(self._pipe)
        try:
            self._watchdog.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            self._watchdog.kill()
            self._watchdog.wait()

    def cpu_seconds(self) -> float | None:
        """CPU time (s, user + system, with the children each has reaped) the run's processes
        have had so far: every process carrying its mark; ``None`` without ``/proc``. Taken at a
        timeout, it tells a run that was too slow (it used its time) from one the machine
        stopped or throttled (it got little of it)."""
        if not os.path.isdir("/proc"):
            return None
        return sum(process_cpu_seconds(pid) or 0.0 for pid in watchdog.marked_pids(self.token))

    def _tell(self, line: str) -> None:
        try:
            os.write(self._pipe, line.encode())  # type: ignore[arg-type]
        except OSError:
            pass  # the watchdog is gone (killed by someone): the run is still cleaned up here


def process_cpu_seconds(pid: int) -> float | None:
    """CPU time (s) of process ``pid`` from ``/proc/<pid>/stat``: utime + stime + cutime + cstime
    (fields 14-17, in clock ticks); ``None`` when it cannot be read (gone, no ``/proc``)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as handle:
            stat = handle.read()
    except OSError:
        return None
    fields = stat[stat.rfind(b")") + 2 :].split()  # after "pid (comm) ": field 3 is fields[0]
    try:
        ticks = sum(int(fields[i]) for i in range(11, 15))
    except (IndexError, ValueError):
        return None
    return ticks / os.sysconf("SC_CLK_TCK")


def _killpg(pid: int, sig: int) -> None:
    try:
        os.killpg(pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def _exited(process: subprocess.Popen) -> bool:
    """The process has exited (without reaping it, so that its group id stays reserved)."""
    if hasattr(os, "waitid"):
        try:
            return os.waitid(os.P_PID, process.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is not None
        except ChildProcessError:
            return True
    return process.poll() is not None


def wait_unreaped(process: subprocess.Popen[bytes]) -> None:
    """Block until ``process`` exits, without reaping it (see ``_exited``)."""
    if hasattr(os, "waitid"):
        try:
            os.waitid(os.P_PID, process.pid, os.WEXITED | os.WNOWAIT)
        except ChildProcessError:
            pass
    else:
        process.wait()


def run_process_group(command: list[str], cwd: Path, env: dict[str, str], log_path: Path, timeout: float | None) -> GroupRun:
    """Run ``command`` in its own process group with stdout and stderr to ``log_path``.

    Returns a ``GroupRun``; past ``timeout`` the group gets
    SIGTERM, then SIGKILL after ``KILL_GRACE_S``. Whatever is left of the group when the program
    exits is killed too, and so is every process it started that left the group (``RunGuard``);
    when the calling process dies first, the run's watchdog kills them all.
    """
    start = time.monotonic()
    with RunGuard() as guard, open(log_path, "wb") as log:
        log.write(f"$ {shlex.join(command)}\n".encode())
        log.flush()
        try:
            process = subprocess.Popen(
                command,
                cwd=cwd,
                env=guard.environ(env),
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        except FileNotFoundError:
            where = "not on PATH" if os.sep not in command[0] else "no such file"
            return GroupRun(None, False, time.monotonic() - start, f"executable not found: {command[0]!r} ({where})")
        except PermissionError:
            return GroupRun(
                None, False, time.monotonic() - start, f"executable {command[0]!r} cannot be run (permission denied; is it executable?)"
            )
        except OSError as exc:
            return GroupRun(None, False, time.monotonic() - start, f"could not start {command[0]!r}: {exc.strerror or exc}")
        guard.watch(process.pid)
        timed_out, cpu = False, None
        try:
            while not _exited(process):
                if timeout is not None and time.monotonic() - start >= timeout:
                    timed_out, cpu = True, guard.cpu_seconds()
                    _killpg(process.pid, signal.SIGTERM)
                    grace_end = time.monotonic() + KILL_GRACE_S
                    while not _exited(process) and time.monotonic() < grace_end:
                        time.sleep(0.02)
                    break
                time.sleep(0.02)
        finally:
            _killpg(process.pid, signal.SIGKILL)
            status = process.wait()
    return GroupRun(status, timed_out, time.monotonic() - start, None, cpu)
