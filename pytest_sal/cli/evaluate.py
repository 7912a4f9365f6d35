"""``sal evaluate CONFIG --slam NAME [--runs N]``: run a SLAM system on the clean sequence and on
each enabled perturbation of an experiment config, score every run against the ground truth and
write the paper's result tree.

Under ``<output_dir>/slam_results/<algo>/``::

    trajectories/run_<k>/baseline.txt, <perturbation>.txt           TUM, the scored trajectory
    metrics/run_<k>/<name>/ate.json                                  RunMetrics + alignment used
    metrics/run_<k>/<perturbation>/vs_baseline.json                  against the baseline of run k
    metrics/summary.json, aggregated_metrics.png                     over runs
    metrics/comparison/run_<k>/ate_comparison.png
    trajectory_plots/comparison/run_<k>/trajectory_comparison_xz.png    aligned estimates, top view
    trajectory_plots/comparison/run_<k>/trajectory_comparison_error.png translation error over time
    work/run_<k>/<name>/                                             the system's own files and logs

The tree is built beside the previous one (``sal_adapters.atomic``) and swapped in once every
run is scored: an interrupted evaluation leaves the previous results whole.

Unlike the reference implementation, the baseline is run once per run number and reused for
every perturbation; a failed run (baseline included) is recorded with its reason and never
aborts the rest. ``SalError`` from a system (bad use: an unsupported sensor) still stops.

Each perturbed sequence is computed once (or taken from the content cache that ``sal perturb``
and the plugin fill, keyed by the sequence's fingerprint) and read back for every run; the
SLAM runs themselves are never cached: N runs measure the system's run-to-run spread.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pytest_sal.cli.arg_types import add_cache_arguments, add_slam_arguments
from pytest_sal.experiment.config import BASELINE
from sal_adapters.atomic import Replacement
from sal_adapters.errors import SalError
from sal_adapters.json_values import json_safe
from sal_adapters.textfiles import atomic_write

if TYPE_CHECKING:  # numpy and scipy load when a command runs, not for `sal --help`
    from sal_adapters.trajectory import Trajectory

__all__ = ["SUMMARY_METRICS", "add_evaluate_commands", "run_evaluate"]

#: metrics summarised over runs in summary.json
SUMMARY_METRICS = ("ate_rmse", "rpe_trans", "rpe_rot", "t_rel", "r_rel", "tracking_rate")

EPILOG = """\
examples:
  sal evaluate example_suites/configs/indoor_camera.yaml --slam reference_vo
  sal evaluate exp.yaml --slam orbslam3 --slam-option features=2000 --runs 3 --timeout 900
  sal evaluate exp.yaml --slam reference_vo --cache-dir /tmp/sal-cache   # frames sal perturb wrote there

