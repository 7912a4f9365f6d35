"""Has a noisy system's boundary regressed? Both outcomes' curves are fitted again from their
runs (``Outcome.trials``: every run's severity and whether it held, as the history keeps
them), and the posterior probability that ``s_R`` moved toward the mild side by more than the
limit is compared with the confidence. The two fits are independent, so the probability is a
sum over pairs of ``s_R`` values, binned on the grid. An unchanged system raises it above
``C`` in at most about ``1 - C`` of comparisons (less with a limit above 0): the false-alarm
rate (``benchmarks/bench_reliability.py`` measures it).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pytest_sal.engine.reliability_curve import CurveFit, SeverityAxis, fit_curve

if TYPE_CHECKING:
    from pytest_sal.engine.outcome import Outcome

__all__ = ["refit", "regression_probability"]


def refit(outcome: Outcome) -> CurveFit | None:
    """The curve of a noisy outcome fitted from its runs (``None``: not a noisy outcome, or one
    stored without its axis)."""
    b = outcome.boundary
    if not b.noisy or not b.search_range or b.log_scale is None or not b.grid_step:
        return None
    mild, severe = b.search_range
    axis = SeverityAxis(float(mild), float(severe), bool(b.log_scale), float(b.grid_step))
    runs = [(t.value, bool(r.get("passed"))) for t in outcome.trials for r in t.runs if not r.get("abstained")]
    return fit_curve(axis, [v for v, _ in runs], [h for _, h in runs])


def regression_probability(before: CurveFit, now: CurveFit, reliability: float, limit: float, relative: bool, worse: str) -> float:
    """Posterior probability that ``s_R`` got worse from ``before`` to ``now`` by more than
    ``limit`` (the parameter's unit, or percent of the ``before`` value when ``relative``):
    toward larger values when ``worse`` is ``lower`` (visibility), smaller ones otherwise."""
    values_before, mass_before = _s_r_masses(before, reliability)
    values_now, mass_now = _s_r_masses(now, reliability)
    worse_by = (values_now[:, None] - values_before[None, :]) if worse == "lower" else (values_before[None, :] - values_now[:, None])
    if relative:
        with np.errstate(divide="ignore", invalid="ignore"):
            change = np.where(
                values_before[None, :] == 0, np.where(worse_by > 0, np.inf, 0.0), 100 * worse_by / np.abs(values_before)[None, :]
            )
    else:
        change = worse_by
    return float((mass_now[:, None] * mass_before[None, :] * (change > limit)).sum())


def _s_r_masses(fit: CurveFit, reliability: float) -> tuple[np.ndarray, np.ndarray]:
    """``s_R``'s posterior on the grid: the values (cell midpoints, the range's ends for the
    cells beyond it) and their masses."""
    grid = fit.axis.grid
    centres = np.concatenate([[0.0], (grid[1:] + grid[:-1]) / 2, [1.0]])
    masses = np.bincount(np.searchsorted(grid, fit.s_values(reliability)), fit.weights, len(centres))
    return fit.axis.to_value(centres), masses / masses.sum()
