"""The documented import path of the trajectory plots (``from pytest_sal.plots import
plot_trajectories, plot_ate_over_time``); the code lives in :mod:`pytest_sal.analysis.plots`."""

from pytest_sal.analysis.plots import PLANES, ate_figure, plot_ate_over_time, plot_trajectories, png_bytes, save_png, trajectory_figure

__all__ = ["PLANES", "ate_figure", "plot_ate_over_time", "plot_trajectories", "png_bytes", "save_png", "trajectory_figure"]
