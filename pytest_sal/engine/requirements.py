"""The requirement language: metrics compared with numbers are pass criteria, parameters
compared with numbers are operating envelopes.

>>> from pytest_sal import ate_rmse, tracking_rate
>>> from sal_modules import fog
>>> req = Requirement.build([ate_rmse < 1.5, tracking_rate >= 0.9, fog.visibility_m >= 25])
>>> str(req)
'ate_rmse < 1.5 m and tracking_rate >= 0.9 wherever fog.visibility_m >= 25 m'

Misuse is an ``InvalidRequirement`` (a ``TypeError``) raised when the test module is imported,
so pytest reports it at collection, with what to write instead.
"""

from __future__ import annotations

import math
import numbers
import operator
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from pytest_sal.engine.tolerance import parse_tolerance
from sal_adapters.common.errors import SalError
from sal_modules.params import Bound, ParamRef

__all__ = [
    "METRICS",
    "Criterion",
    "InvalidRequirement",
    "Metric",
    "Requirement",
    "SearchSettings",
    "ate_rmse",
    "r_rel",
    "rpe_rot",
    "rpe_trans",
    "scale_error",
    "t_rel",
    "tracking_rate",
]

_OPS: dict[str, Callable[[float, float], bool]] = {"<": operator.lt, "<=": operator.le, ">": operator.gt, ">=": operator.ge}


class InvalidRequirement(SalError, TypeError):
    """A requirement written wrongly (the message says what to write instead)."""


@dataclass(frozen=True, eq=False)
class Metric:
    """A metric of a trial (``RunMetrics`` attribute ``name``) that criteria compare with numbers.

    Attributes:
        name: attribute of ``pytest_sal.analysis.metrics.RunMetrics``.
        unit: its unit, for messages.
        better: ``lower`` or ``higher``.
        doc: one line.
        lowest, highest: the values the metric can take (a criterion outside them is refused).
    """

    name: str
    unit: str
    better: str
    doc: str = ""
    lowest: float = 0.0
    highest: float = math.inf

    def _criterion(self, op: str, value: Any) -> Criterion:
        if not isinstance(value, numbers.Real) or isinstance(value, bool) or not math.isfinite(float(value)):
            example = "1.5" if self.better == "lower" else "0.95"
            raise InvalidRequirement(
                f"{self.name} {op} {value!r}: compare a metric with a finite number in {self.unit or 'its unit'}, "
                f"e.g. {self.name} {'<' if self.better == 'lower' else '>='} {example}"
            )
        threshold = float(value)
        lo, hi = self.lowest, self.highest
        never = {"<": threshold <= lo, "<=": threshold < lo, ">": threshold >= hi, ">=": threshold > hi}[op]
        always = {"<": threshold > hi, "<=": threshold >= hi, ">": threshold < lo, ">=": threshold <= lo}[op]
        if never or always:
            unit = f" {self.unit}" if self.unit else ""
            span = f"{lo:g} .. {hi:g}{unit}" if math.isfinite(hi) else f"{lo:g}{unit} or more"
            raise InvalidRequirement(
                f"{self.name} {op} {threshold:g}{unit} {'can never hold' if never else 'always holds, so it tests nothing'}: "
                f"{self.name} is {span}; pick a threshold inside that range"
            )
        return Criterion(self, op, threshold)

    def __lt__(self, value: Any) -> Criterion:
        return self._criterion("<", value)

    def __le__(self, value: Any) -> Criterion:
        return self._criterion("<=", value)

    def __gt__(self, value: Any) -> Criterion:
        return self._criterion(">", value)

    def __ge__(self, value: Any) -> Criterion:
        return self._criterion(">=", value)

    __hash__ = object.__hash__

    def __repr__(self) -> str:
        return f"<Metric {self.name} [{self.unit or '-'}]>"


ate_rmse = Metric("ate_rmse", "m", "lower", "absolute trajectory error, RMSE after SE(3) (Sim(3) for mono) alignment")
rpe_trans = Metric("rpe_trans", "m/m", "lower", "relative translation error per metre travelled (RMSE)")
rpe_rot = Metric("rpe_rot", "deg/m", "lower", "relative rotation error per metre travelled (RMSE)")
tracking_rate = Metric("tracking_rate", "", "higher", "frames with a valid pose / frames given", highest=1.0)
scale_error = Metric("scale_error", "", "lower", "|1 - s| of the Sim(3) alignment (mono)")
t_rel = Metric("t_rel", "%", "lower", "KITTI translation error: mean over segments (ini sal_kitti_segments) of drift / length")
r_rel = Metric("r_rel", "deg/100m", "lower", "KITTI rotation error: mean over segments (ini sal_kitti_segments) of angle / length")