Writes <base_dir>/<name>/slam_results/<SLAM>/: trajectories/run_<k>/{baseline,<perturbation>}.txt,
metrics/run_<k>/<perturbation>/{ate,vs_baseline}.json, metrics/summary.json (median, mean, std,
min, max over runs; failures with reasons), metrics/aggregated_metrics.png,
metrics/comparison/run_<k>/ate_comparison.png and
trajectory_plots/comparison/run_<k>/trajectory_comparison_{xz,error}.png (top view, error over time).
"""


def add_evaluate_commands(commands: argparse._SubParsersAction) -> None:
    """Add ``evaluate`` to the ``sal`` subcommands."""
    cmd = commands.add_parser(
        "evaluate",
        help="run a SLAM system on the clean and each perturbed sequence, N runs, and score them",
        description="Run a SLAM system on the clean sequence (the baseline, once per run) and on each enabled\n"
        "perturbation of the experiment config, score every run against the ground truth (ATE, RPE,\n"
        "KITTI t_rel / r_rel over the segments of evaluation.kitti_segments_m, tracking rate) and compare\n"
        "it with the baseline of the same run.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    cmd.add_argument("config", type=Path, metavar="CONFIG", help="experiment YAML")
    add_slam_arguments(cmd, "runs per sequence")
    add_cache_arguments(cmd, "content cache of perturbed frames", no_cache="perturb in memory; read and store nothing in the cache")
    cmd.set_defaults(run=_run)


def _run(args: argparse.Namespace) -> int:
    from pytest_sal.cli.arg_types import parse_key_values

    if not args.timeout > 0:
        raise SalError(f"--timeout must be positive, got {args.timeout:g}")
    options = parse_key_values(args.slam_option, "--slam-option")
    run_evaluate(
        args.config, args.slam, options, runs=args.runs, timeout=args.timeout, cache_dir=args.cache_dir, use_cache=not args.no_cache
    )
    return 0


def run_evaluate(
    config_path: Path,
    slam: str,
    options: dict[str, Any] | None = None,
    *,
    runs: int = 1,
    timeout: float | None = 600.0,
    cache_dir: Path | None = None,
    use_cache: bool = True,
    out: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Run, score and write everything (see the module docstring); return the summary dict
    (also in ``metrics/summary.json``) with ``root`` (the results folder) added."""
    from pytest_sal.engine.trial_runner import cached_sequence
    from pytest_sal.experiment.config import build_sequence, load_config, perturbed_sequences
    from pytest_sal.store.trial_cache import command_cache
    from sal_wrappers import create

    config = load_config(config_path)
    system = create(slam, **(options or {}))  # unknown name: SalError listing the known systems
    clean = build_sequence(config)
    groundtruth = clean.groundtruth
    sequences = perturbed_sequences(config, clean)
    if use_cache:
        cache = command_cache(cache_dir)
        sequences = {name: seq if seq is clean else cached_sequence(seq, cache, progress=True) for name, seq in sequences.items()}
    if groundtruth is None:
        out(f"warning: {clean.name} has no ground truth: only tracking rates are scored")

    final = config.output_dir() / "slam_results" / slam
    with Replacement() as outputs:  # the previous results stay whole until every run is scored
        root = outputs.folder(final)
        metrics_dir = root / "metrics"
        all_metrics: dict[str, list[Any]] = {name: [] for name in sequences}
        for k in range(1, runs + 1):
            run_metrics: dict[str, Any] = {}
            for name, sequence in sequences.items():
                workdir = root / "work" / f"run_{k}" / name
                workdir.mkdir(parents=True, exist_ok=True)
                start = time.perf_counter()
                result = _run_system(system, sequence, workdir, timeout)
                seconds = time.perf_counter() - start
                metrics = _score(result, groundtruth, config.evaluation.kitti_segments_m)
                run_metrics[name] = metrics
                all_metrics[name].append(metrics)
                if result.trajectory is not None and len(result.trajectory):
                    path = root / "trajectories" / f"run_{k}" / f"{name}.txt"
                    path.parent.mkdir(parents=True, exist_ok=True)
                    result.trajectory.write_tum(path)
                _write_json(metrics_dir / f"run_{k}" / name / "ate.json", _ate_record(metrics, result, k, seconds))
                if name != BASELINE:
                    vs = _vs_baseline(
                        metrics, run_metrics[BASELINE], result, baseline_traj=_baseline_trajectory(root, k), groundtruth=groundtruth
                    )
                    _write_json(metrics_dir / f"run_{k}" / name / "vs_baseline.json", vs)
                out(_progress(name, k, runs, metrics, seconds))
            _run_plots(root, k, run_metrics, groundtruth, out)

        summary = _summary(all_metrics, slam, system, config, clean, runs)
        _write_json(metrics_dir / "summary.json", summary)
        _try_plot(lambda: _aggregated_plot(summary, metrics_dir / "aggregated_metrics.png"), out)
    out(_table(summary))
    out(f"wrote {final}")
    return {**summary, "root": str(final)}


