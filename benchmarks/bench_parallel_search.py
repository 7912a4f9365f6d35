"""The boundary search with k free workers (speculative k-ary bisection) against the sequential
one, on a system whose runs take a fixed time and need no CPU.

``pytest_sal.testing.SleepySlam`` sleeps ``--sleep`` seconds a run and tracks every frame on
the mild side of 20 m fog visibility (a quarter beyond); the requirement is
``tracking_rate >= 0.5`` with the envelope ``fog.visibility_m >= 25`` over fog's search range
(1-100000 m), to ``--tolerance-pct`` of the bracket's larger end. For each k the search may run
k runs at once (the executor's slots, at most k): the table gives its rounds, the trials on
its path, the speculative ones, the runs, the wall time (median of ``--repeats``) and the
interval, which must be the same for every k (the script exits 1 when it is not).

``--executor threads``: a run happens in the thread that hands it over (the search runs a
round's trials in threads), so the scheduling is measured beyond the machine's cores.
``--executor ray``: runs are Ray tasks (``pytest_sal.engine.execution.ray_executor.RayExecutor``) on a
local Ray with ``--num-cpus`` logical CPUs (default: the largest k) or the cluster at
``--address``. No cache: every trial runs. From the repository root:

    PYTHONPATH=. .venv/bin/python benchmarks/bench_parallel_search.py --executor threads --k 1 2 4
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pytest_sal import tracking_rate
from pytest_sal.engine.execution.executor import Executor
from pytest_sal.engine.execution.run_job import RunJob
from pytest_sal.engine.execution.trial_runner import TrialRunner
from pytest_sal.engine.outcomes.outcome import Boundary
from pytest_sal.engine.outcomes.run_record import RunRecord
from pytest_sal.engine.requirements import Requirement
from pytest_sal.engine.search.requirement_search import SearchSettings, deterministic_search
from pytest_sal.testing import InProcessSlots, SleepySlam
from sal_adapters import open_dataset
from sal_modules import fog


class Capped(Executor):
    """Another executor's runs, at most ``k`` at once (one Ray for every k)."""

    def __init__(self, inner: Executor, k: int):
        super().__init__()
        self.inner, self.k, self.name = inner, k, inner.name

    def slots(self, system: Any) -> int:
        return min(self.k, self.inner.slots(system))

    def _run(self, job: RunJob) -> RunRecord:
        return self.inner.run(job)


@dataclass
class Row:
    """One k's search: what the table shows."""

    k: int
    rounds: int
    path: int
    speculative: int
    runs: int
    wall_s: float
    interval: str


def measure(k: int, base: Executor | None, args: argparse.Namespace, workdir: Path, repeats: int) -> Row:
    """Search ``repeats`` times with at most ``k`` runs at once; the median wall time (the rest
    is the same every time: the system is deterministic and nothing is cached)."""
    dataset = open_dataset("synthetic", scene="indoor", frames=args.frames, sensor="rgbd")
    requirement = Requirement.build([tracking_rate >= 0.5, fog.visibility_m >= 25])
    settings = SearchSettings(tolerance_pct=args.tolerance_pct, max_trials=args.max_trials)
    rows = []
    for repeat in range(repeats):
        executor = InProcessSlots(k) if base is None else Capped(base, k)
        system = SleepySlam(sleep_s=args.sleep)
        runner = TrialRunner(dataset, fog.visibility_m.ref(), system, requirement, workdir=workdir / f"k{k}-{repeat}", executor=executor)
        start = time.perf_counter()
        result = deterministic_search(runner, requirement, settings)
        wall = time.perf_counter() - start
        path = sum(not t.speculative for t in result.trials)
        interval = Boundary(result.pass_value, result.fail_value, "m").text()
        runs = sum(len(t.info.runs) for t in result.trials)
        rows.append(Row(k, result.rounds, path, result.speculative, runs, wall, interval))
    return dataclasses.replace(rows[0], wall_s=statistics.median(r.wall_s for r in rows))


def ray_executor(args: argparse.Namespace) -> Executor:
    """A ``RayExecutor`` on the cluster at ``--address`` or a local Ray with ``--num-cpus``."""
    try:
        from pytest_sal.engine.execution.ray_executor import RayExecutor  # type: ignore[import-not-found,unused-ignore]
    except ImportError as exc:
        raise SystemExit(f"--executor ray needs pytest_sal.engine.execution.ray_executor.RayExecutor and ray: {exc}") from None
    executor: Executor = RayExecutor(address=args.address, num_cpus=args.num_cpus or max(args.k))
    return executor


def table(rows: list[Row], args: argparse.Namespace) -> str:
    """The rows as a Markdown table, with the setting above it."""
    lines = [
        f"executor {args.executor}, runs of {args.sleep:g} s (sleeping), {args.frames} frames, "
        f"tolerance {args.tolerance_pct:g} %, max_trials {args.max_trials}, median of {args.repeats}",
        "",
        "| k | rounds | trials on the path | speculative | runs | wall time (s) | interval |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r.k} | {r.rounds} | {r.path} | {r.speculative} | {r.runs} | {r.wall_s:.2f} | {r.interval} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--executor", choices=("threads", "ray"), default="threads")
    parser.add_argument("--k", type=int, nargs="+", default=[1, 2, 4], help="most runs at once (default 1 2 4)")
    parser.add_argument("--sleep", type=float, default=0.3, help="seconds each run sleeps (default 0.3)")
    parser.add_argument("--frames", type=int, default=8, help="frames of the synthetic sequence (default 8)")
    parser.add_argument("--tolerance-pct", type=float, default=5.0, help="relative tolerance, %% (default 5)")
    parser.add_argument("--max-trials", type=int, default=12, help="trial budget on the path (default 12)")
    parser.add_argument("--repeats", type=int, default=3, help="searches per k, median wall time (default 3)")
    parser.add_argument("--address", default="", help="ray: the cluster's address (empty: a local Ray)")
    parser.add_argument("--num-cpus", type=int, default=None, help="ray: logical CPUs of a local Ray (default: the largest k)")
    args = parser.parse_args(argv)
    if min(args.k) < 1:
        parser.error(f"--k takes whole numbers from 1; got {min(args.k)}")

    base = ray_executor(args) if args.executor == "ray" else None
    try:
        with tempfile.TemporaryDirectory(prefix="sal-bench-search-") as folder:
            measure(max(args.k), base, args, Path(folder) / "warm-up", 1)  # imports, and as many Ray workers as the widest round
            rows = [measure(k, base, args, Path(folder), args.repeats) for k in args.k]
    finally:
        if base is not None:
            base.close()
    print(table(rows, args))
    same = len({r.interval for r in rows}) == 1
    print(f"\nthe same interval for every k: {'yes' if same else 'NO'}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
