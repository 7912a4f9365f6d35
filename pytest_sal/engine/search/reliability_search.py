"""The search of a noisy system: where to run next, when to stop, and what the runs show.
Pure: it knows severities and whether each run held the requirement, not SLAM.

Each run is one sample of the curve ``p(severity)`` (``reliability_curve``). Runs go on the
fixed grid of the parameter's ``SeverityAxis`` (and the envelope's edge), so sessions, xdist
workers and the cache share them. The edge runs first; then each round places ``width()`` runs
(the executor's free slots) at the grid values whose run is expected to leave the least entropy
in the posterior of ``s_R``, the most severe value where ``p >= R`` (the Psi method's rule,
aimed at ``s_R``). A value whose next run is ``cached`` (it costs nothing) is taken instead
when it is worth at least half the best value's gain. Placement depends only on the runs, so
a second session with the cache replays the first and sends nothing.

It stops once the verdict is settled at ``confidence`` (``p(edge) >= R``, or ``< R``) and
``s_R``'s interval is within tolerance or two grid cells (or lies wholly beyond an end of the
range), or when
``max_runs`` runs of its own are spent. A verdict still open then is ``inconclusive``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from pytest_sal.engine.search.reliability_curve import CurveFit, Interval, SeverityAxis, fit_curve

__all__ = ["Observation", "ReliabilityResult", "more_runs_needed", "reliability_search", "verdict_of"]

#: at most this many grid values are scored before each round (spread over where s_R may lie)
_CANDIDATES = 20
#: every grid value this many cells either side of s_R's median is a candidate too (the thinned set may skip them)
_NEAR = 3
#: while the verdict is open, its entropy weighs this much against s_R's: the verdict first (it decides the test)
_VERDICT_WEIGHT = 20.0
#: a cached value is taken when its gain is at least this share of the best value's
_CACHED_SHARE = 0.5


@dataclass(frozen=True)
class Observation:
    """One run: its severity (the parameter's unit) and whether the requirement held
    (``None``: the run abstained, starved by the machine: no evidence)."""

    value: float
    held: bool | None


@dataclass
class ReliabilityResult:
    """What the runs show (see the module text).

    Attributes:
        verdict: ``passed``, ``failed`` or ``inconclusive``.
        fit: the fitted curve over every counted run.
        holds_at_edge: posterior probability that ``p(edge) >= R``.
        s_r: ``s_R`` on the axis (median, interval, one-sided bound at ``confidence``).
        s50: ``s_50`` on the axis (where half the runs hold).
        runs: runs this search made or read (against ``max_runs``).
        termination: ``settled`` or ``max_runs``.
    """

    verdict: str
    fit: CurveFit
    holds_at_edge: float
    s_r: Interval
    s50: Interval
    runs: int
    termination: str
    rounds: int = 0
    observations: list[Observation] = field(default_factory=list)


def verdict_of(fit: CurveFit, edge_x: float, reliability: float, confidence: float) -> tuple[str, float]:
    """``(verdict, P(p(edge) >= R))``: ``passed`` when that probability is at least
    ``confidence``, ``failed`` when at most ``1 - confidence``, else ``inconclusive``."""
    holds = fit.holds_at(edge_x, reliability)
    if holds >= confidence:
        return "passed", holds
    if holds <= 1 - confidence:
        return "failed", holds
    return "inconclusive", holds


def more_runs_needed(runs: int, holds: float, confidence: float) -> int | None:
    """About how many more runs would settle a verdict whose probability of holding is
    ``holds`` after ``runs`` runs: the bound's z-score grows as the square root of the runs,
    so ``runs * (z_C / z_now)^2`` in all; ``None`` when ``p(edge)`` sits on ``R`` (z ~ 0)."""
    z_now = abs(float(stats.norm.ppf(min(max(holds, 1e-12), 1 - 1e-12))))
    if z_now < 0.05:
        return None
    z_c = float(stats.norm.ppf(confidence))
    return max(1, math.ceil(max(runs, 1) * (z_c / z_now) ** 2) - runs)


def reliability_search(
    run: Callable[[list[float]], list[bool | None]],
    axis: SeverityAxis,
    edge: float,
    reliability: float,
    confidence: float,
    max_runs: int,
    *,
    tolerance: float | None = None,
    rel_tolerance: float | None = None,
    width: Callable[[], int] | None = None,
    cached: Callable[[float], bool] | None = None,
    earlier: Sequence[Observation] = (),
    at_edge_only: bool = False,
) -> ReliabilityResult:
    """Estimate the curve and settle the verdict at ``edge`` (see the module text).

    Args:
        run: one run at each value given (a value may repeat: that many runs); whether each
            held (``None``: abstained). Called with up to ``width()`` values at once.
        axis: the parameter's severity axis and grid.
        edge: the envelope's edge (the parameter's unit).
        reliability, confidence: ``R`` and ``C``.
        max_runs: the most runs this search makes (cached ones included).
        tolerance, rel_tolerance: stop once ``s_R``'s interval is at most this wide (the
            unit), or at most this share of its larger end.
        width: how many runs a round may hold now (``None``: 1).
        cached: whether the next run at a value would be read from a cache.
        earlier: runs already made (earlier in the session), counted in the fit and not in
            ``max_runs``.
        at_edge_only: every run at ``edge`` (one ``sal.sweep`` level or ``sal.at`` point),
            until the verdict settles; the tolerance does not apply.
    """
    width = width or (lambda: 1)
    cached = cached or (lambda value: False)
    observations = list(earlier)
    edge_x = float(axis.to_x(edge))
    spent = rounds = 0

    current = _fit(fit_curve(axis, [], []), observations)

    def place(values: list[float]) -> CurveFit:
        nonlocal spent, rounds
        rounds += 1
        spent += len(values)
        made = [Observation(v, h) for v, h in zip(values, run(values))]
        observations.extend(made)
        return _fit(current, made)

    current = place([edge] * max(1, min(width(), max_runs)))
    while True:
        verdict, holds = verdict_of(current, edge_x, reliability, confidence)
        s_r = current.s_r(reliability, confidence)
        if verdict != "inconclusive" and (at_edge_only or _within_tolerance(axis, s_r, tolerance, rel_tolerance)):
            termination = "settled"
            break
        if spent >= max_runs:
            termination = "max_runs"
            break
        count = min(max(1, width()), max_runs - spent)
        current = place([edge] * count if at_edge_only else _next_values(current, axis, edge, reliability, confidence, count, cached))
    return ReliabilityResult(
        verdict, current, holds, s_r, current.s_r(0.5, confidence), spent, termination, rounds, observations[len(earlier) :]
    )


def _fit(fit: CurveFit, observations: Sequence[Observation]) -> CurveFit:
    """``fit`` updated with the ``observations`` that did not abstain."""
    counted = [o for o in observations if o.held is not None]
    return fit.updated([o.value for o in counted], [bool(o.held) for o in counted]) if counted else fit


def _within_tolerance(axis: SeverityAxis, s_r: Interval, tolerance: float | None, rel_tolerance: float | None) -> bool:
    """``s_R``'s interval is within tolerance, within two cells of the grid or one unit of an
    integer parameter (runs on the grid cannot narrow it further), or wholly beyond one end of
    the range."""
    if s_r.low >= 1 or s_r.high <= 0 or s_r.high - s_r.low <= 2 * axis.step * (1 + 1e-9):
        return True
    low, high = (float(axis.to_value(min(max(x, 0.0), 1.0))) for x in (s_r.low, s_r.high))
    spread = abs(high - low)
    if axis.integer and spread <= 1:  # whole numbers cannot resolve it further
        return True
    if tolerance is not None:
        return spread <= tolerance
    return rel_tolerance is not None and spread <= rel_tolerance * max(abs(low), abs(high))


def _next_values(
    current: CurveFit, axis: SeverityAxis, edge: float, reliability: float, confidence: float, count: int, cached: Callable[[float], bool]
) -> list[float]:
    """The ``count`` grid values (or the edge) whose next run says most about ``s_R``."""
    edge_x = float(axis.to_x(edge))
    candidates = _candidates(current, axis, edge_x, reliability)
    open_verdict = verdict_of(current, edge_x, reliability, confidence)[0] == "inconclusive"
    weight = _VERDICT_WEIGHT if open_verdict else 0.0
    gains = current.entropy(reliability, edge_x, weight) - current.expected_entropy(candidates, reliability, edge_x, weight)
    values = [edge if x == edge_x else axis.grid_value(x) for x in candidates]
    order = [int(i) for i in np.argsort(-gains, kind="stable")]
    chosen = order[:count]
    free = [i for i in order if gains[i] >= _CACHED_SHARE * gains[order[0]] and cached(values[i])]
    if free and free[0] not in chosen:
        chosen = [free[0], *chosen[: count - 1]]
    return [values[i] for i in chosen]


def _candidates(current: CurveFit, axis: SeverityAxis, edge_x: float, reliability: float) -> np.ndarray:
    """Grid values where ``s_R`` may lie (its 0.5-99.5 % posterior range, a few cells wider,
    both ends of the range kept), thinned to at most ``_CANDIDATES``; every grid value within
    ``_NEAR`` cells of ``s_R``'s median (so a cliff is resolved to one cell, not to the thinned
    spacing); and the edge."""
    grid = axis.grid
    s = current.s_r(reliability, 0.99)
    lo, hi = max(0.0, s.low - 4 * axis.step), min(1.0, s.high + 4 * axis.step)
    inside = grid[(grid >= lo) & (grid <= hi)]
    if len(inside) > _CANDIDATES:
        inside = inside[:: math.ceil(len(inside) / _CANDIDATES)]
    near = grid[np.abs(grid - s.estimate) <= _NEAR * axis.step * (1 + 1e-9)]
    return np.unique(np.concatenate([inside, near, [edge_x]]))
