"""The plots of ``sal evaluate`` (``pytest_sal.experiment.evaluate``): per run, the ATE of each
perturbation against the baseline, the aligned trajectories and the translation error over
time; over runs, the median ATE and tracking rate per sequence. A plot that fails is a warning.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pytest_sal.experiment.schema import BASELINE

if TYPE_CHECKING:
    from sal_adapters.trajectory import Trajectory

__all__ = ["aggregated_plot", "run_plots", "try_plot"]


def run_plots(root: Path, k: int, run_metrics: dict[str, Any], groundtruth: Trajectory | None, warn: Callable[[str], None]) -> None:
    """The plots of run ``k`` under ``root``: ATE per perturbation, the aligned trajectories
    (top view) and the translation error over time (``run_metrics``: ``RunMetrics`` by sequence)."""
    from pytest_sal.analysis.plots import plot_ate_over_time, plot_trajectories

    try_plot(lambda: _ate_bar_plot(run_metrics, root / "metrics" / "comparison" / f"run_{k}" / "ate_comparison.png", k), warn)
    estimates = {name: m.ate.estimate for name, m in run_metrics.items() if m.ate is not None}
    if groundtruth is not None or estimates:
        path = root / "trajectory_plots" / "comparison" / f"run_{k}" / "trajectory_comparison_xz.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        try_plot(lambda: plot_trajectories(groundtruth, estimates, path, title=f"Trajectories, run {k} (aligned, xz)", plane="xz"), warn)
    ates = {name: m.ate for name, m in run_metrics.items() if m.ate is not None}
    if ates:  # the errors the top view is too coarse to show
        error_path = root / "trajectory_plots" / "comparison" / f"run_{k}" / "trajectory_comparison_error.png"
        try_plot(lambda: plot_ate_over_time(ates, error_path, title=f"Translation error over time, run {k}"), warn)


def try_plot(draw: Callable[[], Any], warn: Callable[[str], None]) -> None:
    """``draw()``; a plot that fails is a warning (``warn``), never the end of an evaluation."""
    try:
        draw()
    except Exception as exc:
        warn(f"plot failed: {type(exc).__name__}: {exc}")


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


def aggregated_plot(summary: dict[str, Any], path: Path) -> Path:
    """Median ATE (m) and tracking rate per sequence over the runs of ``summary`` (``summary.json``),
    with min-max bars and the runs that succeeded."""
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
