"""Boundary search: where between the envelope's edge and the far end of the search range the
system stops meeting its requirement. Pure: it knows values and verdicts, not SLAM.

Severity runs from ``mild`` to ``severe`` (for fog, from long to short visibility). The
search evaluates the envelope's ``edge`` first: that trial decides the test. If it passes, the
failure boundary lies on the severe side and the search bisects between the edge and the
severe end; if it fails, the boundary lies on the mild side and it bisects between the edge and
the mild end. The interval ``(pass_value, fail_value)`` shrinks until it is within
``tolerance`` (in search units), ``max_trials`` is spent, or (integer domain) the two values are
neighbours. When the far end gives the same verdict as the edge, the boundary is not bracketed.

Bisection is geometric (``sqrt(a b)``) when both ends are positive and a decade or more apart
(visibility 1..100000 m), arithmetic otherwise. A previous boundary ``warm_start`` is tried
right after the edge: when it still brackets within tolerance, an unchanged system needs three
trials. Every trial is checked against the order: a pass more severe than a fail contradicts
monotonicity and is reported.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

__all__ = ["SearchResult", "SearchSpace", "TrialPoint", "boundary_search", "TERMINATIONS"]

#: Why a search stopped.
TERMINATIONS = ("tolerance", "max_trials", "not_bracketed", "domain_resolution")


@dataclass(frozen=True)
class SearchSpace:
    """The values a search may try, in search units.

    Attributes:
        mild, severe: the ends of the search range (the mildest and the most severe value).
        domain: ``continuous`` or ``integer``.
    """

    mild: float
    severe: float
    domain: Literal["continuous", "integer"] = "continuous"

    def worse(self, a: float, b: float) -> bool:
        """``a`` is more severe than ``b``."""
        return a < b if self.severe < self.mild else a > b

    def midpoint(self, a: float, b: float) -> float:
        """Geometric mean when both are positive and a decade or more apart, else the mean;
        rounded to an integer strictly between them in the integer domain (when one exists)."""
        lo, hi = min(a, b), max(a, b)
        mid = math.sqrt(lo * hi) if lo > 0 and hi / lo >= 10 else (lo + hi) / 2
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
    repeat: bool = False


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
        flaky: the repeated edge trial disagreed with the first.
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
    tolerance: float,
    max_trials: int = 8,
    warm_start: tuple[float | None, float | None] | None = None,
    recheck_edge: Callable[[Any], bool] | None = None,
) -> SearchResult:
    """Search the failure boundary (see the module text).

    Args:
        evaluate: value -> ``(passed, info)``; one trial.
        space: search range and domain.
        edge: the envelope's edge (its most severe value).
        tolerance: stop when ``|pass_value - fail_value| <= tolerance`` (search units).
        max_trials: at most this many evaluations, the edge (and its repeat) included.
        warm_start: a previous ``(pass_value, fail_value)`` tried first after the edge.
        recheck_edge: given the edge trial's ``info``, whether it sits within noise of the
            threshold: then the edge is run once more, and disagreement makes the result flaky.
    """
    trials: list[TrialPoint] = []

    def run(value: float, repeat: bool = False) -> bool:
        passed, info = evaluate(value)
        trials.append(TrialPoint(value, bool(passed), info, repeat))
        return bool(passed)

    edge_passed = run(edge)
    flaky = False
    if recheck_edge is not None and recheck_edge(trials[-1].info) and len(trials) < max_trials:
        flaky = run(edge, repeat=True) != edge_passed
    passing = edge if edge_passed else None
    failing = None if edge_passed else edge
    far = space.severe if edge_passed else space.mild

    def bracket(value: float, passed: bool) -> None:
        nonlocal passing, failing
        if passed and (passing is None or space.worse(value, passing)) and (failing is None or space.worse(failing, value)):
            passing = value
        if not passed and (failing is None or space.worse(failing, value)) and (passing is None or space.worse(value, passing)):
            failing = value

    for hint in warm_start or ():
        if hint is None or len(trials) >= max_trials or hint == edge:
            continue
        if (edge_passed and space.worse(hint, edge)) or (not edge_passed and space.worse(edge, hint)):
            bracket(hint, run(hint))

    if (passing is None or failing is None) and len(trials) < max_trials and all(t.value != far for t in trials):
        bracket(far, run(far))
    if passing is None or failing is None:
        termination = "not_bracketed" if any(t.value == far for t in trials) else "max_trials"
    else:
        termination = _bisect(run, bracket, space, tolerance, max_trials, trials, lambda: (passing, failing))
    return SearchResult(edge_passed, passing, failing, termination, trials, _contradictions(trials, space), flaky)


def _bisect(
    run: Callable[[float], bool],
    bracket: Callable[[float, bool], None],
    space: SearchSpace,
    tolerance: float,
    max_trials: int,
    trials: list[TrialPoint],
    current: Callable[[], tuple[float, float]],
) -> str:
    """Halve the bracket until tolerance, domain resolution or the trial budget stops it."""
    while True:
        passing, failing = current()
        if abs(passing - failing) <= tolerance:
            return "tolerance"
        if space.neighbours(passing, failing):
            return "domain_resolution"
        if len(trials) >= max_trials:
            return "max_trials"
        mid = space.midpoint(passing, failing)
        if mid in (passing, failing):
            return "domain_resolution"
        bracket(mid, run(mid))


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
