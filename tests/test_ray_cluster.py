"""RayExecutor on a two-node Ray cluster on this machine (ray.cluster_utils.Cluster: two raylets,
1 CPU each, both on 127.0.0.1): runs added together go to both nodes at once, the outcome is the
local executor's, every port stays on loopback, and closing the executor leaves the cluster it
joined running."""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from ray_clusters import listening_addresses, ray_environment, session_processes, wait_until_gone

from pytest_sal import tracking_rate
from pytest_sal.engine.execution.executor import Executor, LocalExecutor
from pytest_sal.engine.execution.ray_executor import RayExecutor
from pytest_sal.engine.execution.run_job import RunJob
from pytest_sal.engine.execution.trial_runner import TrialRunner
from pytest_sal.engine.outcomes.outcome import Outcome, Trial
from pytest_sal.engine.outcomes.run_record import RunRecord
from pytest_sal.engine.requirements import Requirement
from pytest_sal.engine.search.requirement_search import SearchSettings, search_outcome
from pytest_sal.store.content_cache import ContentCache
from sal_adapters import open_dataset
from sal_modules import fog
from sal_wrappers import SlamSystem, create


@dataclass
class TwoNodes:
    executor: RayExecutor
    cluster: Any  # ray.cluster_utils.Cluster
    folder: Path


@pytest.fixture(scope="module")
def two_nodes() -> Iterator[TwoNodes]:
    """A head and a second node, 1 CPU each, joined by a RayExecutor at the head's GCS address."""
    from ray.cluster_utils import Cluster  # after pytest_sal.engine.execution.ray_executor: node addresses on 127.0.0.1

    folder = Path(tempfile.mkdtemp(prefix="sal-ray-", dir="/tmp"))
    (folder / "ray").mkdir()  # Cluster notes its address in $RAY_TMPDIR/ray, not in the shared /tmp/ray
    node = {"num_cpus": 1, "node_ip_address": "127.0.0.1", "temp_dir": str(folder), "object_store_memory": 100 * 2**20}
    with ray_environment(), pytest.MonkeyPatch.context() as patch:
        patch.setenv("RAY_TMPDIR", str(folder))
        # token mode for the cluster's processes (the environment) and this one (Ray's cached config),
        # as a local ray.init sets it: the modules' clusters then agree whichever started first
        from ray._private.authentication.authentication_token_setup import _enable_token_auth

        _enable_token_auth()
        cluster = Cluster(initialize_head=True, head_node_args={**node, "include_dashboard": False})
        try:
            cluster.add_node(**node)
            cluster.wait_for_nodes()
            executor = RayExecutor(cluster.address)
            yield TwoNodes(executor, cluster, folder)
            executor.close()
        finally:
            cluster.shutdown()
            shutil.rmtree(folder, ignore_errors=True)


class Spy(Executor):
    """Passes runs on to ``inner`` and keeps where each ran."""

    name = "spy"

    def __init__(self, inner: Executor):
        super().__init__()
        self.inner = inner
        self.workers: list[str] = []

    def _run(self, job: RunJob) -> RunRecord:
        output = self.inner.run(job)
        self.workers.append(output.worker)
        return output

    def slots(self, system: SlamSystem) -> int:
        return self.inner.slots(system)


def search(executor: Executor, cache: Path) -> Outcome:
    """reference_vo's boundary of tracking_rate >= 0.9 in fog on 10 street frames, searched as a
    noisy system (2 runs a trial: the reliability search, several runs a round)."""
    requirement = Requirement.build([tracking_rate >= 0.9, fog.visibility_m >= 200])
    dataset = open_dataset("synthetic", scene="urban", frames=10, sensor="mono")
    runner = TrialRunner(
        dataset,
        fog.visibility_m.ref(),
        create("reference_vo"),
        requirement,
        runs=2,
        cache=ContentCache(cache),
        workdir=cache / "work",
        executor=executor,
    )
    return search_outcome(runner, requirement, SearchSettings(tolerance_pct=25.0, max_trials=4), "test_fog")


def test_the_search_on_two_nodes_gives_the_local_outcome(two_nodes: TwoNodes, tmp_path: Path) -> None:
    executor = two_nodes.executor
    assert executor.slots(create("reference_vo")) == 1  # not connected yet: a joined cluster's size is unknown
    on_ray = search(executor, tmp_path / "ray")
    assert executor.describe() == f"ray at {two_nodes.cluster.address}: 2 nodes, 2 CPUs, 0 GPUs"
    local = search(LocalExecutor(), tmp_path / "local")
    # runs are placed by the slots free at each round (two on Ray once connected, one here), so the paths differ;
    # the verdict and the interval of s80 agree
    assert on_ray.verdict == local.verdict == "passed" and on_ray.boundary.noisy
    ray_low, ray_high = sorted(on_ray.boundary.interval)
    local_low, local_high = sorted(local.boundary.interval)
    assert ray_low <= local_high and local_low <= ray_high
    assert executor.submitted == sum(len(t.runs) for t in on_ray.trials) > len(on_ray.trials)  # several runs a trial


def test_runs_added_together_go_to_both_nodes_at_once(two_nodes: TwoNodes, tmp_path: Path) -> None:
    two_nodes.executor.connect()
    spy = Spy(two_nodes.executor)
    dataset = open_dataset("synthetic", scene="urban", frames=30, sensor="mono")  # about 1 s a run: both runs are in flight together
    requirement = Requirement.build([tracking_rate >= 0.9, fog.visibility_m >= 200])
    runner = TrialRunner(dataset, fog.visibility_m.ref(), create("reference_vo"), requirement, runs=2, workdir=tmp_path, executor=spy)
    trial = Trial(value=200.0, passed=False)
    first, second = runner.add_runs(trial, 2)
    assert first["passed"] and second["passed"] and first["ate_rmse"] == second["ate_rmse"]
    nodes = {worker.split(" on Ray node ")[1] for worker in spy.workers}
    assert len(nodes) == 2, spy.workers


def test_every_port_of_the_cluster_is_on_loopback(two_nodes: TwoNodes) -> None:
    two_nodes.executor.connect()
    processes = session_processes(two_nodes.folder)
    assert len([pid for pid in processes if "raylet" in Path(f"/proc/{pid}/comm").read_text()]) == 2
    assert listening_addresses(processes) == {"127.0.0.1"}


def test_closing_the_executor_leaves_the_joined_cluster_running(two_nodes: TwoNodes) -> None:
    two_nodes.executor.connect()
    two_nodes.executor.close()
    assert session_processes(two_nodes.folder) and two_nodes.folder.exists()
    two_nodes.cluster.shutdown()
    assert wait_until_gone(two_nodes.folder) == set()
