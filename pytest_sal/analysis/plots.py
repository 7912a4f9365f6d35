"""PNG plots of trajectories and of their absolute error over time.

Figures are built on ``matplotlib.figure.Figure`` with an Agg canvas, so no pyplot state or
backend is touched (safe inside pytest and without a display). Each ``plot_*`` writes its
PNG atomically (temporary file, then ``os.replace``) and returns the path; the matching
``*_figure`` function returns the figure for other uses.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import IO, Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from pytest_sal.analysis.trajectory_errors import AteResult
from sal_adapters.common.errors import SalError
from sal_adapters.common.textfiles import atomic_write
from sal_adapters.trajectory import Trajectory

__all__ = ["PLANES", "ate_figure", "plot_ate_over_time", "plot_trajectories", "png_bytes", "save_png", "trajectory_figure"]

#: planes a trajectory can be drawn in (horizontal axis first); ``"auto"`` picks one
PLANES = ("xy", "xz", "yz", "yx", "zx", "zy")
FIGSIZE = (8.0, 6.0)  # inches
DPI = 100
ALIGN_NAMES = {"se3": "SE(3) aligned", "sim3": "Sim(3) aligned", "none": "not aligned"}
REFERENCE_STYLE: dict[str, Any] = dict(color="0.2", linestyle="--", linewidth=1.1, zorder=3)  # on top, estimates show through
#: a time step longer than this many median steps, and than GAP_MIN_S, is left as a gap
GAP_STEPS = 5.0
GAP_MIN_S = 0.5


def trajectory_figure(
    reference: Trajectory | None,
    estimates: dict[str, Trajectory],
    *,
    title: str = "Trajectories (top view)",
    plane: str = "auto",
) -> Figure:
    """Top view of ``reference`` (grey, dashed) and ``estimates`` (already aligned), in metres,
    equal aspect, a circle at each start, gaps where tracking was lost. ``plane`` ``"auto"``: the two axes along which
    the reference (else the first estimate) extends most, e.g. ``xz`` for a KITTI camera."""
    shown = [t for t in [reference, *estimates.values()] if t is not None and len(t)]
    if not shown:
        raise SalError("nothing to plot: the reference and every estimate are empty")
    axes = _plane_axes(shown[0].positions, plane)
    fig, ax = _figure()
    lines: list[tuple[str, Trajectory, dict[str, Any]]] = []
    if reference is not None and len(reference):
        lines.append(("reference", reference, REFERENCE_STYLE))
    lines += [(name, t, dict(linewidth=1.4)) for name, t in estimates.items() if len(t)]
    for name, traj, style in lines:
        xy = traj.positions[:, axes]
        (line,) = ax.plot(*_broken_at_gaps(traj.timestamps, xy).T, label=name, **style)
        ax.plot(*xy[0], "o", color=line.get_color(), markersize=7, markeredgecolor="white", zorder=4)
    ax.plot([], [], "o", color="0.5", label="start")
    names = "xyz"
    ax.set_xlabel(f"{names[axes[0]]} [m]")
    ax.set_ylabel(f"{names[axes[1]]} [m]")
    ax.set_aspect("equal", adjustable="datalim")
    _finish(ax, title)
    return fig


def ate_figure(ate_results: dict[str, AteResult], *, title: str = "Absolute trajectory error") -> Figure:
    """Per-pose translation error (m) against time since the earliest pose (s), with each
    run's RMSE as a dashed line of the same colour; gaps where tracking was lost."""
    if not ate_results:
        raise SalError("nothing to plot: no ATE result given")
    t0 = min(float(r.timestamps[0]) for r in ate_results.values())
    fig, ax = _figure()
    for name, result in ate_results.items():
        label = f"{name}: RMSE {result.rmse:#.3g} m ({ALIGN_NAMES.get(result.align, result.align)})"
        curve = _broken_at_gaps(result.timestamps, np.column_stack([result.timestamps - t0, result.errors]))
        (line,) = ax.plot(*curve.T, linewidth=1.2, label=label)
        ax.axhline(result.rmse, color=line.get_color(), linestyle="--", linewidth=1.2)
    ax.plot([], [], color="0.5", linestyle="--", label="RMSE")
    ax.set_xlabel("time since start [s]")
    ax.set_ylabel("translation error [m]")
    ax.set_ylim(bottom=0)
    _finish(ax, title)
    return fig


def plot_trajectories(
    reference: Trajectory | None,
    estimates: dict[str, Trajectory],
    path: str | Path,
    *,
    title: str = "Trajectories (top view)",
    plane: str = "auto",
) -> Path:
    """Write ``trajectory_figure`` as a PNG at ``path``; return the path."""
    return save_png(trajectory_figure(reference, estimates, title=title, plane=plane), path)


def plot_ate_over_time(ate_results: dict[str, AteResult], path: str | Path, *, title: str = "Absolute trajectory error") -> Path:
    """Write ``ate_figure`` as a PNG at ``path``; return the path."""
    return save_png(ate_figure(ate_results, title=title), path)


def save_png(fig: Figure, path: str | Path) -> Path:
    """Render ``fig`` to ``path`` as a PNG, atomically (``sal_adapters.common.textfiles.atomic_write``)."""
    png = png_bytes(fig)

    def write(handle: IO[Any]) -> None:
        handle.write(png)

    return atomic_write(path, write, binary=True)


def png_bytes(fig: Figure) -> bytes:
    """``fig`` rendered as PNG bytes (``DPI`` dots per inch: 800 x 600 px at ``FIGSIZE``)."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=DPI)
    return buffer.getvalue()


def _figure() -> tuple[Figure, Axes]:
    fig = Figure(figsize=FIGSIZE, dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig, fig.add_subplot()


def _finish(ax: Axes, title: str) -> None:
    ax.set_title(title)
    ax.grid(True, color="0.88", linewidth=0.8)
    ax.legend(loc="best", fontsize="small", framealpha=0.9)


def _broken_at_gaps(stamps: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``points`` (N x 2) with a NaN row wherever the time step exceeds ``GAP_STEPS`` median steps
    and ``GAP_MIN_S`` seconds, so that no line is drawn across a stretch that was not tracked."""
    steps = np.diff(stamps)
    if not len(steps):
        return points
    gaps = np.flatnonzero(steps > max(GAP_STEPS * float(np.median(steps)), GAP_MIN_S)) + 1
    return np.insert(np.asarray(points, dtype=np.float64), gaps, np.nan, axis=0)


def _plane_axes(positions: np.ndarray, plane: str) -> list[int]:
    """Indices of the horizontal and vertical axes of ``plane`` (see ``trajectory_figure``)."""
    if plane == "auto":
        extent = np.ptp(positions, axis=0)
        return sorted(np.argsort(extent)[-2:].tolist())
    if plane not in PLANES:
        raise SalError(f"plane must be 'auto' or one of {', '.join(PLANES)}, got {plane!r}")
    return ["xyz".index(c) for c in plane]
