"""Running an external program in its own process group, with a log and a timeout, so that
nothing it starts outlives the run."""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
import time
from pathlib import Path

__all__ = ["KILL_GRACE_S", "run_process_group"]

#: Seconds between SIGTERM and SIGKILL when a run times out.
KILL_GRACE_S = 3.0


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


def run_process_group(command: list[str], cwd: Path, env: dict[str, str], log_path: Path, timeout: float | None) -> tuple[int | None, bool, float, str | None]:
    """Run ``command`` in its own process group with stdout and stderr to ``log_path``.

    Returns ``(exit status, timed out, wall time, start error)``; past ``timeout`` the group gets
    SIGTERM, then SIGKILL after ``KILL_GRACE_S``. Whatever is left of the group when the program
    exits is killed too.
    """
    start = time.monotonic()
    with open(log_path, "wb") as log:
        log.write(f"$ {shlex.join(command)}\n".encode())
        log.flush()
        try:
            process = subprocess.Popen(command, cwd=cwd, env=env, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        except FileNotFoundError:
            where = "not on PATH" if os.sep not in command[0] else "no such file"
            return None, False, time.monotonic() - start, f"executable not found: {command[0]!r} ({where})"
        except PermissionError:
            return None, False, time.monotonic() - start, f"executable {command[0]!r} cannot be run (permission denied; is it executable?)"
        except OSError as exc:
            return None, False, time.monotonic() - start, f"could not start {command[0]!r}: {exc.strerror or exc}"
    timed_out = False
    try:
        while not _exited(process):
            if timeout is not None and time.monotonic() - start >= timeout:
                timed_out = True
                _killpg(process.pid, signal.SIGTERM)
                grace_end = time.monotonic() + KILL_GRACE_S
                while not _exited(process) and time.monotonic() < grace_end:
                    time.sleep(0.02)
                break
            time.sleep(0.02)
    finally:
        _killpg(process.pid, signal.SIGKILL)
        status = process.wait()
    return status, timed_out, time.monotonic() - start, None