#: Metrics by name.
METRICS: dict[str, Metric] = {m.name: m for m in (ate_rmse, rpe_trans, rpe_rot, tracking_rate, scale_error, t_rel, r_rel)}


@dataclass(frozen=True, eq=False)
class Criterion:
    """``metric op threshold``; a missing metric (the run failed, nothing tracked) fails it."""

    metric: Metric
    op: str
    threshold: float

    def holds(self, metrics: Mapping[str, Any]) -> bool:
        value = metrics.get(self.metric.name)
        return value is not None and math.isfinite(float(value)) and _OPS[self.op](float(value), self.threshold)

    def __bool__(self) -> bool:
        raise InvalidRequirement(f"{self} is a criterion for sal.require(...), not a truth value; use criterion.holds(metrics)")

    def __str__(self) -> str:
        unit = f" {self.metric.unit}" if self.metric.unit else ""
        return f"{self.metric.name} {self.op} {self.threshold:g}{unit}"


@dataclass(frozen=True, eq=False)
class Requirement:
    """Criteria that must hold wherever the envelope holds.

    Attributes:
        criteria: pass criteria (all must hold).
        envelope: the parameter bound searched, or ``None`` (``sal.sweep`` / ``sal.at`` only).
        options: ``tolerance`` (``pytest_sal.engine.tolerance``), ``max_trials``, ``runs``, ``search_range``, ``seed``,
            ``reliability``, ``confidence``, ``max_runs`` as given.
    """

    criteria: tuple[Criterion, ...]
    envelope: Bound | None = None
    options: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def build(cls, items: Iterable[Any], **options: Any) -> Requirement:
        """Sort ``items`` into criteria and one envelope; raise ``InvalidRequirement`` on misuse."""
        criteria: list[Criterion] = []
        envelopes: list[Bound] = []
        for item in items:
            if isinstance(item, Criterion):
                criteria.append(item)
            elif isinstance(item, Bound):
                envelopes.append(item)
            elif isinstance(item, Metric):
                raise InvalidRequirement(f"{item.name} alone is not a criterion: compare it with a number, e.g. {item.name} < 1.5")
            elif isinstance(item, ParamRef) or hasattr(item, "qualname"):
                label = getattr(item, "label", None) or item.qualname
                raise InvalidRequirement(f"{label} alone is not an envelope: compare it with a number, e.g. {label} >= 25")
            else:
                raise InvalidRequirement(
                    f"sal.require() takes metric criteria (ate_rmse < 1.5) and one parameter bound (fog.visibility_m >= 25); got {item!r}"
                )
        if not criteria:
            raise InvalidRequirement(
                "sal.require() needs at least one metric criterion, e.g. sal.require(ate_rmse < 1.5, fog.visibility_m >= 25)"
            )
        if len(envelopes) > 1:
            shown = ", ".join(str(e) for e in envelopes)
            raise InvalidRequirement(
                f"sal.require() searches one parameter; got {len(envelopes)} envelopes ({shown}). "
                f"Write one test per parameter, or chain the modules and bound one parameter: "
                f"sal.require(ate_rmse < 1.5, (night() >> fog).visibility_m >= 40)"
            )
        envelope = envelopes[0] if envelopes else None
        if envelope is not None:
            _check_envelope(envelope)
        _check_options(options, envelope)
        return cls(tuple(criteria), envelope, dict(options))

    def holds(self, metrics: Mapping[str, Any]) -> bool:
        return all(c.holds(metrics) for c in self.criteria)

    def criteria_rows(self) -> list[tuple[str, str, float]]:
        """The criteria as ``(metric, op, threshold)``: the form outcomes, history and reports keep."""
        return [(c.metric.name, c.op, c.threshold) for c in self.criteria]

    def failed(self, metrics: Mapping[str, Any]) -> list[Criterion]:
        return [c for c in self.criteria if not c.holds(metrics)]

    def __str__(self) -> str:
        text = " and ".join(str(c) for c in self.criteria)
        return text + (f" wherever {self.envelope}" if self.envelope is not None else "")


