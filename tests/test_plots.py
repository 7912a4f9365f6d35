"""PNG plots: written atomically, readable, not blank, lines where the data says."""

from __future__ import annotations

from pathlib import Path

import cv2
import matplotlib
import numpy as np
import pytest

from pytest_sal.analysis.plots import ate_figure, plot_ate_over_time, plot_trajectories, save_png, trajectory_figure
from pytest_sal.analysis.trajectory_errors import ate
from sal_adapters.common.errors import SalError
from sal_adapters.trajectory import Trajectory

BLUE_BGR = (180, 119, 31)  # matplotlib's first colour, tab:blue


def loop(n: int = 120, noise: float = 0.0, seed: int = 0) -> Trajectory:
    u = np.linspace(0.0, 2 * np.pi, n)
    positions = np.column_stack([20 * np.cos(u), 0.3 * np.sin(u), 12 * np.sin(u)])
    positions += np.random.default_rng(seed).normal(0.0, noise, positions.shape) if noise else 0.0
    return Trajectory(np.arange(n) / 10.0, positions, np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))


def distinct_colours(image: np.ndarray) -> int:
    return len(np.unique(image.reshape(-1, 3) // 16, axis=0))


def test_plots_are_readable_non_blank_pngs(tmp_path: Path) -> None:
    backend = matplotlib.get_backend()
    reference = loop()
    results = {"noisy": ate(loop(noise=0.3, seed=1), reference), "noisier": ate(loop(noise=0.8, seed=2), reference, align="sim3")}
    traj_png = plot_trajectories(reference, {k: r.estimate for k, r in results.items()}, tmp_path / "out" / "traj.png", title="loop")
    ate_png = plot_ate_over_time(results, tmp_path / "out" / "ate.png")
    assert traj_png == tmp_path / "out" / "traj.png" and ate_png.exists()
    for png in (traj_png, ate_png):
        image = cv2.imread(str(png))
        assert image is not None and image.shape == (600, 800, 3)
        assert distinct_colours(image) >= 8  # white, grey, text, two runs, antialiasing
        assert np.mean(image == 255) < 0.97
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["ate.png", "traj.png"]  # no temporary left
    assert matplotlib.get_backend() == backend  # no global backend switch


def test_a_straight_line_is_drawn_where_its_data_is(tmp_path: Path) -> None:
    """A line at z = 2 m from x = 0 to 10 m: blue on the line, not 1 m away from it."""
    n = 50
    x = np.linspace(0.0, 10.0, n)
    line = Trajectory(np.arange(n) * 0.1, np.column_stack([x, np.zeros(n), np.full(n, 2.0)]), np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))
    fig = trajectory_figure(None, {"line": line}, plane="xz")
    image = cv2.imread(str(save_png(fig, tmp_path / "line.png")))
    ax = fig.axes[0]
    height = image.shape[0]

    def pixel(px: float, pz: float) -> np.ndarray:
        col, row = ax.transData.transform((px, pz))
        r, c = int(round(height - row)), int(round(col))
        return image[r - 1 : r + 2, c - 1 : c + 2].reshape(-1, 3).astype(int)

    for px in (3.0, 5.0, 8.0):
        on = pixel(px, 2.0)
        assert np.min(np.abs(on - BLUE_BGR).sum(axis=1)) < 40, f"no line at x = {px} m"
        assert np.min(np.abs(pixel(px, 3.0) - BLUE_BGR).sum(axis=1)) > 150, f"line drawn 1 m off at x = {px} m"
    assert ax.get_xlabel() == "x [m]" and ax.get_ylabel() == "z [m]"


def test_auto_plane_is_the_widest_one() -> None:
    fig = trajectory_figure(loop(), {})
    assert (fig.axes[0].get_xlabel(), fig.axes[0].get_ylabel()) == ("x [m]", "z [m]")
    labels = fig.axes[0].get_legend_handles_labels()[1]
    assert labels == ["reference", "start"]


def test_rmse_line_and_errors_over_time() -> None:
    reference = loop()
    result = ate(loop(noise=0.5, seed=4), reference)
    ax = ate_figure({"run": result}).axes[0]
    error_line, rmse_line = ax.lines[0], ax.lines[1]
    assert np.allclose(error_line.get_xdata(), reference.timestamps - reference.timestamps[0])
    assert np.allclose(error_line.get_ydata(), result.errors)
    assert np.allclose(rmse_line.get_ydata(), result.rmse) and rmse_line.get_linestyle() == "--"
    assert "RMSE" in ax.get_legend_handles_labels()[1][0]


def test_bad_plot_requests() -> None:
    with pytest.raises(SalError, match="plane"):
        trajectory_figure(loop(), {}, plane="xw")
    with pytest.raises(SalError, match="nothing to plot"):
        trajectory_figure(None, {})
    with pytest.raises(SalError, match="nothing to plot"):
        ate_figure({})
