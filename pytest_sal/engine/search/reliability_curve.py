"""The chance that a noisy system holds its requirement, as a curve over severity.

Every run at a severity is one Bernoulli observation: the requirement's criteria held, or not.
The curve is the psychometric / probability-of-detection model of psychophysics (psignifit,
QUEST+) and of hit/miss reliability testing (MIL-HDBK-1823A), falling with severity::

    p(x) = floor + (ceiling - floor) * expit(-(x - location) / width)

on the severity axis ``x`` of ``SeverityAxis`` (0 at the search range's mild end, 1 at its
severe end; log for parameters searched over decades). ``ceiling`` (1 minus the lapse rate: a
run fails for no reason of the severity) and ``floor`` (a run holds whatever the severity, the
plateau of a late initialisation that happens one run in two) are fitted, so a plateau is
modelled instead of being forced into a cliff; ``width`` -> 0 is a deterministic step.

The fit is a Bayesian posterior on a grid of the four parameters (psignifit's method; QUEST+
keeps the same grid posterior), with scipy's distributions and special functions: priors
uniform in location over the range and a bit beyond, log-uniform in width, Beta(1, 10) on the
lapse rate and Beta(1, 3) on the floor (psignifit's choice for the lapse; a wider one for the
floor, whose plateaus near 0.5 are real here). From it:

- ``s_R``: the most severe ``x`` where ``p >= R`` (``location - width * logit((R - floor) /
  (ceiling - floor))``; beyond the range's severe end when ``floor >= R``, before its mild end
  when ``ceiling <= R``), its posterior median (``estimate``), the one-sided bound ``s_R/C``
  (the ``1 - C`` quantile toward the mild side: ``s_R`` is at least this severe with
  probability ``C``) and the equal-tailed interval at ``C``;
- ``holds_at(x, R)``: the posterior probability that ``p(x) >= R`` (a requirement's verdict);
- ``band``: the curve's pointwise median and interval (plots);
- ``expected_entropy``: the entropy of ``s_R``'s posterior expected after one more run at each
  candidate severity (the Psi method's / QUEST+'s placement rule, for ``s_R``).

Checked by simulation against systems of known ``p(x)``: ``benchmarks/bench_reliability.py``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import special, stats

__all__ = ["CurveFit", "SeverityAxis", "fit_curve"]

#: lapse rates (1 - ceiling) and floors of the grid; their priors are Beta(1, 10) and Beta(1, 3)
_LAPSES = np.array([0.0, 0.02, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4])
_FLOORS = np.array([0.0, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7])
_LAPSE_PRIOR = stats.beta(1, 10)
_FLOOR_PRIOR = stats.beta(1, 3)
#: widths of the grid: log-spaced from a step (a fraction of a grid cell) to the whole range
_WIDTHS = 10
#: how far beyond the range the location may lie (share of the range, each side)
_BEYOND = 0.25
#: s_R outside the range is clamped this far beyond it (it reads as "beyond the range")
_OUTSIDE = 0.05


@dataclass(frozen=True)
class SeverityAxis:
    """The severity axis ``x`` of a parameter's search range: 0 at ``mild``, 1 at ``severe``,
    in log(value) when ``log`` (a parameter searched over decades), else in the value.

    ``step`` is the spacing of the fixed grid of severities runs are placed on (``grid``;
    rounded to whole numbers when ``integer``, by ``grid_value``): a power of two, so the grids of different tolerances share their points and every session,
    xdist worker and cache entry of one parameter and range meet on the same values.
    """

    mild: float
    severe: float
    log: bool
    step: float
    integer: bool = False

    def to_x(self, value: float | np.ndarray) -> np.ndarray:
        v = np.asarray(value, dtype=float)
        if self.log:
            return (np.log(v) - math.log(self.mild)) / (math.log(self.severe) - math.log(self.mild))
        return (v - self.mild) / (self.severe - self.mild)

    def to_value(self, x: float | np.ndarray) -> np.ndarray:
        """The value at ``x``, kept inside the range (the ends exactly, despite rounding)."""
        t = np.clip(np.asarray(x, dtype=float), 0.0, 1.0)
        if self.log:
            value = np.exp(math.log(self.mild) + t * (math.log(self.severe) - math.log(self.mild)))
        else:
            value = self.mild + t * (self.severe - self.mild)
        return np.where(t == 0, self.mild, np.where(t == 1, self.severe, value))

    def grid_value(self, x: float) -> float:
        """The value a run at ``x`` of the grid takes (a whole number for an ``integer`` parameter)."""
        value = float(self.to_value(x))
        return float(round(value)) if self.integer else value

    @property
    def grid(self) -> np.ndarray:
        """The severities runs are placed on, as ``x`` (0, step, ..., 1)."""
        return np.linspace(0.0, 1.0, int(round(1 / self.step)) + 1)

    @classmethod
    def for_range(cls, mild: float, severe: float, log: bool, tolerance_x: float, integer: bool = False) -> SeverityAxis:
        """The axis whose grid step is the largest power of two at most half of ``tolerance_x``
        (the tolerance on the axis), between 1/64 and 1/256 of the range (finer grids cost more
        to fit than a noisy system's runs can resolve)."""
        level = min(8, max(6, math.ceil(math.log2(2 / max(tolerance_x, 1e-9)))))
        return cls(float(mild), float(severe), bool(log), 2.0**-level, integer)


class _Grid:
    """The parameter grid of the curve and its log prior (one per grid step: built once)."""

    def __init__(self, step: float):
        locations = np.arange(-_BEYOND, 1 + _BEYOND + step / 4, step / 2)  # a step may lie between two grid values
        #: grid points are ordered location first: ``reshape(locations, -1)`` gives a location x shape table
        self.locations = len(locations)
        widths = np.geomspace(step / 8, 0.4, _WIDTHS)
        loc, wid, lapse, floor = (a.ravel() for a in np.meshgrid(locations, widths, _LAPSES, _FLOORS, indexing="ij"))
        keep = (1 - lapse) - floor >= 0.1  # the curve falls by at least 0.1: ceiling above floor
        self.location, self.width, self.ceiling, self.floor = loc[keep], wid[keep], 1 - lapse[keep], floor[keep]
        self.log_prior = (
            _log_cell_prior(_LAPSES, _LAPSE_PRIOR)[np.searchsorted(_LAPSES, lapse[keep])]
            + _log_cell_prior(_FLOORS, _FLOOR_PRIOR)[np.searchsorted(_FLOORS, floor[keep])]
        )

    def p(self, x: float) -> np.ndarray:
        """``p(x)`` under every grid point."""
        return self.floor + (self.ceiling - self.floor) * special.expit(-(x - self.location) / self.width)

    def s_at(self, r: float) -> np.ndarray:
        """``s_R`` on the axis under every grid point, clamped to ``[-_OUTSIDE, 1 + _OUTSIDE]``."""
        q = (r - self.floor) / (self.ceiling - self.floor)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = self.location - self.width * special.logit(np.clip(q, 1e-12, 1 - 1e-12))
        s = np.where(q <= 0, np.inf, np.where(q >= 1, -np.inf, s))
        return np.clip(s, -_OUTSIDE, 1 + _OUTSIDE)


_GRIDS: dict[float, _Grid] = {}


def _grid(step: float) -> _Grid:
    if step not in _GRIDS:
        _GRIDS[step] = _Grid(step)
    return _GRIDS[step]


def _log_cell_prior(points: np.ndarray, prior: stats.rv_continuous) -> np.ndarray:
    """Log prior mass of the cells around ``points`` (midpoints between neighbours as edges)."""
    edges = np.concatenate([[0.0], (points[1:] + points[:-1]) / 2, [1.0]])
    return np.log(np.diff(prior.cdf(edges)))


@dataclass(frozen=True)
class Interval:
    """A posterior summary on the axis: ``estimate`` (median), ``low`` / ``high`` (the
    equal-tailed interval) and ``bound`` (the one-sided bound toward the mild side)."""

    estimate: float
    low: float
    high: float
    bound: float


class CurveFit:
    """The posterior of the curve given runs (``fit_curve``)."""

    def __init__(self, axis: SeverityAxis, xs: np.ndarray, held: np.ndarray, log_post: np.ndarray | None = None):
        self.axis = axis
        self.grid = _grid(axis.step)
        self.xs, self.held = xs, held
        if log_post is None:
            log_post = self.grid.log_prior + self._log_likelihood(xs, held)
        self.log_post = log_post
        self.weights = np.exp(log_post - special.logsumexp(log_post))
        self._s_cache: dict[float, np.ndarray] = {}

    def updated(self, values: Sequence[float], held: Sequence[bool]) -> CurveFit:
        """This fit with more runs at ``values`` (the parameter's unit)."""
        xs, flags = np.asarray(self.axis.to_x(np.asarray(values, dtype=float)), dtype=float), np.asarray(held, dtype=bool)
        return CurveFit(
            self.axis, np.concatenate([self.xs, xs]), np.concatenate([self.held, flags]), self.log_post + self._log_likelihood(xs, flags)
        )

    def _log_likelihood(self, xs: np.ndarray, held: np.ndarray) -> np.ndarray:
        """Log-likelihood of the runs under every grid point: ``k log p + (n - k) log(1 - p)`` per value."""
        total = np.zeros_like(self.grid.log_prior)
        for x in np.unique(xs):
            at = xs == x
            k, n = int(held[at].sum()), int(at.sum())
            p = self.grid.p(float(x))
            total += special.xlogy(k, p) + special.xlog1py(n - k, -p)
        return total

    @property
    def runs(self) -> int:
        return len(self.xs)

    def s_r(self, r: float, confidence: float) -> Interval:
        """``s_R`` on the axis: median, equal-tailed ``confidence`` interval, one-sided bound."""
        return self._summary(self._s_at(r), confidence)

    def transition(self) -> tuple[float, float]:
        """Where ``p`` has fallen by 10 % and by 90 % of its drop (``location -/+ width *
        logit(0.9)``): posterior medians on the axis, clamped like ``s_R``."""
        spread = self.grid.width * special.logit(0.9)
        start, end = (np.clip(self.grid.location + sign * spread, -_OUTSIDE, 1 + _OUTSIDE) for sign in (-1, 1))
        return self._summary(start, 0.5).estimate, self._summary(end, 0.5).estimate

    def holds_at(self, x: float, r: float) -> float:
        """Posterior probability that ``p(x) >= r``."""
        return float(self.weights[self.grid.p(x) >= r].sum())

    def p_at(self, x: float, confidence: float) -> Interval:
        """``p(x)``: median and equal-tailed interval (``bound``: its lower one-sided bound)."""
        return self._summary(self.grid.p(x), confidence)

    def band(self, xs: Sequence[float] | np.ndarray, confidence: float) -> np.ndarray:
        """Rows ``(x, median, low, high)`` of ``p`` at ``xs``."""
        rows = [(x, *(lambda i: (i.estimate, i.low, i.high))(self.p_at(float(x), confidence))) for x in xs]
        return np.array(rows, dtype=float)

    def entropy(self, r: float, edge_x: float | None = None, verdict_weight: float = 0.0) -> float:
        """The entropy (nats) of ``s_R``'s posterior, binned on the grid, plus ``verdict_weight``
        times the binary entropy of "``s_R`` is at least as severe as ``edge_x``"."""
        s = self._s_at(r)
        masses = np.bincount(np.searchsorted(self.axis.grid, s), self.weights, len(self.axis.grid) + 1)
        verdict = float(_binary_entropies(np.array([self.weights[s >= edge_x].sum()]))[0]) if edge_x is not None else 0.0
        return float(_entropies(masses[None, :])[0]) + verdict_weight * verdict

    def expected_entropy(self, candidates: np.ndarray, r: float, edge_x: float | None = None, verdict_weight: float = 0.0) -> np.ndarray:
        """For each candidate ``x``: ``entropy`` expected after one more run there (lower: the
        run says more about ``s_R``), plus ``verdict_weight`` times the expected binary entropy
        of "``s_R`` is at least as severe as ``edge_x``" (the verdict) when that is given.
        Vectorised over candidates (8 at a time), the grid points sorted by their ``s_R`` cell."""
        live = np.flatnonzero(self.weights > self.weights.max() * 1e-7)  # the rest cannot move an entropy
        s = self._s_at(r)[live]
        order = np.argsort(np.searchsorted(self.axis.grid, s), kind="stable")
        live, s = live[order], s[order]
        cells = np.searchsorted(self.axis.grid, s)
        starts = np.flatnonzero(np.concatenate([[True], cells[1:] != cells[:-1]]))
        weights = self.weights[live].astype(np.float32)  # single precision: twice as fast, ample for an entropy
        holds = s >= (edge_x if edge_x is not None else -np.inf)
        location, width, floor, ceiling = (
            a[live].astype(np.float32) for a in (self.grid.location, self.grid.width, self.grid.floor, self.grid.ceiling)
        )
        out = np.empty(len(candidates))
        for first in range(0, len(candidates), 8):
            xs = np.asarray(candidates[first : first + 8], dtype=np.float32)[:, None]
            held = weights * (floor + (ceiling - floor) * special.expit(-(xs - location) / width))
            missed = weights - held
            held_total, missed_total = held.sum(axis=1), missed.sum(axis=1)
            p_held = held_total / (held_total + missed_total)
            out[first : first + len(xs)] = p_held * _entropies(np.add.reduceat(held, starts, axis=1)) + (1 - p_held) * _entropies(
                np.add.reduceat(missed, starts, axis=1)
            )
            if verdict_weight:
                out[first : first + len(xs)] += verdict_weight * (
                    p_held * _binary_entropies(held[:, holds].sum(axis=1) / held_total)
                    + (1 - p_held) * _binary_entropies(missed[:, holds].sum(axis=1) / missed_total)
                )
        return out

    def s_values(self, r: float) -> np.ndarray:
        """``s_R`` on the axis under every grid point of the curve (``weights`` are their masses)."""
        return self._s_at(r)

    def _s_at(self, r: float) -> np.ndarray:
        if r not in self._s_cache:
            self._s_cache[r] = self.grid.s_at(r)
        return self._s_cache[r]

    def _summary(self, values: np.ndarray, confidence: float) -> Interval:
        """Weighted quantiles of ``values`` (one per grid point) under the posterior; grid points
        with a mass below 1e-12 of the largest are left out (they move no quantile)."""
        live = self.weights > self.weights.max() * 1e-12
        values, weights = values[live], self.weights[live]
        order = np.argsort(values, kind="stable")
        cumulative = np.cumsum(weights[order])
        sorted_values = values[order]

        def quantile(q: float) -> float:
            return float(sorted_values[min(np.searchsorted(cumulative, q * cumulative[-1]), len(values) - 1)])

        tail = (1 - confidence) / 2
        return Interval(quantile(0.5), quantile(tail), quantile(1 - tail), quantile(1 - confidence))


def _entropies(masses: np.ndarray) -> np.ndarray:
    """Entropy (nats) of each row of ``masses`` as a distribution: ``sum(entr(m / total))``, 0 for an empty row."""
    totals = masses.sum(axis=1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(totals[:, 0] > 0, special.entr(masses / totals).sum(axis=1), 0.0)


def _binary_entropies(p: np.ndarray) -> np.ndarray:
    return special.entr(p) + special.entr(1 - p)


def fit_curve(axis: SeverityAxis, values: Sequence[float], held: Sequence[bool]) -> CurveFit:
    """The posterior of the curve after runs at ``values`` (the parameter's unit) that held or not."""
    xs = axis.to_x(np.asarray(values, dtype=float)) if len(values) else np.zeros(0)
    return CurveFit(axis, np.asarray(xs, dtype=float), np.asarray(held, dtype=bool))
