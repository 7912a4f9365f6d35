"""Regression checks against the run history and the warm start it gives a search.

``--sal-compare-fail`` texts are parsed by ``parse_compare_fail`` into ``RegressionCheck``
objects whose ``fails`` says, in words, how the boundary or a metric at the envelope's edge got
worse than in the previous outcome (``History.baseline``); ``warm_start`` turns the previous
boundary into the first trials of the next search.

``judge`` is the one rule of what a regression is, for the plugin's gate and ``sal compare``
alike: a verdict worse than the baseline's, a check given that fails (these fail: pytest fails
the test, ``sal compare`` exits 1), and, when no check is given, what ``DEFAULT_CHECKS`` find
(said as a regression, failing nothing).
"""

from __future__ import annotations

import argparse
import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from pytest_sal.engine.outcomes.outcome import Outcome, Trial
from pytest_sal.engine.outcomes.quantity import with_unit
from pytest_sal.engine.requirements import METRICS
from sal_adapters.common.suggest import closest

__all__ = [
    "DEFAULT_CHECKS",
    "VERDICT_RANK",
    "BoundaryCheck",
    "Judgement",
    "MetricCheck",
    "RegressionCheck",
    "edge_trial",
    "judge",
    "parse_compare_fail",
    "regressions",
    "warm_start",
]

_EPS = 1e-9  # "more than the limit": a change equal to it (up to rounding) does not fail


COMPARE_FAIL_FORMS = (
    "boundary:10% (the boundary's pass value moved toward the mild side by more than 10 % of its previous value), "
    "boundary:2.5 (... by more than 2.5 in the parameter's unit), "
    "METRIC:0.2 (the metric at the envelope's edge got worse by more than 0.2 in its unit), "
    "METRIC:15% (... by more than 15 % of its previous value); METRIC is one of " + ", ".join(METRICS)
)


class RegressionCheck(ABC):
    """One ``--sal-compare-fail`` check; ``str(check)`` is its text (``boundary:10%``)."""

    limit: float
    relative: bool

    @abstractmethod
    def fails(self, current: Outcome, previous: Outcome) -> str | None:
        """Why ``current`` regressed against ``previous``, in words, or ``None``.

        Improvements never fail. Outcomes that are not comparable (a different parameter, search
        direction or envelope edge: the test changed) give ``None``.
        """
        raise NotImplementedError(f"{type(self).__name__}.fails")

    def _exceeds(self, change: float) -> bool:
        return change > self.limit * (1 + _EPS) + _EPS * 1e-3

    def _limit_text(self, unit: str) -> str:
        return f"{self.limit:g} %" if self.relative else with_unit(self.limit, unit)

    def _moved(self, before: float, now: float, worse_by: float, unit: str) -> str | None:
        """The change from ``before`` to ``now`` in words (``+47 %``, ``+7 m``) when getting
        worse by ``worse_by`` exceeds the limit, else ``None``."""
        if worse_by <= 0:
            return None
        change = worse_by if not self.relative else (math.inf if before == 0 else 100.0 * worse_by / abs(before))
        if not self._exceeds(change):
            return None
        if self.relative:
            return "from 0" if before == 0 else _percent(100.0 * (now - before) / abs(before))
        return _signed_quantity(now - before, unit)


