"""Where runs happen: the executor seam.

A ``TrialRunner`` hands every run that is not in the cache to an ``Executor`` as a ``RunJob``
and gets a ``RunRecord`` back; the cache, the verdicts, the search and the history stay on the
controller (the pytest session), so results of every executor are interchangeable and a cached
run is never sent anywhere.

- ``local`` (``LocalExecutor``, the default): the run happens in this process, one at a time
  (the system still starts its own child process where it crashes easily).
- ``ray`` (``pytest_sal.engine.execution.ray_executor.RayExecutor``): each run is a Ray task on a local or
  remote Ray cluster, several at once; the search then evaluates several points per round.

``pytest_sal.engine.execution.executor_factory.make_executor`` makes the one ``--sal-executor`` names
(Ray is imported only then).

``Executor.run`` blocks until the run is done and is safe to call from several threads at once:
the runner runs a batch of runs, and the search a round of trials, each in its own thread.
"""

from __future__ import annotations

import threading
from typing import Any

from pytest_sal.engine.execution.run_job import RunJob, run_job
from pytest_sal.engine.outcomes.run_record import RunRecord
from sal_adapters.common.errors import SalError
from sal_wrappers import SlamSystem

__all__ = ["EXECUTORS", "Executor", "ExecutorError", "LocalExecutor"]

#: The executors ``--sal-executor`` takes.
EXECUTORS = ("local", "ray")


class ExecutorError(SalError):
    """An executor cannot be made or reached: an unknown name, Ray not installed, a Ray cluster
    that cannot be joined or cannot fit a system's resources."""


class Executor:
    """Runs ``RunJob``s; the base class is also the interface.

    Attributes:
        name: ``local`` or ``ray``.
        submitted: runs handed to this executor so far (a cached run is never handed over).
    """

    name: str = ""

    def __init__(self) -> None:
        self.submitted = 0
        self._count_lock = threading.Lock()

    def run(self, job: RunJob) -> RunRecord:
        """Run ``job`` and wait for its record. Failures of the system come back in the record;
        an exception means the run could not happen at all (a usage error)."""
        with self._count_lock:
            self.submitted += 1
        return self._run(job)

    def slots(self, system: SlamSystem) -> int:
        """How many runs of ``system`` can go at once now (1 for ``local``)."""
        return 1

    def describe(self) -> str:
        """One line for the session header."""
        return self.name

    def close(self) -> None:
        """Release what the executor holds (a Ray connection, a local Ray it started)."""

    def _run(self, job: RunJob) -> RunRecord:
        raise NotImplementedError

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class LocalExecutor(Executor):
    """Runs in this process, one run at a time: the behaviour before executors existed."""

    name = "local"

    def _run(self, job: RunJob) -> RunRecord:
        return run_job(job)
