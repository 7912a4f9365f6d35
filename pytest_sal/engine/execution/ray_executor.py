"""The ``ray`` executor: every run that is not cached is one Ray task running ``run_job``.

``RayExecutor(address)`` joins or starts a Ray cluster on its first run (``connect``), so a
suite served from the cache never starts Ray:

- ``""``: a local single-node Ray started for this session and shut down by ``close``. Every
  port binds to 127.0.0.1 (the node address is ``127.0.0.1``; that needs
  ``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0`` before Ray is imported, which this module sets when it
  is unset), without the dashboard, with its own temp folder (``/tmp/sal-ray-*``: a stale session
  folder of a killed run would make Ray join a dead cluster) and a 256 MB object store.
- ``"auto"``: the cluster already running on this machine (``ray start --head``).
- ``"ray://host:10001"``: a remote cluster through the Ray client (needs ``ray[client]``).
- ``"host:port"``: a cluster's GCS address; ``address`` gives it once connected, for other
  processes of the session (pytest-xdist workers) to submit to the same cluster.

Token authentication (Ray 2.60 turns it on for a local Ray that ``ray.init`` starts): the token
comes from ``RAY_AUTH_TOKEN``, else the file ``RAY_AUTH_TOKEN_PATH`` names, else
``~/.ray/auth_token`` (which a local start writes, mode 0600, when there is no token: ``private_home_token``). Joining a
``host:port`` address without ``RAY_AUTH_MODE`` set asks the cluster first and turns token
mode on when it wants one (a pytest-xdist worker started before the controller's Ray sees the
token but has no ``RAY_AUTH_MODE=token``).

A task asks for the system's ``resources()`` (CPUs, GPUs, memory) and is retried by Ray
``max_retries`` times when its worker or node is lost; after that the run is a failed run that
names the reason and is never cached (``not_cached``). Ray does not say when a queued task
starts, so a task without a result ``(attempts + 1) x (timeout + RESULT_GRACE_S)`` seconds
after it was submitted (every attempt, and as long again in the queue) is cancelled and is
such a failed run too. A ``SalError`` raised on the worker (the dataset is not readable there)
is raised here as itself.
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

# Ray reads this when it is imported: without it a local Ray's "127.0.0.1" becomes the machine's
# external address, and its ports listen on every interface.
os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")

import ray
from ray._private.authentication.authentication_token_generator import generate_new_authentication_token
from ray._private.authentication.authentication_token_setup import maybe_enable_token_auth_if_token_available
from ray._raylet import GcsClient  # type: ignore[attr-defined]  # the compiled module; its stub leaves it out
from ray.exceptions import (
    AuthenticationError,
    GetTimeoutError,
    LocalRayletDiedError,
    NodeDiedError,
    ObjectLostError,
    OutOfMemoryError,
    RayTaskError,
    WorkerCrashedError,
)

from pytest_sal.engine.execution.executor import Executor, ExecutorError
from pytest_sal.engine.execution.run_job import RunJob, failed_output, run_job, worker_name
from pytest_sal.engine.outcomes.run_record import RunRecord
from sal_adapters.common.errors import SalError
from sal_wrappers import SlamSystem

__all__ = ["OBJECT_STORE_BYTES", "RESULT_GRACE_S", "RayExecutor", "private_home_token"]

#: Seconds a task may take beyond its run's timeout (per attempt) before it is cancelled.
RESULT_GRACE_S = 60.0
#: Object store of a local Ray: PNG bytes and run results are small.
OBJECT_STORE_BYTES = 256 * 2**20
#: Seconds ``slots`` and the resource check reuse what the cluster said.
_VIEW_TTL_S = 0.2
#: Ray errors that say the worker or its node was lost (the machine's failure, retried by Ray).
_LOST = (WorkerCrashedError, NodeDiedError, LocalRayletDiedError, ObjectLostError, OutOfMemoryError)


@dataclass(frozen=True)
class _ClusterView:
    """What the cluster said at ``at`` (``time.monotonic()``): its live nodes' resources."""

    at: float
    nodes: list[dict[str, float]]