@dataclass(frozen=True)
class BoundaryCheck(RegressionCheck):
    """``boundary:LIMIT`` / ``boundary:LIMIT%``: the boundary moved toward the mild side.

    Compared is the boundary's ``pass_value``, the most severe value at which the system still
    met its requirement. It regressed when it moved toward the mild side (for ``worse='lower'``,
    such as ``fog.visibility_m``, it got larger): by more than ``limit`` in the parameter's unit,
    or, relative, by more than ``limit`` percent of ``|previous pass_value|``.

    The relative change is the scale-free change of the pass value itself, not of the margin to
    the envelope's edge: the margin is undefined for tests without an edge, tiny (and its relative
    change huge) when the boundary sits near the edge, and changes meaning when the edge is
    moved; the pass value's relative change reads the same on geometric scales (visibility 1 m
    to 100 km: 15 m -> 22 m is +47 % wherever the edge is). At a previous pass value of 0 any
    move toward the mild side counts as exceeding a relative limit.

    A boundary that now failed everywhere searched (no pass value) regressed, unless it did
    before too. A previous boundary without a pass value cannot get worse.

    A noisy system's boundary is statistical: its ``s_R`` regressed when the probability that
    it moved toward the mild side by more than the limit, from the baseline's runs to this
    run's, reaches the current outcome's confidence (``engine.search.reliability_compare``).
    """

    limit: float
    relative: bool

    def __str__(self) -> str:
        return f"boundary:{self.limit:g}{'%' if self.relative else ''}"

    def fails(self, current: Outcome, previous: Outcome) -> str | None:
        if not _comparable(current, previous):
            return None
        if current.boundary.noisy and previous.boundary.noisy:
            return self._statistical(current, previous)
        before, now = previous.boundary.pass_value, current.boundary.pass_value
        unit = current.boundary.unit or previous.boundary.unit
        where = "down to" if current.worse == "lower" else "up to"
        label = f"{current.parameter} boundary"
        if before is None:
            return None
        if now is None:
            return (
                f"{label} moved toward the mild side: passed {where} {with_unit(before, unit)} before, "
                f"now failed everywhere searched (limit {self._limit_text(unit)})"
            )
        moved = self._moved(before, now, (now - before) if current.worse == "lower" else (before - now), unit)
        if moved is None:
            return None
        toward = "toward the requirement" if _at_or_beyond_edge(now, current) else "toward the mild side, past the requirement"
        return (
            f"{label} moved {toward}: passed {where} {with_unit(before, unit)} before, now only {where} "
            f"{with_unit(now, unit)} ({moved}, limit {self._limit_text(unit)})"
        )

    def _statistical(self, current: Outcome, previous: Outcome) -> str | None:
        """A noisy system's ``s_R`` moved beyond the limit with the current outcome's confidence
        (``reliability_compare``): both curves fitted again from their runs."""
        from pytest_sal.engine.search.reliability_compare import refit, regression_probability

        now_b, before_b = current.boundary, previous.boundary
        if now_b.reliability != before_b.reliability or now_b.search_range != before_b.search_range:
            return None  # another requirement: not comparable
        now_fit = refit(current)
        before_fit = refit(previous, now_fit.axis) if now_fit is not None else None  # the baseline on this run's axis
        if now_fit is None or before_fit is None:
            return None
        assert now_b.reliability is not None and now_b.confidence is not None
        probability = regression_probability(before_fit, now_fit, now_b.reliability, self.limit, self.relative, current.worse)
        if probability < now_b.confidence:
            return None
        name, unit = f"s{100 * now_b.reliability:.4g}", now_b.unit or before_b.unit
        return (
            f"{current.parameter} {name} moved toward the mild side by more than {self._limit_text(unit)} with probability "
            f"{100 * probability:.3g} % (>= {100 * now_b.confidence:.4g} %): {name} {with_unit(before_b.estimate, unit)} before "
            f"({before_b.runs} runs), now {with_unit(now_b.estimate, unit)} ({now_b.runs} runs)"
        )


