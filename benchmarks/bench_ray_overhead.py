"""What the Ray executor costs beside the local one: Ray's start, the time a run spends going to a
Ray worker and back, and ``RayExecutor.slots``.

A run here is ``FakeSlam`` (returns at once) on 4 synthetic indoor frames in fog, scored like any
run: the same work either way, so ``ray - local`` per run is the Ray path's overhead (pickling
the job and the output, scheduling, the object store). Runs go one at a time, after one
warm-up run each way (a fresh Ray worker imports pytest-sal first). Run from the repository root:

    .venv/bin/python benchmarks/bench_ray_overhead.py              # 50 runs each way
    .venv/bin/python benchmarks/bench_ray_overhead.py --runs 200 --two-node
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from pytest_sal.engine.execution.executor import Executor, LocalExecutor
from pytest_sal.engine.execution.ray_executor import RayExecutor
from pytest_sal.engine.execution.run_job import RunJob
from pytest_sal.testing import FakeSlam
from sal_adapters import open_dataset
from sal_modules import fog


def job(workdir: Path, number: int) -> RunJob:
    dataset = open_dataset("synthetic", scene="indoor", frames=4, sensor="rgbd")
    return RunJob(
        key=f"{number:064d}",
        number=number,
        value=20.0,
        label="fog.visibility_m = 20 m",
        dataset=dataset,
        module=fog(visibility_m=20.0),
        system=FakeSlam(),
        seed=0,
        workdir=workdir,
        timeout=60.0,
        kitti_segments=(100.0,),
    )


def ms_per_run(executor: Executor, workdir: Path, runs: int) -> float:
    """Milliseconds per run of ``runs`` runs one after the other, after one warm-up run."""
    executor.run(job(workdir, 0))
    start = time.perf_counter()
    for number in range(runs):
        executor.run(job(workdir, number))
    return (time.perf_counter() - start) / runs * 1000


def seconds(action: Callable[[], object]) -> float:
    start = time.perf_counter()
    action()
    return time.perf_counter() - start


def two_node_start() -> float:
    """Seconds to start a two-node ray.cluster_utils.Cluster (1 CPU each, on 127.0.0.1) and join it."""
    from ray.cluster_utils import Cluster

    folder = Path(tempfile.mkdtemp(prefix="sal-ray-", dir="/tmp"))
    (folder / "ray").mkdir()
    os.environ["RAY_TMPDIR"] = str(folder)  # where Cluster notes its address: not the shared /tmp/ray
    node = {"num_cpus": 1, "node_ip_address": "127.0.0.1", "temp_dir": str(folder), "object_store_memory": 100 * 2**20}
    start = time.perf_counter()
    cluster = Cluster()
    try:
        cluster.add_node(**node, include_dashboard=False)  # the head
        cluster.add_node(**node)
        cluster.wait_for_nodes()
        executor = RayExecutor(cluster.address)
        executor.connect()
        took = time.perf_counter() - start
        executor.close()
        return took
    finally:
        cluster.shutdown()
        shutil.rmtree(folder, ignore_errors=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=50, help="runs each way (default 50)")
    parser.add_argument("--two-node", action="store_true", help="also time a two-node cluster's start (after the local Ray)")
    args = parser.parse_args()
    rows: list[tuple[str, str]] = []
    with tempfile.TemporaryDirectory(prefix="sal-bench-") as tmp:
        workdir = Path(tmp)
        local = ms_per_run(LocalExecutor(), workdir, args.runs)
        ray = RayExecutor(num_cpus=2)
        rows.append(("local Ray start (2 CPUs), s", f"{seconds(ray.connect):.2f}"))
        on_ray = ms_per_run(ray, workdir, args.runs)
        rows += [
            (f"local executor, ms/run ({args.runs} runs)", f"{local:.1f}"),
            (f"ray executor, ms/run ({args.runs} runs)", f"{on_ray:.1f}"),
            ("ray overhead, ms/run", f"{on_ray - local:.1f}"),
        ]
        system = FakeSlam()
        calls = 10_000
        rows.append(("slots(), cached view, us/call", f"{seconds(lambda: [ray.slots(system) for _ in range(calls)]) / calls * 1e6:.1f}"))
        fresh = []
        for _ in range(200):
            ray._view = None  # ask the cluster every time
            fresh.append(seconds(lambda: ray.slots(system)))
        rows.append(("slots(), asking the cluster, ms/call", f"{sum(fresh) / len(fresh) * 1000:.2f}"))
        ray.close()
        if args.two_node:
            rows.append(("two-node cluster start and join, s", f"{two_node_start():.2f}"))
    width = max(len(name) for name, _ in rows)
    for name, value in rows:
        print(f"{name:<{width}}  {value:>8}")


if __name__ == "__main__":
    main()
