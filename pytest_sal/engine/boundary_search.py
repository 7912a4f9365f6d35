"""Boundary search: where between the envelope's edge and the far end of the search range the
system stops meeting its requirement. Pure: it knows values and verdicts, not SLAM.

Severity runs from ``mild`` to ``severe`` (for fog, from long to short visibility). The
search evaluates the envelope's ``edge`` first: that trial decides the test. If it passes, the
failure boundary lies on the severe side and the search bisects between the edge and the
severe end; if it fails, the boundary lies on the mild side and it bisects between the edge and
the mild end. The interval ``(pass_value, fail_value)`` shrinks until it is within tolerance,
``max_trials`` is spent, or (integer domain) the two values are neighbours. When the far end
gives the same verdict as the edge, the boundary is not bracketed.

Every value is in the parameter's own unit. Bisection is geometric (``sqrt(a b)``) on a ``log``
scale, and on a linear one when both ends are positive and a decade or more apart (visibility
1..100000 m); arithmetic otherwise. The tolerance is absolute (``tolerance``, in the unit) or
relative (``rel_tolerance``: the bracket's width over its larger end), which suits a parameter
searched over decades (bandwidth 0.01..200 Mbit/s) as well as a linear one.

Noisy systems. A ``Judge`` may stand behind ``evaluate``: each trial is then a vote of runs
(see ``pytest_sal.votes``). The search asks it to ``confirm`` the edge and, at the end, both
ends of the bracket (or the far end, when it agrees with the edge) with a stronger lead of votes. When a confirmation turns an end's verdict,
the bracket is rebuilt from every trial and bisection goes on while the budget lasts. An edge
whose runs never settled on a verdict makes the result ``flaky``.

A previous boundary ``warm_start`` is tried right after the edge: when it still brackets within
tolerance, an unchanged system needs three trials. Every trial is checked against the order: a
pass more severe than a fail contradicts monotonicity and is reported.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

__all__ = ["TERMINATIONS", "Judge", "SearchResult", "SearchSpace", "TrialPoint", "boundary_search"]

#: Why a search stopped.
TERMINATIONS = ("tolerance", "max_trials", "not_bracketed", "domain_resolution")


@dataclass(frozen=True)
class SearchSpace:
    """The values a search may try, in the parameter's unit.

    Attributes:
        mild, severe: the ends of the search range (the mildest and the most severe value).
        domain: ``continuous`` or ``integer``.
        scale: ``log`` bisects geometrically; ``linear`` does so only over a decade or more.
    """

    mild: float
    severe: float
    domain: Literal["continuous", "integer"] = "continuous"
    scale: Literal["linear", "log"] = "linear"

    def worse(self, a: float, b: float) -> bool:
        """``a`` is more severe than ``b``."""
        return a < b if self.severe < self.mild else a > b

    def midpoint(self, a: float, b: float) -> float:
        """Geometric mean on a log scale, or when both are positive and a decade or more apart,
        else the mean; rounded to an integer strictly between them in the integer domain."""
        lo, hi = min(a, b), max(a, b)
        geometric = lo > 0 and (self.scale == "log" or hi / lo >= 10)
        mid = math.sqrt(lo * hi) if geometric else (lo + hi) / 2
        if self.domain == "integer":
            mid = float(min(max(round(mid), math.floor(lo) + 1), math.ceil(hi) - 1))
        return mid

    def neighbours(self, a: float, b: float) -> bool:
        return self.domain == "integer" and abs(a - b) <= 1


@dataclass
class TrialPoint:
    """One evaluated value: ``passed`` and whatever the evaluator reported (``info``)."""

    value: float
    passed: bool
    info: Any = None


class Judge(Protocol):
    """Verdict strength of a noisy system's trials (``info`` is the evaluator's trial)."""

    def confirm(self, info: Any) -> bool:
        """Run more of ``info``'s trial until its verdict is confirmed; the verdict now."""
        ...

    def settled(self, info: Any) -> bool:
        """The trial's runs agree enough to call its verdict (not a real disagreement)."""
        ...


@dataclass
class SearchResult:
    """What the search found.

    Attributes:
        edge_passed: the verdict at the envelope's edge (the test's verdict).
        pass_value, fail_value: the bracket: the most severe value seen to pass next to the
            mildest value seen to fail (either may be ``None`` when not bracketed).
        termination: one of ``TERMINATIONS``.
        trials: every evaluation in order.
        contradictions: trials that contradict monotonicity, in words.
        flaky: the edge's runs disagreed and never settled on a verdict.
    """

    edge_passed: bool
    pass_value: float | None
    fail_value: float | None
    termination: str
    trials: list[TrialPoint] = field(default_factory=list)
    contradictions: list[str] = field(default_factory=list)
    flaky: bool = False