def _check_envelope(bound: Bound) -> None:
    param = bound.ref.param
    if not param.searchable:
        searchable = _searchable_names(param.owner)
        hint = f"; searchable parameters of {param.owner.name}: {', '.join(searchable)}" if searchable else ""  # type: ignore[union-attr]
        raise InvalidRequirement(f"{bound.ref.label} is not searchable, so it cannot be an envelope{hint}")
    worse_side = {"lower": ("<", "<="), "higher": (">", ">=")}[param.worse]  # type: ignore[index]
    if bound.op in worse_side:
        better = ">=" if param.worse == "lower" else "<="
        raise InvalidRequirement(
            f"{bound}: {bound.ref.label} gets worse when {param.worse}, so an envelope bounds its severe side: "
            f"write {bound.ref.label} {better} {bound.value:g} (the system must cope with everything milder)"
        )
    try:
        param.validate(bound.value, param.owner.name)  # type: ignore[union-attr]
    except SalError as exc:
        raise InvalidRequirement(f"{bound}: {exc}") from None
    unchanged = bound.ref.unchanged_at(bound.value)
    if unchanged is not None:
        raise InvalidRequirement(
            f"{bound}: the envelope's edge cannot change the frames ({unchanged}), so the test would pass "
            f"whatever the system does; bound a severity that perturbs, e.g. {bound.ref.label} {bound.op} {param.default:g}"
            f"{' ' + bound.ref.unit if bound.ref.unit else ''}"
        )


def _check_search_range(envelope: Bound, search_range: Any) -> None:
    """``search_range`` must be an interval inside the scale the search walks."""
    scale = envelope.ref.param.search_space()
    unit = f" {scale.unit}" if scale.unit else ""
    lo, hi = sorted(float(v) for v in search_range)
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo == hi:
        raise InvalidRequirement(
            f"sal.require(): search_range {tuple(search_range)!r} must be two finite numbers low < high, in{unit or ' the unit'}"
        )
    if lo < scale.min or hi > scale.max:
        raise InvalidRequirement(
            f"sal.require(): search_range ({lo:g}, {hi:g}){unit} leaves the valid range of {envelope.ref.label}, "
            f"{scale.min:g} .. {scale.max:g}{unit}"
        )


def _searchable_names(owner: Any) -> list[str]:
    return list(owner.searchable()) if owner is not None and hasattr(owner, "searchable") else []


def _check_options(options: Mapping[str, Any], envelope: Bound | None) -> None:
    known = {"tolerance", "max_trials", "runs", "search_range", "seed", "reliability", "confidence", "max_runs"}
    unknown = sorted(set(options) - known)
    if unknown:
        raise InvalidRequirement(f"sal.require(): unknown option(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}")
    for name in ("max_trials", "runs", "max_runs"):
        value = options.get(name)
        if value is not None and (not isinstance(value, int) or isinstance(value, bool) or value < 1):
            raise InvalidRequirement(f"sal.require(): {name} must be a whole number >= 1, got {value!r}")
    for name, lowest in (("reliability", 0.0), ("confidence", 0.5)):
        value = options.get(name)
        if value is not None and (
            not isinstance(value, numbers.Real) or isinstance(value, bool) or not math.isfinite(value) or not lowest < float(value) < 1
        ):
            raise InvalidRequirement(f"sal.require(): {name} must be a probability between {lowest:g} and 1 (both excluded), got {value!r}")
    tolerance = options.get("tolerance")
    if tolerance is not None:
        try:
            parse_tolerance(tolerance)
        except ValueError as exc:
            raise InvalidRequirement(f"sal.require(): tolerance {exc}, got {tolerance!r}") from None
    search_range = options.get("search_range")
    if search_range is not None:
        if envelope is None:
            raise InvalidRequirement("sal.require(): search_range needs a parameter bound to search")
        if not (
            isinstance(search_range, (tuple, list)) and len(search_range) == 2 and all(isinstance(v, numbers.Real) for v in search_range)
        ):
            raise InvalidRequirement(
                f"sal.require(): search_range must be (low, high) in {envelope.ref.unit or 'the unit'}, got {search_range!r}"
            )
        _check_search_range(envelope, search_range)


@dataclass(frozen=True)
class SearchSettings:
    """Defaults a requirement may override (ini ``sal_tolerance``, ``sal_max_trials``,
    ``sal_reliability``, ``sal_confidence``, ``sal_max_runs``).

    Attributes:
        tolerance_pct: default tolerance, in percent (ini ``sal_tolerance = 10%``): the search
            stops when the bracket's width is at most this percent of its larger end (20-22 m
            at 10 %), which suits linear parameters and ones searched over decades
            (0.08-0.09 Mbit/s) alike (``pytest_sal.engine.tolerance``).
        max_trials: default trial budget (a deterministic system's bisection).
        reliability, confidence: a noisy system meets its requirement at the edge when
            ``p(edge) >= reliability`` with this one-sided confidence.
        max_runs: default run budget of a noisy system's search.
    """

    tolerance_pct: float = 10.0
    max_trials: int = 8
    reliability: float = 0.8
    confidence: float = 0.9
    max_runs: int = 30