@dataclass(frozen=True)
class MetricCheck(RegressionCheck):
    """``METRIC:LIMIT`` / ``METRIC:LIMIT%``: the metric at the envelope's edge got worse.

    Compared are the aggregated metrics of each outcome's edge trial (its first trial at the
    ``edge`` value, see ``edge_trial``). Worse follows the metric: larger for ``ate_rmse``,
    smaller for ``tracking_rate``; by more than ``limit`` in the metric's unit, or by more than
    ``limit`` percent of ``|previous value|``. A metric that is now missing (the run failed,
    nothing tracked) regressed when it was there before. Outcomes whose edges differ, or without
    an edge trial, are not compared.
    """

    metric: str
    limit: float
    relative: bool

    def __str__(self) -> str:
        return f"{self.metric}:{self.limit:g}{'%' if self.relative else ''}"

    def fails(self, current: Outcome, previous: Outcome) -> str | None:
        if not _comparable(current, previous) or current.edge is None:
            return None
        trial_now, trial_before = edge_trial(current), edge_trial(previous)
        if trial_now is None or trial_before is None:
            return None
        before, now = _number(trial_before.metrics.get(self.metric)), _number(trial_now.metrics.get(self.metric))
        metric = METRICS[self.metric]
        at = f"{self.metric} at the envelope's edge ({current.parameter} = {with_unit(current.edge, current.boundary.unit)})"
        if before is None:
            return None
        if now is None:
            return f"{at} got worse: {with_unit(before, metric.unit)} before, now not available (the runs failed)"
        moved = self._moved(before, now, (now - before) if metric.better == "lower" else (before - now), metric.unit)
        if moved is None:
            return None
        return (
            f"{at} got worse: {with_unit(before, metric.unit)} before, now {with_unit(now, metric.unit)} "
            f"({moved}, limit {self._limit_text(metric.unit)})"
        )


def parse_compare_fail(text: str) -> RegressionCheck:
    """argparse type for ``--sal-compare-fail``: ``boundary:10%``, ``boundary:2.5``,
    ``ate_rmse:0.2``, ``ate_rmse:15%`` (any metric of ``METRICS``).

    >>> parse_compare_fail("boundary:10%")
    BoundaryCheck(limit=10.0, relative=True)
    >>> str(parse_compare_fail(" ATE_RMSE : 0.2 "))
    'ate_rmse:0.2'

    Raises:
        argparse.ArgumentTypeError: the text is none of the forms; the message lists them.
    """
    what, sep, amount = str(text).partition(":")
    what, amount = what.strip().lower(), amount.strip().replace(" ", "")

    def bad(reason: str) -> argparse.ArgumentTypeError:
        return argparse.ArgumentTypeError(f"{text!r}: {reason}; valid forms: {COMPARE_FAIL_FORMS}")

    if not sep:
        raise bad("expected WHAT:LIMIT")
    if what != "boundary" and what not in METRICS:
        close = closest(what, ["boundary", *METRICS])  # the valid forms below list them all
        raise bad(f"unknown quantity {what!r}" + (f" (did you mean {close!r}?)" if close else ""))
    relative = amount.endswith("%")
    number = amount[:-1] if relative else amount
    try:
        limit = float(number)
    except ValueError:
        raise bad(f"the limit {amount!r} is not a number") from None
    if not math.isfinite(limit) or limit < 0:
        raise bad(f"the limit must be a finite number >= 0, got {amount!r}")
    return BoundaryCheck(limit, relative) if what == "boundary" else MetricCheck(what, limit, relative)


@dataclass(frozen=True)
class Judgement:
    """A test's regressions against its baseline, in words (``judge``).

    Attributes:
        verdict: the verdict got worse (``passed in the baseline, failed now``), or ``None``;
            under pytest the test fails by itself (its requirement is not met).
        failing: the checks given that fail (``--sal-compare-fail``, ``sal compare --fail``).
        said: without checks given, what ``DEFAULT_CHECKS`` find: a regression said, not failed.
    """

    verdict: str | None
    failing: list[str]
    said: list[str]

    @property
    def found(self) -> list[str]:
        """Every regression, the verdict's first."""
        return ([self.verdict] if self.verdict else []) + self.failing + self.said

    @property
    def fails(self) -> bool:
        """A regression that fails: a worse verdict or a check given."""
        return self.verdict is not None or bool(self.failing)


def judge(current: Outcome, previous: Outcome, checks: Sequence[RegressionCheck], baseline: str = "the baseline") -> Judgement:
    """``current`` against its baseline outcome ``previous`` (``History.baseline``): the one
    rule of a regression, for the plugin's gate and ``sal compare``; ``baseline`` names it in
    the verdict's message (``0001``)."""
    worse = VERDICT_RANK.get(current.verdict, 2) > VERDICT_RANK.get(previous.verdict, 2)
    verdict = f"{previous.verdict} in {baseline}, {current.verdict} now" if worse else None
    if checks:
        return Judgement(verdict, regressions(list(checks), current, previous), [])
    return Judgement(verdict, [], regressions(list(DEFAULT_CHECKS), current, previous))


