"""The watchdog of one SLAM run: it kills the run's processes when the process that started
the run dies without cleaning up (SIGKILL, pytest's default SIGTERM, a crash).

Every run is marked: its child starts with ``SAL_RUN_<token>=1`` in its environment, which
everything it starts inherits, double-forked ``setsid()`` daemons included. ``kill_marked``
finds the marked processes in ``/proc/*/environ`` and SIGKILLs them (Linux only: elsewhere it
finds nothing, and only the run's process group is killed). A process that replaces its
environment (``env -i``, a container) is not found this way.

``sal_wrappers.process_group.RunGuard`` starts this file as a script,
``python -I -S watchdog.py TOKEN``, with the read end of a pipe as its stdin; only the parent
holds the write end. The parent writes the run's process group id (a line) once the run has
started, and ``done`` once it has cleaned up itself: the watchdog then exits. End of file
before ``done`` means the parent is gone: the watchdog SIGKILLs the process group and every
marked process, then exits; SIGTERM to the watchdog does the same. It runs in a session of
its own, so a signal to the parent's process group (Ctrl-C, a job control kill) leaves it to
do its work. It imports nothing but ``os``, ``signal``, ``sys`` and ``time`` (a start of
about 20 ms), and uses no ``PR_SET_PDEATHSIG``: that fires when the *thread* that started a
child ends, and the parent starts runs from worker threads.
"""

from __future__ import annotations

import os
import signal
import sys
import time

__all__ = ["KILL_WITHIN_S", "MARK_PREFIX", "kill_marked", "mark", "marked_pids"]

#: Environment variables ``MARK_PREFIX + token`` mark the processes of a run.
MARK_PREFIX = "SAL_RUN_"
#: Seconds ``kill_marked`` keeps killing marked processes that are still alive (or reappear).
KILL_WITHIN_S = 2.0


def mark(token: str) -> str:
    """The name of the environment variable that marks the processes of the run ``token``."""
    return MARK_PREFIX + token


def marked_pids(token: str) -> list[int]:
    """The processes (other than this one) whose environment holds ``mark(token)``; empty
    where there is no ``/proc`` or a process's environment cannot be read (another user's)."""
    needle = b"\0" + mark(token).encode() + b"="
    own = os.getpid()
    try:
        names = os.listdir("/proc")
    except OSError:
        return []
    found = []
    for name in names:
        if not name.isdigit() or int(name) == own:
            continue
        try:
            with open(f"/proc/{name}/environ", "rb") as handle:
                environ = handle.read()
        except OSError:
            continue
        if needle in b"\0" + environ:
            found.append(int(name))
    return found


def kill_marked(token: str, within: float = KILL_WITHIN_S) -> int:
    """SIGKILL every process marked with ``token``, again until none is left (a process may
    fork while it is being killed; a dying one keeps its environment for a moment) or
    ``within`` seconds have passed. Returns how many processes were sent SIGKILL."""
    killed: set[int] = set()
    refused: set[int] = set()
    deadline = time.monotonic() + within
    while True:
        pids = [pid for pid in marked_pids(token) if pid not in refused]
        if not pids or time.monotonic() > deadline:
            return len(killed)
        for pid in pids:
            try:
                os.kill(pid, signal.SIGKILL)
                killed.add(pid)
            except ProcessLookupError:
                pass
            except PermissionError:
                refused.add(pid)
        time.sleep(0.005)


def _watch(token: str) -> int:
    """The watchdog's loop (see the module text)."""
    group = 0

    def clean_up(*_: object) -> None:
        if group > 0:
            try:
                os.killpg(group, signal.SIGKILL)
            except OSError:
                pass
        kill_marked(token)
        os._exit(0)

    signal.signal(signal.SIGTERM, clean_up)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    pending = b""
    while True:
        chunk = os.read(0, 256)
        if not chunk:
            clean_up()
        *lines, pending = (pending + chunk).split(b"\n")
        for line in lines:
            if line == b"done":
                return 0
            group = int(line)


if __name__ == "__main__":
    sys.exit(_watch(sys.argv[1]))
