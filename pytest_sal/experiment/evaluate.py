"""The evaluate workflow (``sal evaluate``): a SLAM system run on the clean sequence and on each
enabled perturbation of an experiment config, N runs, every run scored against the ground truth,
and the paper's result tree written.

Under ``<output_dir>/slam_results/<system>/``::

    trajectories/run_<k>/baseline.txt, <perturbation>.txt           TUM, the scored trajectory
    metrics/run_<k>/<name>/ate.json                                  RunMetrics + alignment used
    metrics/run_<k>/<perturbation>/vs_baseline.json                  against the baseline of run k
    metrics/summary.json, aggregated_metrics.png                     over runs
    metrics/comparison/run_<k>/ate_comparison.png
    trajectory_plots/comparison/run_<k>/trajectory_comparison_xz.png    aligned estimates, top view
    trajectory_plots/comparison/run_<k>/trajectory_comparison_error.png translation error over time
    work/run_<k>/<name>/                                             the system's own files and logs

The tree is built beside the previous one (``sal_adapters.common.atomic``) and swapped in once every
run is scored: an interrupted evaluation leaves the previous results whole.

Unlike the reference implementation, the baseline is run once per run number and reused for
every perturbation; a failed run (baseline included) is recorded with its reason and never
aborts the rest. ``SalError`` from a system (bad use: an unsupported sensor) still stops.

Each perturbed sequence is computed once (or taken from the content cache that ``sal perturb``
and the plugin fill, keyed by the sequence's fingerprint) and read back for every run; the
SLAM runs themselves are never cached: N runs measure the system's run-to-run spread.

With an ``executor`` that runs elsewhere (``--executor ray``), every sequence's run number k
goes to it at once, as many at a time as it has room for; the workers read the perturbed
frames from the content cache at the same path, so that path must be shared with them.
"""

from __future__ import annotations

import json
import math
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pytest_sal.experiment.config import build_sequence, perturbed_sequences
from pytest_sal.experiment.evaluate_plots import aggregated_plot, run_plots, try_plot
from pytest_sal.experiment.schema import BASELINE, ExperimentConfig
from sal_adapters.common.atomic import Replacement
from sal_adapters.common.errors import SalError
from sal_adapters.common.json_values import json_safe
from sal_adapters.common.textfiles import atomic_write_text

if TYPE_CHECKING:  # numpy and scipy load when a command runs, not for `sal --help`
    from pytest_sal.analysis.metrics import RunMetrics
    from pytest_sal.engine.execution.executor import Executor
    from sal_adapters.sequence import Sequence
    from sal_adapters.trajectory import Trajectory
    from sal_wrappers.base import SlamSystem

__all__ = ["SUMMARY_METRICS", "ScoredRun", "evaluate_experiment"]

#: metrics summarised over runs in summary.json
SUMMARY_METRICS = ("ate_rmse", "rpe_trans", "rpe_rot", "t_rel", "r_rel", "tracking_rate")


@dataclass(frozen=True)
class ScoredRun:
    """One run scored: run ``run`` of ``runs`` on the sequence ``name`` took ``seconds`` (s)."""

    name: str
    run: int
    runs: int
    metrics: RunMetrics
    seconds: float


def _ignore(message: str) -> None:
    """The default ``warn``: warnings go nowhere."""


