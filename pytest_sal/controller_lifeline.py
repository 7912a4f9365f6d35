"""An xdist worker dies with its controller.

Killing ``pytest -n 2`` (a cancelled CI job: SIGTERM, then SIGKILL) killed only the controller;
its workers went on running, with their SLAM programs and the daemons those started, until
execnet noticed the closed channel about 15 s later. ``follow_controller`` makes a worker
SIGKILL itself within ``POLL_S`` of its parent's death; each run's watchdog
(``sal_wrappers.watchdog``) then kills the run's processes, as it does when a serial session
is killed.
"""

from __future__ import annotations

import os
import signal
import threading
import time

__all__ = ["POLL_S", "follow_controller"]

#: How often (s) a worker checks that its controller is alive.
POLL_S = 0.2


def follow_controller() -> threading.Thread:
    """Start a daemon thread that SIGKILLs this process once its parent (the controller that
    started it) has died: the process is then re-parented, so ``os.getppid()`` changes."""
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(POLL_S)
        os.kill(os.getpid(), signal.SIGKILL)

    thread = threading.Thread(target=watch, name="sal-controller-lifeline", daemon=True)
    thread.start()
    return thread