# -- running and scoring ---------------------------------------------------------------------------
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

    from pytest_sal.analysis.metrics import MIN_POSES, ate

    def ratio(x: float | None, y: float | None) -> float | None:
        return None if x is None or y is None or y == 0 else x / y

    def diff(x: float | None, y: float | None) -> float | None:
        return None if x is None or y is None else x - y

    same = {"ate_rmse": None, "frames": 0, "reason": None}
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
    import numpy as np

    from pytest_sal.analysis.kitti_metrics import KITTI_SEGMENTS_M

    entries: dict[str, Any] = {}
    for name, ms in all_metrics.items():
        entry: dict[str, Any] = {
            "runs": len(ms),
            "failures": sum(1 for m in ms if m.failure is not None),
            "failure_reasons": [{"run": i, "reason": m.failure} for i, m in enumerate(ms, 1) if m.failure is not None],
            "kitti_missing": [{"run": i, "reason": m.kitti_missing} for i, m in enumerate(ms, 1) if m.kitti_missing is not None],
        }
        for metric in SUMMARY_METRICS:
            values = [float(v) for v in (getattr(m, metric) for m in ms) if v is not None and math.isfinite(float(v))]
            a = np.asarray(values)
            stats: dict[str, Any] = {s: None for s in ("median", "mean", "std", "min", "max")}
            if len(a):
                stats = {
                    "median": float(np.median(a)),
                    "mean": float(a.mean()),
                    "std": float(a.std()),
                    "min": float(a.min()),
                    "max": float(a.max()),
                }
            entry[metric] = {**stats, "count": len(values), "values": values}
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


# -- plots ---------------------------------------------------------------------------------------
def _run_plots(root: Path, k: int, run_metrics: dict[str, Any], groundtruth: Trajectory | None, out: Callable[[str], None]) -> None:
    from pytest_sal.analysis.plots import plot_ate_over_time, plot_trajectories

    _try_plot(lambda: _ate_bar_plot(run_metrics, root / "metrics" / "comparison" / f"run_{k}" / "ate_comparison.png", k), out)
    estimates = {name: m.ate.estimate for name, m in run_metrics.items() if m.ate is not None}
    if groundtruth is not None or estimates:
        path = root / "trajectory_plots" / "comparison" / f"run_{k}" / "trajectory_comparison_xz.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        _try_plot(lambda: plot_trajectories(groundtruth, estimates, path, title=f"Trajectories, run {k} (aligned, xz)", plane="xz"), out)
    ates = {name: m.ate for name, m in run_metrics.items() if m.ate is not None}
    if ates:  # the errors the top view is too coarse to show
        error_path = root / "trajectory_plots" / "comparison" / f"run_{k}" / "trajectory_comparison_error.png"
        _try_plot(lambda: plot_ate_over_time(ates, error_path, title=f"Translation error over time, run {k}"), out)


def _try_plot(draw: Callable[[], Any], out: Callable[[str], None]) -> None:
    try:
        draw()
    except Exception as exc:
        out(f"warning: plot failed: {type(exc).__name__}: {exc}")


def _ate_bar_plot(run_metrics: dict[str, Any], path: Path, k: int) -> Path:
    from pytest_sal.analysis.plots import save_png

    fig, ax = _figure()
    names = [n for n in run_metrics if n != BASELINE]
    values = [run_metrics[n].ate_rmse for n in names]
    heights = [0.0 if v is None else v for v in values]
    bars = ax.bar(range(len(names)), heights, color=["tab:red" if v is None else "tab:blue" for v in values])
    for bar, v, _n in zip(bars, values, names):
        label = "failed" if v is None else f"{v:#.3g}"
        ax.annotate(label, (bar.get_x() + bar.get_width() / 2, bar.get_height()), ha="center", va="bottom", fontsize="small")
    b = run_metrics[BASELINE].ate_rmse
    if b is not None:
        ax.axhline(b, color="0.2", linestyle="--", label=f"baseline {b:#.3g} m")
        ax.legend(loc="best", fontsize="small")
    ax.set_xticks(range(len(names)), names, rotation=30, ha="right")
    ax.set_ylabel("ATE RMSE [m]")
    ax.set_title(f"ATE per perturbation, run {k}")
    ax.grid(True, axis="y", color="0.88")
    path.parent.mkdir(parents=True, exist_ok=True)
    return save_png(fig, path)