def evaluate_experiment(
    config: ExperimentConfig,
    system: SlamSystem,
    slam: str,
    *,
    runs: int = 1,
    timeout: float | None = 600.0,
    cache_dir: Path | None = None,
    use_cache: bool = True,
    progress: bool = True,
    on_run: Callable[[ScoredRun], None] | None = None,
    warn: Callable[[str], None] = _ignore,
    executor: Executor | None = None,
) -> dict[str, Any]:
    """Run ``system`` (created as ``slam``, the name of its results folder) ``runs`` times on the
    clean and every perturbed sequence, score and write everything (see the module text).
    Perturbed sequences go through the content cache at ``cache_dir`` (default ``.sal/cache``)
    unless ``use_cache`` is false (``progress``: a bar while one is written); ``timeout``:
    seconds per run. ``on_run`` is called with each run as it is scored, ``warn`` with each
    warning (no ground truth, a plot that failed). ``executor``: where the runs happen
    (``None`` or ``local``: here, one at a time; another one needs the cache). Returns the
    summary (also in ``metrics/summary.json``) with ``root``, the results folder, added."""
    from pytest_sal.engine.execution.run_job import cached_sequence
    from pytest_sal.store.content_cache import command_cache

    remote = executor if executor is not None and executor.name != "local" else None
    if remote is not None and not use_cache:
        raise SalError(
            f"sal evaluate --executor {remote.name} needs the cache: its workers read the perturbed frames from it; drop --no-cache"
        )
    clean = build_sequence(config)
    groundtruth = clean.groundtruth
    sequences = perturbed_sequences(config, clean)
    if use_cache:
        cache = command_cache(cache_dir)
        sequences = {name: seq if seq is clean else cached_sequence(seq, cache, progress=progress) for name, seq in sequences.items()}
    if groundtruth is None:
        warn(f"{clean.name} has no ground truth: only tracking rates are scored")

    final = config.output_dir() / "slam_results" / slam
    with Replacement() as outputs:  # the previous results stay whole until every run is scored
        root = outputs.folder(final)
        all_metrics: dict[str, list[Any]] = {name: [] for name in sequences}
        for k in range(1, runs + 1):
            ran = _run_elsewhere(remote, config, system, sequences, root, k, timeout) if remote is not None else {}
            run_metrics = _evaluate_run(config, system, sequences, root, k, runs, timeout, groundtruth, on_run, ran)
            for name, metrics in run_metrics.items():
                all_metrics[name].append(metrics)
            run_plots(root, k, run_metrics, groundtruth, warn)
        summary = _summary(all_metrics, slam, system, config, clean, runs)
        _write_json(root / "metrics" / "summary.json", summary)
        try_plot(lambda: aggregated_plot(summary, root / "metrics" / "aggregated_metrics.png"), warn)
    return {**summary, "root": str(final)}


def _evaluate_run(
    config: ExperimentConfig,
    system: SlamSystem,
    sequences: dict[str, Sequence],
    root: Path,
    k: int,
    runs: int,
    timeout: float | None,
    groundtruth: Trajectory | None,
    on_run: Callable[[ScoredRun], None] | None,
    ran: dict[str, tuple[Any, float]],
) -> dict[str, Any]:
    """Run number ``k`` on every sequence (the baseline first): its trajectories and records
    written under ``root``; its ``RunMetrics`` by sequence name. ``ran``: runs that already
    happened elsewhere (``RunResult`` and seconds by sequence name); the others run here."""
    metrics_dir = root / "metrics" / f"run_{k}"
    run_metrics: dict[str, Any] = {}
    for name, sequence in sequences.items():
        workdir = root / "work" / f"run_{k}" / name
        workdir.mkdir(parents=True, exist_ok=True)
        if name in ran:
            result, seconds = ran[name]
        else:
            start = time.perf_counter()
            result = _run_system(system, sequence, workdir, timeout)
            seconds = time.perf_counter() - start
        metrics = run_metrics[name] = _score(result, groundtruth, config.evaluation.kitti_segments_m)
        if result.trajectory is not None and len(result.trajectory):
            path = root / "trajectories" / f"run_{k}" / f"{name}.txt"
            path.parent.mkdir(parents=True, exist_ok=True)
            result.trajectory.write_tum(path)
        _write_json(metrics_dir / name / "ate.json", _ate_record(metrics, result, k, seconds))
        if name != BASELINE:
            vs = _vs_baseline(metrics, run_metrics[BASELINE], result, baseline_traj=_baseline_trajectory(root, k), groundtruth=groundtruth)
            _write_json(metrics_dir / name / "vs_baseline.json", vs)
        if on_run is not None:
            on_run(ScoredRun(name, k, runs, metrics, seconds))
    return run_metrics


