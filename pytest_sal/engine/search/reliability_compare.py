"""Has a noisy system's boundary regressed? Both outcomes' runs (``Outcome.trials``: every run's
severity and whether it held, as the history keeps them) are fitted again on one severity axis
under one curve shape: the width, the lapse rate and the floor are shared, and each outcome has
its own location (the pooled slope of a likelihood-ratio test, as a posterior). A regression
is declared when the posterior probability that ``s_R`` moved toward the mild side by more than
the limit reaches the confidence.

Sharing the shape is what gives the gate its power: ``s_R`` of one session alone is uncertain
mostly through the shape (30 runs cannot exclude a lapse rate of 20 %, under which ``s_R`` lies
at the range's mild end), and that uncertainty is the same for both sessions, so it cancels in
their difference. An unchanged system raises the probability above ``C`` in at most about
``1 - C`` of comparisons (less with a limit above 0): the false-alarm rate, measured with the
detection rate by ``benchmarks/bench_reliability.py``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy import special

from pytest_sal.engine.search.reliability_curve import CurveFit, SeverityAxis, fit_curve

if TYPE_CHECKING:
    from pytest_sal.engine.outcomes.outcome import Outcome

__all__ = ["refit", "regression_probability"]

#: shapes whose posterior mass is below this share of the largest are left out (they move no probability)
_NEGLIGIBLE = 1e-10


def refit(outcome: Outcome, axis: SeverityAxis | None = None) -> CurveFit | None:
    """The curve of a noisy outcome fitted from its runs, on ``axis`` (default: the outcome's
    own; ``None``: not a noisy outcome, or one stored without its axis)."""
    b = outcome.boundary
    if not b.noisy or not b.search_range or b.log_scale is None or not b.grid_step:
        return None
    if axis is None:
        mild, severe = b.search_range
        axis = SeverityAxis(float(mild), float(severe), bool(b.log_scale), float(b.grid_step))
    runs = [(t.value, bool(r.get("passed"))) for t in outcome.trials for r in t.runs if not r.get("abstained")]
    return fit_curve(axis, [v for v, _ in runs], [h for _, h in runs])


def regression_probability(before: CurveFit, now: CurveFit, reliability: float, limit: float, relative: bool, worse: str) -> float:
    """Posterior probability that ``s_R`` got worse from ``before`` to ``now`` by more than
    ``limit`` (the parameter's unit, or percent of the ``before`` value when ``relative``):
    toward larger values when ``worse`` is ``lower`` (visibility), smaller ones otherwise.

    Both fits must be on one axis. With the shape ``θ`` shared and the two locations
    independent given it (uniform priors), ``P = Σ_θ π(θ) Σ_b w_b(b | θ) W_now(moved beyond
    the limit from s_R(b, θ) | θ)``, where ``π(θ)`` is proportional to the shape's prior times
    both sessions' likelihoods summed over their locations."""
    if before.axis != now.axis:
        raise ValueError(f"both curves must be fitted on one severity axis: {before.axis} and {now.axis}")
    grid, axis = now.grid, now.axis
    table = (grid.locations, -1)
    rising = slice(None, None, -1) if axis.mild > axis.severe else slice(None)  # locations in the order of their values
    log_lik_before = (before.log_post - grid.log_prior).reshape(table)[rising]
    log_lik_now = (now.log_post - grid.log_prior).reshape(table)[rising]
    evidence_before = special.logsumexp(log_lik_before, axis=0)
    evidence_now = special.logsumexp(log_lik_now, axis=0)
    log_shape = grid.log_prior.reshape(table)[0] + evidence_before + evidence_now
    shape_weights = np.exp(log_shape - special.logsumexp(log_shape))
    values = axis.to_value(np.clip(now.s_values(reliability), 0.0, 1.0)).reshape(table)[rising]  # non-decreasing down each column
    total = 0.0
    for shape in np.flatnonzero(shape_weights > shape_weights.max() * _NEGLIGIBLE):
        weights_before = np.exp(log_lik_before[:, shape] - evidence_before[shape])
        weights_now = np.exp(log_lik_now[:, shape] - evidence_now[shape])
        column = values[:, shape]
        step = limit * np.abs(column) / 100 if relative else limit
        below = np.concatenate([[0.0], np.cumsum(weights_now)])  # below[k]: mass of the k smallest values
        if worse == "lower":  # a regression: now beyond before + step
            moved = 1.0 - below[np.searchsorted(column, column + step, side="right")]
        else:  # now below before - step
            moved = below[np.searchsorted(column, column - step, side="left")]
        total += shape_weights[shape] * float(weights_before @ moved)
    return min(max(total, 0.0), 1.0)