def boundary_search(
    evaluate: Callable[[float], tuple[bool, Any]],
    space: SearchSpace,
    edge: float,
    tolerance: float | None = None,
    max_trials: int = 8,
    warm_start: tuple[float | None, float | None] | None = None,
    judge: Judge | None = None,
    rel_tolerance: float | None = None,
) -> SearchResult:
    """Search the failure boundary (see the module text).

    Args:
        evaluate: value -> ``(passed, info)``; one trial.
        space: search range, domain and scale.
        edge: the envelope's edge (its most severe value).
        tolerance: stop when ``|pass_value - fail_value| <= tolerance`` (the parameter's unit).
        max_trials: at most this many evaluations, the edge included.
        warm_start: a previous ``(pass_value, fail_value)`` tried first after the edge.
        judge: confirms verdicts of a noisy system (``None``: every verdict is final).
        rel_tolerance: stop when the bracket's width is at most this share of its larger end.
    """
    if tolerance is None and rel_tolerance is None:
        raise ValueError("boundary_search needs tolerance or rel_tolerance")
    search = _Search(evaluate, space, max_trials, judge)
    edge_passed = search.run(edge)
    flaky = False
    if judge is not None:
        edge_passed = search.confirm(search.trials[0])
        flaky = not judge.settled(search.trials[0].info)
    far = space.severe if edge_passed else space.mild

    for hint in warm_start or ():
        if hint is None or search.spent or hint == edge:
            continue
        if (edge_passed and space.worse(hint, edge)) or (not edge_passed and space.worse(edge, hint)):
            search.run(hint)

    passing, failing = search.bracket()
    unbracketed = (passing is None or failing is None) and not search.spent and all(t.value != far for t in search.trials)
    if unbracketed and search.run(far) == edge_passed and judge is not None:  # "never failed/passed" is a claim to confirm
        search.confirm(search.trials[-1])
    while True:
        passing, failing = search.bracket()
        if passing is None or failing is None:
            termination = "not_bracketed" if any(t.value == far for t in search.trials) else "max_trials"
            break
        termination = search.bisect(tolerance, rel_tolerance)
        if judge is None or not search.confirm_ends():
            break
        if search.spent:  # an end turned, and no budget is left to search the new bracket
            termination = "max_trials"
            break
    passing, failing = search.bracket()
    return SearchResult(search.trials[0].passed, passing, failing, termination, search.trials, _contradictions(search.trials, space), flaky)


class _Search:
    """The trials of one search and the bracket they give."""

    def __init__(self, evaluate: Callable[[float], tuple[bool, Any]], space: SearchSpace, max_trials: int, judge: Judge | None):
        self.evaluate = evaluate
        self.space = space
        self.max_trials = max_trials
        self.judge = judge
        self.trials: list[TrialPoint] = []

    @property
    def spent(self) -> bool:
        return len(self.trials) >= self.max_trials

    def run(self, value: float) -> bool:
        passed, info = self.evaluate(value)
        self.trials.append(TrialPoint(value, bool(passed), info))
        return bool(passed)

    def confirm(self, trial: TrialPoint) -> bool:
        """Let the judge confirm ``trial``; whether its verdict changed is seen in ``passed``."""
        assert self.judge is not None
        trial.passed = bool(self.judge.confirm(trial.info))
        return trial.passed

    def bracket(self) -> tuple[float | None, float | None]:
        """The most severe pass that is milder than every fail seen so far, and the mildest
        fail more severe than it, taking the trials in order (the edge first)."""
        passing: float | None = None
        failing: float | None = None
        worse = self.space.worse
        for t in self.trials:
            if t.passed and (passing is None or worse(t.value, passing)) and (failing is None or worse(failing, t.value)):
                passing = t.value
            if not t.passed and (failing is None or worse(failing, t.value)) and (passing is None or worse(t.value, passing)):
                failing = t.value
        return passing, failing

    def bisect(self, tolerance: float | None, rel_tolerance: float | None) -> str:
        """Halve the bracket until tolerance, domain resolution or the trial budget stops it."""
        while True:
            passing, failing = self.bracket()
            assert passing is not None and failing is not None
            width = abs(passing - failing)
            if (tolerance is not None and width <= tolerance) or (
                rel_tolerance is not None and width <= rel_tolerance * max(abs(passing), abs(failing))
            ):
                return "tolerance"
            if self.space.neighbours(passing, failing):
                return "domain_resolution"
            if self.spent:
                return "max_trials"
            mid = self.space.midpoint(passing, failing)
            if mid in (passing, failing):
                return "domain_resolution"
            self.run(mid)

    def confirm_ends(self) -> bool:
        """Confirm the trials at both ends of the bracket; ``True`` when a verdict turned."""
        turned = False
        for value in self.bracket():
            trial = next(t for t in reversed(self.trials) if t.value == value)
            before = trial.passed
            turned |= self.confirm(trial) != before
        return turned


def _contradictions(trials: list[TrialPoint], space: SearchSpace) -> list[str]:
    """Pairs where a more severe value passed while a milder one failed."""
    found = []
    passes = [t for t in trials if t.passed]
    fails = [t for t in trials if not t.passed]
    for p in passes:
        for f in fails:
            if space.worse(p.value, f.value):
                found.append(f"{p.value:g} passed but the milder {f.value:g} failed")
    return found