# -- running and scoring ---------------------------------------------------------------------------
def _run_elsewhere(
    executor: Executor,
    config: ExperimentConfig,
    system: SlamSystem,
    sequences: dict[str, Sequence],
    root: Path,
    k: int,
    timeout: float | None,
) -> dict[str, tuple[Any, float]]:
    """Run number ``k`` of every sequence on ``executor``, up to its free slots at once:
    ``(RunResult, seconds)`` by sequence name."""
    from concurrent.futures import ThreadPoolExecutor

    from pytest_sal.analysis.kitti_metrics import KITTI_SEGMENTS_M
    from pytest_sal.engine.execution.run_job import RunJob
    from sal_wrappers.base import RunResult

    def run(name: str) -> tuple[Any, float]:
        job = RunJob(
            key=name,
            number=k,
            value=math.nan,
            label=name,
            dataset=sequences[name],
            module=None,
            system=system,
            seed=config.experiment.seed,
            workdir=root / "work" / f"run_{k}" / name,
            timeout=timeout,
            kitti_segments=config.evaluation.kitti_segments_m or KITTI_SEGMENTS_M,
        )
        result = RunResult.from_dict(executor.run(job).result)
        return result, result.wall_time_s

    with ThreadPoolExecutor(max_workers=max(1, executor.slots(system)), thread_name_prefix="sal-evaluate") as pool:
        return dict(zip(sequences, pool.map(run, sequences)))


def _run_system(system: Any, sequence: Any, workdir: Path, timeout: float | None) -> Any:
    """``system.run``; an exception other than ``SalError`` becomes a failed ``RunResult``."""
    import numpy as np

    from sal_wrappers.base import RunResult, TrackState

    start = time.perf_counter()
    try:
        return system.run(sequence, workdir, timeout=timeout)
    except SalError:
        raise
    except Exception as exc:
        n = len(sequence)
        return RunResult(
            system=getattr(system, "name", type(system).__name__),
            sequence=sequence.name,
            sensor=sequence.sensor,
            timestamps=sequence.timestamps,
            states=np.full(n, TrackState.NOT_INITIALISED, dtype=np.int8),
            wall_time_s=time.perf_counter() - start,
            failure=f"raised {type(exc).__name__}: {exc}",
        )


def _score(result: Any, groundtruth: Trajectory | None, kitti_segments: tuple[float, ...] | None) -> Any:
    from pytest_sal.analysis.metrics import evaluate

    return evaluate(result, groundtruth, kitti_segments=kitti_segments)


def _baseline_trajectory(root: Path, k: int) -> Trajectory | None:
    from sal_adapters.trajectory import Trajectory

    path = root / "trajectories" / f"run_{k}" / f"{BASELINE}.txt"
    return Trajectory.read_tum(path) if path.is_file() else None


def _ate_record(metrics: Any, result: Any, k: int, seconds: float) -> dict[str, Any]:
    record = {"run": k, **json_safe(metrics.to_dict())}
    a = metrics.ate
    record["alignment"] = {
        "method": metrics.align,
        "scale": None if a is None else a.scale,
        "max_diff_s": None if a is None else a.max_diff,
        "matched": metrics.matched,
    }
    record["scored_trajectory"] = metrics.scored
    record["ate_stats"] = None if a is None else {k2: getattr(a, k2) for k2 in ("rmse", "mean", "median", "std", "min", "max")}
    record["wall_time_s"] = float(result.wall_time_s)
    record["seconds"] = seconds
    record["log_tail"] = (
        result.log_tail if result.failure is not None or metrics.failure is not None else ""
    )  # a run or a score that failed
    return record


