"""``sal evaluate CONFIG --system NAME [--runs N]``: run a SLAM system on the clean sequence and on
each enabled perturbation of an experiment config, score every run against the ground truth and
write the paper's result tree (``pytest_sal.experiment.evaluate``), with one line per run as it is
scored and a table of the medians over runs."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from pytest_sal.cli.arg_types import add_cache_arguments, add_executor_arguments, add_slam_arguments, executor_from_args, parse_key_values
from pytest_sal.experiment.config import load_config
from pytest_sal.experiment.evaluate import ScoredRun, evaluate_experiment
from pytest_sal.experiment.schema import BASELINE
from sal_adapters.common.errors import SalError

__all__ = ["add_evaluate_commands"]

EPILOG = """\
examples:
  sal evaluate example_suites/configs/indoor_camera.yaml --system reference_vo
  sal evaluate exp.yaml --system orbslam3 --system-option features=2000 --runs 3 --timeout 900
  sal evaluate exp.yaml --system reference_vo --cache-dir /tmp/sal-cache   # frames sal perturb wrote there

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
    add_executor_arguments(cmd)
    cmd.set_defaults(run=_run)


def _run(args: argparse.Namespace) -> int:
    from sal_wrappers import create

    if not args.timeout > 0:
        raise SalError(f"--timeout must be positive, got {args.timeout:g}")
    options = parse_key_values(args.slam_option, "--system-option")
    config = load_config(args.config)
    system = create(args.slam, **options)  # unknown name: SalError listing the known systems
    with executor_from_args(args) as executor:
        summary = evaluate_experiment(
            config,
            system,
            args.slam,
            runs=args.runs,
            timeout=args.timeout,
            cache_dir=args.cache_dir,
            use_cache=not args.no_cache,
            on_run=lambda run: print(_progress(run)),
            warn=lambda message: print(f"warning: {message}"),
            executor=executor,
        )
    print(_table(summary))
    print(f"wrote {summary['root']}")
    return 0


def _fmt(value: float | None, spec: str = ".4f") -> str:
    return "-" if value is None else format(value, spec)


def _progress(run: ScoredRun) -> str:
    """One scored run: sequence, run number, ATE, frames tracked, seconds, why it failed."""
    m = run.metrics
    ate = "failed" if m.ate_rmse is None else f"{m.ate_rmse:.4f} m"
    line = f"{run.name:20s} run {run.run}/{run.runs}  ATE {ate:>10s}  tracked {m.tracked}/{m.frames} ({m.tracking_rate:6.1%})  {run.seconds:6.2f} s"
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