def _aggregated_plot(summary: dict[str, Any], path: Path) -> Path:
    import numpy as np

    from pytest_sal.analysis.plots import save_png

    fig, axes = _figure(2)
    entries = {BASELINE: summary["baseline"], **summary["perturbations"]}
    names = list(entries)
    for ax, metric, unit in zip(axes, ("ate_rmse", "tracking_rate"), ("ATE RMSE [m]", "tracking rate")):
        med = np.array([np.nan if entries[n][metric]["median"] is None else entries[n][metric]["median"] for n in names], dtype=float)
        lo = np.array([np.nan if entries[n][metric]["min"] is None else entries[n][metric]["min"] for n in names], dtype=float)
        hi = np.array([np.nan if entries[n][metric]["max"] is None else entries[n][metric]["max"] for n in names], dtype=float)
        x = np.arange(len(names))
        ax.bar(x, np.nan_to_num(med), color=["0.5"] + ["tab:blue"] * (len(names) - 1))
        ax.errorbar(x, np.nan_to_num(med), yerr=[np.nan_to_num(med - lo), np.nan_to_num(hi - med)], fmt="none", ecolor="black", capsize=4)
        for xi, n in zip(x, names):
            e = entries[n]
            ax.annotate(f"{e['runs'] - e['failures']}/{e['runs']} ok", (xi, 0), ha="center", va="bottom", fontsize="x-small")
        ax.set_xticks(x, names, rotation=30, ha="right")
        ax.set_ylabel(unit)
        ax.set_title(f"{unit}: median, min-max over {summary['run_count']} run(s)")
        ax.grid(True, axis="y", color="0.88")
    path.parent.mkdir(parents=True, exist_ok=True)
    return save_png(fig, path)


def _figure(columns: int = 1) -> tuple[Any, Any]:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8.0 if columns == 1 else 12.0, 6.0), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = [fig.add_subplot(1, columns, i + 1) for i in range(columns)]
    return fig, axes[0] if columns == 1 else axes


# -- text and files --------------------------------------------------------------------------------
def _fmt(value: float | None, spec: str = ".4f") -> str:
    return "-" if value is None else format(value, spec)


def _progress(name: str, k: int, runs: int, m: Any, seconds: float) -> str:
    ate = "failed" if m.ate_rmse is None else f"{m.ate_rmse:.4f} m"
    line = f"{name:20s} run {k}/{runs}  ATE {ate:>10s}  tracked {m.tracked}/{m.frames} ({m.tracking_rate:6.1%})  {seconds:6.2f} s"
    return line + (f"  [{m.failure}]" if m.failure else "")


def _table(summary: dict[str, Any]) -> str:
    """Medians over runs: ATE (m), RPE (m/m), KITTI t_rel (%) and r_rel (deg/100m), tracking rate."""
    rows = [
        f"{'sequence':20s} {'ok':>5s} {'ATE median':>11s} {'ATE min':>9s} {'ATE max':>9s} {'RPE trans':>10s} "
        f"{'t_rel %':>8s} {'r_rel deg/100m':>14s} {'tracked':>8s}"
    ]
    for name, e in {BASELINE: summary["baseline"], **summary["perturbations"]}.items():
        rows.append(
            f"{name:20s} {e['runs'] - e['failures']:>2d}/{e['runs']:<2d} {_fmt(e['ate_rmse']['median']):>11s} {_fmt(e['ate_rmse']['min']):>9s} "
            f"{_fmt(e['ate_rmse']['max']):>9s} {_fmt(e['rpe_trans']['median']):>10s} {_fmt(e['t_rel']['median'], '.3f'):>8s} "
            f"{_fmt(e['r_rel']['median'], '.3f'):>14s} {_fmt(e['tracking_rate']['median'], '.1%'):>8s}"
        )
    rows.append(f"t_rel / r_rel: KITTI segments of {', '.join(f'{v:g}' for v in summary['kitti_segments_m'])} m")
    for name, e in {BASELINE: summary["baseline"], **summary["perturbations"]}.items():
        if e["kitti_missing"]:
            rows.append(f"{name}: t_rel / r_rel missing in {len(e['kitti_missing'])} run(s): {e['kitti_missing'][0]['reason']}")
    return "\n".join(rows)


def _write_json(path: Path, data: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(json_safe(data), indent=2) + "\n"
    atomic_write(path, lambda handle: handle.write(text))