def private_home_token() -> Path | None:
    """The token file a local start uses when neither ``RAY_AUTH_TOKEN`` nor
    ``RAY_AUTH_TOKEN_PATH`` is set: ``~/.ray/auth_token``, made here (a new token, mode 0600
    in a folder made 0700) instead of by Ray, which writes it 0644 so that another local user
    can read it and run tasks as this one; an existing one of this user's readable by others
    is made 0600. ``None`` when the environment gives the token."""
    if os.environ.get("RAY_AUTH_TOKEN") or os.environ.get("RAY_AUTH_TOKEN_PATH"):
        return None
    path = Path.home() / ".ray" / "auth_token"
    path.parent.mkdir(mode=0o700, exist_ok=True)
    try:
        descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        status = path.stat()
        if status.st_mode & 0o077 and status.st_uid == os.getuid():
            path.chmod(0o600)
        return path
    with os.fdopen(descriptor, "w") as handle:
        handle.write(generate_new_authentication_token())
    return path


class RayExecutor(Executor):
    """Runs each run as a Ray task; see the module text.

    Args:
        address: ``""`` (start a local Ray), ``"auto"``, ``"ray://host:port"`` or ``"host:port"``.
        num_cpus: CPUs of a local Ray (default: this machine's).
        max_retries: times Ray runs a task again after its worker or node was lost.
        temp_dir: the folder under which a local Ray's session folder is made (default /tmp:
            Ray's socket paths must stay short).
        share: how many controllers submit to the cluster at once (the pytest-xdist workers of
            a session): ``slots`` counts on this one's share of the cluster.
    """

    name = "ray"

    def __init__(
        self, address: str = "", *, num_cpus: int | None = None, max_retries: int = 2, temp_dir: Path | None = None, share: int = 1
    ):
        super().__init__()
        self.share = max(1, int(share))
        self._busy = {"CPU": 0.0, "GPU": 0.0}  # what this executor's runs in flight hold
        self.requested = address
        self.num_cpus = num_cpus
        self.max_retries = max_retries
        self.temp_dir = temp_dir
        self._lock = threading.Lock()
        self._connected = False
        self._owns = False  # this executor started the connection (close ends it)
        self._folder: Path | None = None  # a local Ray's session folder (close removes it)
        self._gcs = ""
        self._view: _ClusterView | None = None

    # -- connection --------------------------------------------------------------------------------
    @property
    def address(self) -> str:
        """Where other processes reach the same cluster: once connected, the GCS address
        ``host:port`` (a ``ray://`` address stays as given); before, the address given."""
        return self._gcs if self._connected else self.requested

    @property
    def session_folder(self) -> Path | None:
        """The temp folder of the local Ray this executor started (its session, sockets and
        logs, ``session_latest/logs``), removed by ``close``; ``None`` otherwise."""
        return self._folder

    def connect(self) -> None:
        """Join or start the cluster (once; later calls return at once). ``ExecutorError`` when
        it cannot be reached or a local Ray does not come up on loopback."""
        with self._lock:
            if self._connected:
                return
            if ray.is_initialized():  # this process is connected already (a user's ray.init)
                current = ray.get_runtime_context().gcs_address
                if self.requested not in ("", "auto", current):
                    raise ExecutorError(
                        f"this process is already connected to the Ray cluster at {current}; it cannot join {self.requested}"
                    )
            elif self.requested:
                self._join()
            else:
                self._start_local()
            self._gcs = self.requested if self.requested.startswith("ray://") else ray.get_runtime_context().gcs_address
            self._connected = True

    def _start_local(self) -> None:
        root = self.temp_dir if self.temp_dir is not None else Path("/tmp")
        self._folder = Path(tempfile.mkdtemp(prefix="sal-ray-", dir=root))
        try:
            private_home_token()
            ray.init(
                num_cpus=self.num_cpus if self.num_cpus is not None else os.cpu_count(),
                _node_ip_address="127.0.0.1",
                include_dashboard=False,
                _temp_dir=str(self._folder),
                object_store_memory=OBJECT_STORE_BYTES,
                log_to_driver=False,
                logging_level=logging.WARNING,
            )
        except Exception as exc:
            self._shutdown()
            raise ExecutorError(f"cannot start a local Ray in {root}: {exc}") from exc
        self._owns = True
        where = sorted({node["NodeManagerAddress"] for node in ray.nodes() if node["Alive"]})
        if where != ["127.0.0.1"]:
            self._shutdown()
            raise ExecutorError(
                f"the local Ray came up on {', '.join(where)}, not on loopback: Ray was imported before pytest_sal.engine.execution.ray_executor "
                "set RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0 (set it to 0 in the environment)"
            )

    def _join(self) -> None:
        if not self.requested.startswith("ray://") and self.requested != "auto":
            self._follow_token_mode()
        try:
            ray.init(address=self.requested, log_to_driver=False, logging_level=logging.WARNING)
        except Exception as exc:
            raise ExecutorError(
                f"cannot join the Ray cluster at {self.requested}: {exc}. A cluster with token authentication needs its token here "
                "(RAY_AUTH_TOKEN, or the file RAY_AUTH_TOKEN_PATH names, or ~/.ray/auth_token) and RAY_AUTH_MODE=token"
            ) from exc
        self._owns = True

    def _follow_token_mode(self) -> None:
        """Use token authentication when the cluster at the GCS address asks for it and
        ``RAY_AUTH_MODE`` does not say (a pytest-xdist worker started before the controller's
        Ray has neither); ``ExecutorError`` when it cannot be reached or no token is here."""
        if os.environ.get("RAY_AUTH_MODE") is not None:
            return
        try:
            GcsClient(address=self.requested)  # answers at once: in the mode of this process (no token)
        except AuthenticationError:
            if not maybe_enable_token_auth_if_token_available(warn_if_disabled=False):
                raise ExecutorError(
                    f"the Ray cluster at {self.requested} asks for its token and none is here: set RAY_AUTH_TOKEN (or the file "
                    "RAY_AUTH_TOKEN_PATH names, or ~/.ray/auth_token)"
                ) from None
        except Exception as exc:
            raise ExecutorError(f"cannot reach the Ray cluster at {self.requested}: {exc}") from exc

    def close(self) -> None:
        """Disconnect: shut down the local Ray this executor started and remove its folder (a
        cluster it joined keeps running)."""
        with self._lock:
            self._shutdown()
            self._connected = False

    def _shutdown(self) -> None:
        if self._owns:
            ray.shutdown()
            self._owns = False
        if self._folder is not None:
            shutil.rmtree(self._folder, ignore_errors=True)
            self._folder = None

    # -- the cluster ---------------------------------------------------------------------------------
    def _cluster(self) -> _ClusterView:
        """What the cluster says now, asked at most every ``_VIEW_TTL_S`` seconds."""
        view = self._view
        if view is None or time.monotonic() - view.at > _VIEW_TTL_S:
            nodes = [node["Resources"] for node in ray.nodes() if node["Alive"]]
            view = self._view = _ClusterView(time.monotonic(), nodes)
        return view

    def slots(self, system: SlamSystem) -> int:
        """How many more runs of ``system`` fit this executor's share of the cluster now (its
        CPUs, and GPUs when the system asks for some, over ``share``, less what its own runs in
        flight hold), at least 1. The cluster's size, not the free resources Ray reports, which
        lag the runs that just ended by about half a second; so the width of a search follows
        the cluster, not the timing. Before connecting: a local Ray's CPUs, or 1 for a cluster
        not yet joined."""
        needs = system.resources()
        if not self._connected:
            total = {"CPU": float((self.num_cpus or os.cpu_count() or 1) if not self.requested else needs["num_cpus"])}
        else:
            total = {kind: sum(node.get(kind, 0.0) for node in self._cluster().nodes) for kind in ("CPU", "GPU")}
        with self._lock:
            free = {kind: total.get(kind, 0.0) / self.share - self._busy[kind] for kind in ("CPU", "GPU")}
        fits = free.get("CPU", 0.0) // needs["num_cpus"] if needs["num_cpus"] > 0 else float("inf")
        if needs["num_gpus"] > 0:
            fits = min(fits, free.get("GPU", 0.0) // needs["num_gpus"])
        return max(1, int(min(fits, 1024)))

    def describe(self) -> str:
        """``ray at 127.0.0.1:PORT: 2 nodes, 4 CPUs, 0 GPUs``; before connecting, where it will go."""
        if not self._connected:
            return "ray (local, starts on the first run)" if not self.requested else f"ray at {self.requested} (joined on the first run)"
        nodes = self._cluster().nodes
        cpus, gpus = (sum(node.get(kind, 0.0) for node in nodes) for kind in ("CPU", "GPU"))
        return f"ray at {self.address}: {len(nodes)} node{'s' * (len(nodes) != 1)}, {cpus:g} CPUs, {gpus:g} GPUs"

    def _task_options(self, system: SlamSystem) -> dict[str, Any]:
        """The Ray task options of a run of ``system``; ``ExecutorError`` when no node has that much."""
        needs = system.resources()
        options: dict[str, Any] = {"num_cpus": needs["num_cpus"], "num_gpus": needs["num_gpus"], "max_retries": self.max_retries}
        wanted = {"CPU": needs["num_cpus"], "GPU": needs["num_gpus"]}
        if needs["memory"] is not None:
            options["memory"] = wanted["memory"] = needs["memory"]
        nodes = self._cluster().nodes
        if not any(all(node.get(kind, 0.0) >= amount for kind, amount in wanted.items()) for node in nodes):
            asked = ", ".join(f"{kind} {amount:g}" for kind, amount in wanted.items())
            raise ExecutorError(
                f"{system.name} asks for {asked} per run, but no node of the Ray cluster at {self.address} has that much "
                f"({self.describe()}): set the system's num_cpus / num_gpus / memory, or add a node that fits"
            )
        return options

    # -- runs ----------------------------------------------------------------------------------------
    def _run(self, job: RunJob) -> RunRecord:
        self.connect()
        options = self._task_options(job.system)
        held = {"CPU": options["num_cpus"], "GPU": options["num_gpus"]}
        with self._lock:
            for kind, amount in held.items():
                self._busy[kind] += amount
        try:
            return self._submit(job, options)
        finally:
            with self._lock:
                for kind, amount in held.items():
                    self._busy[kind] -= amount

    def _submit(self, job: RunJob, options: dict[str, Any]) -> RunRecord:
        """Run ``job`` as a task with ``options`` and wait for it (see ``_run``)."""
        ref = _TASK.options(**options).remote(job)
        attempts = self.max_retries + 1
        # Ray does not say when a task starts: the wait counts from here and allows one more run
        # for a place in the queue (a busy shared cluster)
        limit = None if job.timeout is None else (attempts + 1) * (job.timeout + RESULT_GRACE_S)
        try:
            record: RunRecord = ray.get(ref, timeout=limit)
            return record
        except GetTimeoutError:
            ray.cancel(ref, force=True)
            reason = (
                f"no result from the Ray worker within {limit:g} s ({attempts} attempt(s) of timeout {job.timeout:g} s "
                f"+ {RESULT_GRACE_S:g} s, and as long again to wait for a worker): cancelled"
            )
            return failed_output(job, reason, reason)
        except RayTaskError as exc:
            if isinstance(exc.cause, SalError):
                raise exc.cause from None
            raise
        except _LOST as exc:
            lost = "Ray worker out of memory" if isinstance(exc, OutOfMemoryError) else f"Ray worker lost {attempts} times"
            reason = f"{lost}: {_first_sentence(exc)}"
            return failed_output(job, reason, reason)


def _first_sentence(error: Exception, most: int = 160) -> str:
    """``WorkerCrashedError: The worker died unexpectedly while executing this task``: the
    error's kind and its first sentence, at most ``most`` characters."""
    text = str(error).strip().splitlines()[0] if str(error).strip() else ""
    text = text.split(". ")[0].rstrip(".")
    return f"{type(error).__name__}: {text[:most]}"


def _on_worker(job: RunJob) -> RunRecord:
    """The Ray task: run ``job`` on this worker, naming it and its Ray node."""
    node = ray.get_runtime_context().get_node_id()
    return run_job(job, worker=f"{worker_name()} on Ray node {node[:12]} ({ray.util.get_node_ip_address()})")


_TASK = ray.remote(_on_worker)