def regressions(checks: list[RegressionCheck], current: Outcome, previous: Outcome | None) -> list[str]:
    """The messages of the ``checks`` that fail ``current`` against ``previous`` (none without
    a previous outcome)."""
    if previous is None:
        return []
    if previous.parameter == current.parameter and previous.boundary.unit != current.boundary.unit:
        return [
            f"not compared: the history has {current.parameter} in {previous.boundary.unit or 'no unit'!r}, this run in "
            f"{current.boundary.unit or 'no unit'!r}; save a new baseline with --sal-save"
        ]
    if current.boundary.noisy != previous.boundary.noisy and previous.parameter == current.parameter:
        kinds = {True: "statistical (a noisy system's s_R, fitted from its runs)", False: "a bisection's failure point"}
        return [
            f"not compared: the baseline's {current.parameter} boundary is {kinds[previous.boundary.noisy]}, this run's is "
            f"{kinds[current.boundary.noisy]} (history written before pytest-sal fitted noisy systems, or the system changed); "
            "save a new baseline with --sal-save"
        ]
    return [message for check in checks if (message := check.fails(current, previous)) is not None]


#: what a regression is when no check is given (``--sal-compare`` alone, ``sal compare``
#: without ``--fail``): said, never failing
DEFAULT_CHECKS: tuple[RegressionCheck, ...] = (BoundaryCheck(10.0, True),)
#: ``Outcome.verdict`` from best to worst (an unknown verdict counts as failed)
VERDICT_RANK = {"passed": 0, "inconclusive": 1, "flaky": 1, "failed": 2}


def warm_start(
    previous: Outcome | None,
    *,
    parameter: str | None = None,
    edge: float | None = None,
    worse: str | None = None,
) -> tuple[float | None, float | None] | None:
    """The previous boundary ``(pass_value, fail_value)`` to try first (``boundary_search``'s
    ``warm_start``), or ``None``: no previous outcome, no value in its boundary, or, when
    ``parameter`` / ``edge`` / ``worse`` of the current search are given, a previous search of a
    different parameter, edge or direction."""
    if previous is None:
        return None
    if parameter is not None and previous.parameter != parameter:
        return None
    if worse is not None and previous.worse != worse:
        return None
    if edge is not None and (previous.edge is None or not math.isclose(previous.edge, edge, rel_tol=1e-9, abs_tol=1e-12)):
        return None
    pair = (previous.boundary.pass_value, previous.boundary.fail_value)
    return None if pair == (None, None) else pair


def edge_trial(outcome: Outcome) -> Trial | None:
    """The trial at the outcome's edge value (``Outcome.trial_at``), or ``None``."""
    return outcome.trial_at(outcome.edge)


def _comparable(current: Outcome, previous: Outcome) -> bool:
    if current.parameter != previous.parameter or current.worse != previous.worse:
        return False
    if (current.edge is None) != (previous.edge is None):
        return False
    return current.edge is None or math.isclose(current.edge, previous.edge, rel_tol=1e-9, abs_tol=1e-12)  # type: ignore[arg-type]


def _at_or_beyond_edge(value: float, outcome: Outcome) -> bool:
    """``value`` is the edge or more severe (still meets the requirement there)."""
    if outcome.edge is None:
        return True
    return value <= outcome.edge if outcome.worse == "lower" else value >= outcome.edge


def _number(value: Any) -> float | None:
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if math.isfinite(number) else None


def _signed_quantity(value: float, unit: str) -> str:
    """A change with its sign, 4 significant digits (``+3.75 m``); unsigned values use ``with_unit``."""
    return f"{value:+.4g} {unit}" if unit else f"{value:+.4g}"


def _percent(value: float) -> str:
    return f"{value:+.0f} %" if abs(value) >= 9.95 else f"{value:+.1f} %"