def _vs_baseline(p: Any, b: Any, result: Any, *, baseline_traj: Trajectory | None, groundtruth: Trajectory | None) -> dict[str, Any]:
    """Ratios and differences against the baseline of the same run, plus the baseline's ATE on
    the frames this run tracked (the fair comparison when frames were dropped or lost)."""
    import numpy as np

    from pytest_sal.analysis.trajectory_errors import MIN_POSES, ate

    def ratio(x: float | None, y: float | None) -> float | None:
        return None if x is None or y is None or y == 0 else x / y

    def diff(x: float | None, y: float | None) -> float | None:
        return None if x is None or y is None else x - y

    same: dict[str, Any] = {"ate_rmse": None, "frames": 0, "reason": None}
    traj = result.trajectory
    if groundtruth is None:
        same["reason"] = "no ground truth"
    elif baseline_traj is None:
        same["reason"] = "the baseline has no trajectory"
    elif traj is None or not len(traj):
        same["reason"] = "this run has no trajectory"
    else:
        tol = p.ate.max_diff if p.ate is not None else (b.ate.max_diff if b.ate is not None else 0.01)
        stamps = baseline_traj.timestamps
        idx = np.clip(np.searchsorted(stamps, traj.timestamps), 1, max(1, len(stamps) - 1))
        lo = np.clip(idx - 1, 0, len(stamps) - 1)
        hi = np.clip(idx, 0, len(stamps) - 1)
        nearest = np.where(np.abs(stamps[lo] - traj.timestamps) <= np.abs(stamps[hi] - traj.timestamps), lo, hi)
        keep = sorted({int(i) for i, t in zip(nearest, traj.timestamps) if abs(stamps[i] - t) <= tol})
        same["frames"] = len(keep)
        if len(keep) < MIN_POSES:
            same["reason"] = f"{len(keep)} baseline pose(s) on the tracked frames: too few to score (need {MIN_POSES})"
        else:
            try:
                same["ate_rmse"] = ate(baseline_traj.select(keep), groundtruth, align=b.align, max_diff=tol).rmse
            except SalError as exc:
                same["reason"] = f"not scored: {exc}"
    return json_safe(
        {
            "perturbed_ok": p.failure is None,
            "baseline_ok": b.failure is None,
            "perturbed_failure": p.failure,
            "baseline_failure": b.failure,
            "ate_rmse": {
                "baseline": b.ate_rmse,
                "perturbed": p.ate_rmse,
                "ratio": ratio(p.ate_rmse, b.ate_rmse),
                "difference": diff(p.ate_rmse, b.ate_rmse),
            },
            "rpe_trans": {
                "baseline": b.rpe_trans,
                "perturbed": p.rpe_trans,
                "ratio": ratio(p.rpe_trans, b.rpe_trans),
                "difference": diff(p.rpe_trans, b.rpe_trans),
            },
            "t_rel": {"baseline": b.t_rel, "perturbed": p.t_rel, "ratio": ratio(p.t_rel, b.t_rel), "difference": diff(p.t_rel, b.t_rel)},
            "r_rel": {"baseline": b.r_rel, "perturbed": p.r_rel, "ratio": ratio(p.r_rel, b.r_rel), "difference": diff(p.r_rel, b.r_rel)},
            "tracking_rate": {
                "baseline": b.tracking_rate,
                "perturbed": p.tracking_rate,
                "ratio": ratio(p.tracking_rate, b.tracking_rate),
                "difference": diff(p.tracking_rate, b.tracking_rate),
            },
            "frames": {"baseline": b.frames, "perturbed": p.frames, "tracked_baseline": b.tracked, "tracked_perturbed": p.tracked},
            "baseline_on_tracked_frames": {
                **same,
                "ratio": ratio(p.ate_rmse, same["ate_rmse"]),
                "difference": diff(p.ate_rmse, same["ate_rmse"]),
            },
        }
    )


def _summary(all_metrics: dict[str, list[Any]], slam: str, system: Any, config: Any, clean: Any, runs: int) -> dict[str, Any]:
    from pytest_sal.analysis.aggregation import summary
    from pytest_sal.analysis.kitti_metrics import KITTI_SEGMENTS_M

    entries: dict[str, Any] = {}
    for name, ms in all_metrics.items():
        entry: dict[str, Any] = {
            "runs": len(ms),
            "failures": sum(1 for m in ms if m.failure is not None),
            "failure_reasons": [{"run": i, "reason": m.failure} for i, m in enumerate(ms, 1) if m.failure is not None],
            "kitti_missing": [{"run": i, "reason": m.kitti_missing} for i, m in enumerate(ms, 1) if m.kitti_missing is not None],
        }
        for metric in SUMMARY_METRICS:  # the one rule of pytest_sal.analysis.aggregation, and the spread
            stats = summary(getattr(m, metric) for m in ms)
            entry[metric] = {**stats, "std": None if stats["median"] is None else statistics.pstdev(stats["values"])}
        entries[name] = entry
    return {
        "system": slam,
        "options": json_safe(system.options()),
        "experiment": config.experiment.name,
        "sequence": clean.name,
        "frames": len(clean),
        "run_count": runs,
        "order": list(all_metrics),
        "std": "population (ddof=0)",
        "kitti_segments_m": list(config.evaluation.kitti_segments_m or KITTI_SEGMENTS_M),
        "baseline": entries[BASELINE],
        "perturbations": {k: v for k, v in entries.items() if k != BASELINE},
    }


# -- files ----------------------------------------------------------------------------------------
def _write_json(path: Path, data: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(json_safe(data), indent=2) + "\n"
    atomic_write_text(path, text)
