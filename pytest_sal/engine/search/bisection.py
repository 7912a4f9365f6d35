"""Boundary search: where between the envelope's edge and the far end of the search range the
system stops meeting its requirement. Pure: it knows values and verdicts, not SLAM: ``run_trial``
gives a ``Verdict`` (the engine's ``Trial``), and the search returns those it was given.

Severity runs from ``mild`` to ``severe`` (for fog, from long to short visibility). The
search tries the envelope's ``edge`` first: that trial decides the test. If it passes, the
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

Every verdict is final: the search is for deterministic systems (one run per trial). A noisy
system's boundary is a curve of its chance to hold (``pytest_sal.engine.search.reliability_search``).

A previous boundary ``warm_start`` is tried right after the edge: when it still brackets within
tolerance, an unchanged system needs three trials. Every trial is checked against the order: a
pass more severe than a fail contradicts monotonicity and is reported.

Free workers. ``width`` says before each round how many trials a round may hold now (free
workers over the runs a trial needs). A round tries several values at once, each
in its own thread (``run_trial`` must then be safe to call from several threads for distinct
values). The edge goes alone; the warm-start hints go together; then the far end. Bisection
speculates: with ``k`` trials free it tries the first ``k`` nodes, breadth-first, of the
bisection tree below the bracket (``k = 3``: the midpoint and both quarter points, the 4-ary
search; ``k = 7``: the 8-ary search). A node exists only where the sequential search would
try it on reaching its bracket (the same tolerance, domain and budget rules, its depth
counted against ``max_trials``). A partial last level takes its nodes in bit-reversed order
(each node's path of verdicts from the root read backwards), so they spread evenly over the
bracket, starting on the side the path's last verdict leads to if it repeats: a boundary near
an end of the bracket gives runs of equal verdicts (0..1000 to 0.5 at ``k = 2``: 6.8 bisection
rounds against 8.0 for a fixed side with boundaries log-uniformly 0.1-316 from an end, 7.6 for
both with uniform ones). After a pass, ``k = 2`` is the midpoint and the quarter point on the
fail side, and ``k = 5`` adds an eighth point in each half. The round then walks the tree along
the verdicts: the trials on that walk are the search path, appended in its order and counted by
``max_trials``; the others are appended after them, ``speculative``, extra to the budget.
A step whose midpoint is ``cached`` (it costs no run) goes alone: a search cached along its
path, as in a second session, walks it without speculating and sends nothing.

Why the interval is the sequential one: a node lies strictly inside its bracket, and its two
children bisect the halves the sequential search would hold after its pass or fail (a verdict
strictly inside the bracket moves the matching end, whatever came before), so the walk
tries what the sequential search would, in its order. Each node off the walk lies in a half
the walk turned away from, outside the bracket the walk ends in, and a trial outside the bracket
moves neither end (``_Search.bracket`` takes only a pass or a fail strictly between them): for
any deterministic system, a monotone one included, off-path trials never move the bracket, and
interval, termination and verdict are those of the sequential search. They add to
``contradictions`` only where the system is not monotone.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Generic, Literal, Protocol, TypeVar

__all__ = ["TERMINATIONS", "SearchResult", "SearchSpace", "Verdict", "boundary_search"]

#: Why a search stopped.
TERMINATIONS = ("tolerance", "max_trials", "not_bracketed", "domain_resolution")

_Item = TypeVar("_Item")
_Done = TypeVar("_Done")


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


class Verdict(Protocol):
    """What ``run_trial`` gives for a value: the ``value`` and whether it ``passed``; the search
    sets ``speculative`` on those it tried in a round beside its path and left off it."""

    value: float
    passed: bool
    speculative: bool


#: the verdicts a search is given and returns
V = TypeVar("V", bound=Verdict)


@dataclass
class SearchResult(Generic[V]):
    """What the search found.

    Attributes:
        edge_passed: the verdict at the envelope's edge (the test's verdict).
        pass_value, fail_value: the bracket: the most severe value seen to pass next to the
            mildest value seen to fail (either may be ``None`` when not bracketed).
        termination: one of ``TERMINATIONS``.
        trials: every trial: each round's path trials in order, then its speculative ones.
        contradictions: trials that contradict monotonicity, in words.
        rounds: rounds of trials (one at a time: as many as trials).
    """

    edge_passed: bool
    pass_value: float | None
    fail_value: float | None
    termination: str
    trials: list[V] = field(default_factory=list)
    contradictions: list[str] = field(default_factory=list)
    rounds: int = 0

    @property
    def speculative(self) -> int:
        """Trials tried beside the search path and left off it (extra to ``max_trials``)."""
        return sum(t.speculative for t in self.trials)


def boundary_search(
    run_trial: Callable[[float], V],
    space: SearchSpace,
    edge: float,
    tolerance: float | None = None,
    max_trials: int = 8,
    warm_start: tuple[float | None, float | None] | None = None,
    rel_tolerance: float | None = None,
    width: Callable[[], int] | None = None,
    cached: Callable[[float], bool] | None = None,
) -> SearchResult[V]:
    """Search the failure boundary (see the module text).

    Args:
        run_trial: value -> its ``Verdict``; runs the trial at the value.
        space: search range, domain and scale.
        edge: the envelope's edge (its most severe value).
        tolerance: stop when ``|pass_value - fail_value| <= tolerance`` (the parameter's unit).
        max_trials: at most this many trials on the search path, the edge included.
        warm_start: a previous ``(pass_value, fail_value)`` tried first after the edge.
        rel_tolerance: stop when the bracket's width is at most this share of its larger end.
        width: how many trials a round may hold now, asked before each round (``None``: 1,
            the sequential search); above 1, ``run_trial`` is called from several threads at
            once, for distinct values.
        cached: whether a trial at a value would be read back from a cache (it costs no run):
            a bisection step whose midpoint is cached goes alone, without speculative trials
            beside it, so a search that is cached along its path sends no new run.
    """
    if tolerance is None and rel_tolerance is None:
        raise ValueError("boundary_search needs tolerance or rel_tolerance")
    search = _Search(run_trial, space, max_trials, width or (lambda: 1), tolerance, rel_tolerance, cached or (lambda value: False))
    (first,) = search.run([edge])
    edge_passed = first.passed
    far = space.severe if edge_passed else space.mild

    beyond = [h for h in warm_start or () if h is not None and h != edge and space.worse(h, edge) == edge_passed]
    search.run(beyond[: max(0, max_trials - search.path_trials)])

    passing, failing = search.bracket()
    unbracketed = (passing is None or failing is None) and not search.spent and all(t.value != far for t in search.trials)
    if unbracketed:
        search.run([far])
    passing, failing = search.bracket()
    if passing is None or failing is None:
        termination = "not_bracketed" if any(t.value == far for t in search.trials) else "max_trials"
    else:
        termination = search.bisect()
    passing, failing = search.bracket()
    return SearchResult(first.passed, passing, failing, termination, search.trials, _contradictions(search.trials, space), search.rounds)


@dataclass(frozen=True)
class _Node:
    """A bracket the bisection tree reaches and the value that bisects it; ``path``: the verdicts
    that lead to it from the round's root (1: a pass, which keeps the fail-side half)."""

    passing: float
    failing: float
    path: tuple[int, ...]
    value: float

    def children(self, space: SearchSpace) -> tuple[_Node, _Node]:
        """The halves after a fail and after a pass at ``value``."""
        return (
            _Node(self.passing, self.value, (*self.path, 0), space.midpoint(self.passing, self.value)),
            _Node(self.value, self.failing, (*self.path, 1), space.midpoint(self.value, self.failing)),
        )


class _Search(Generic[V]):
    """The trials of one search, the bracket they give and the rounds that tried them."""

    def __init__(
        self,
        run_trial: Callable[[float], V],
        space: SearchSpace,
        max_trials: int,
        width: Callable[[], int],
        tolerance: float | None,
        rel_tolerance: float | None,
        cached: Callable[[float], bool],
    ):
        self.run_trial = run_trial
        self.space = space
        self.max_trials = max_trials
        self.width = width
        self.tolerance = tolerance
        self.rel_tolerance = rel_tolerance
        self.cached = cached
        self.trials: list[V] = []
        self.rounds = 0

    @property
    def path_trials(self) -> int:
        return sum(not t.speculative for t in self.trials)

    @property
    def spent(self) -> bool:
        return self.path_trials >= self.max_trials

    def run(self, values: list[float]) -> list[V]:
        """Evaluate ``values`` on the search path, ``width()`` of them a round."""
        points = self._in_rounds(self.run_trial, values)
        self.trials += points
        return points

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

    def bisect(self) -> str:
        """Halve the bracket, a round of the bisection tree at a time, until tolerance, domain
        resolution or the trial budget stops it; why it stopped."""
        while True:
            passing, failing = self.bracket()
            assert passing is not None and failing is not None
            if (stop := self._stop(passing, failing)) is not None:
                return stop
            size = 1 if self.cached(self.space.midpoint(passing, failing)) else max(1, self.width())
            nodes = self._tree(passing, failing, size)
            reached = dict(zip((node.path for node in nodes), self._round(self.run_trial, [node.value for node in nodes])))
            path: tuple[int, ...] = ()
            while (point := reached.pop(path, None)) is not None:
                self.trials.append(point)
                path = (*path, int(point.passed))
            for point in reached.values():
                point.speculative = True
                self.trials.append(point)

    def _stop(self, passing: float, failing: float, ahead: int = 0) -> str | None:
        """Why the sequential search would stop at this bracket, ``ahead`` path trials from now
        (``None``: it would try the midpoint)."""
        width = abs(passing - failing)
        if (self.tolerance is not None and width <= self.tolerance) or (
            self.rel_tolerance is not None and width <= self.rel_tolerance * max(abs(passing), abs(failing))
        ):
            return "tolerance"
        if self.space.neighbours(passing, failing):
            return "domain_resolution"
        if self.path_trials + ahead >= self.max_trials:
            return "max_trials"
        if not min(passing, failing) < self.space.midpoint(passing, failing) < max(passing, failing):
            return "domain_resolution"  # a float resolution's end (or a geometric mean that underflowed)
        return None

    def _tree(self, passing: float, failing: float, size: int) -> list[_Node]:
        """The first ``size`` nodes, breadth-first, of the bisection tree below the bracket: the
        brackets the sequential search would bisect next, a partial last level taken in
        bit-reversed order (sorted by the path read backwards: spread evenly), starting on the
        side the path's last verdict leads to (a pass: the fail-side half)."""
        lean = int(next(t.passed for t in reversed(self.trials) if not t.speculative))
        chosen: list[_Node] = []
        level = [_Node(passing, failing, (), self.space.midpoint(passing, failing))]
        while level and len(chosen) < size:
            found = [n for n in level if self._stop(n.passing, n.failing, ahead=len(n.path)) is None]
            found.sort(key=lambda n: [bit ^ lean for bit in reversed(n.path)])
            found = found[: size - len(chosen)]
            chosen += found
            level = [child for node in found for child in node.children(self.space)]
        return chosen

    def _in_rounds(self, work: Callable[[_Item], _Done], items: Sequence[_Item]) -> list[_Done]:
        """``work`` on each item, ``width()`` items a round."""
        done: list[_Done] = []
        while len(done) < len(items):
            done += self._round(work, items[len(done) : len(done) + max(1, self.width())])
        return done

    def _round(self, work: Callable[[_Item], _Done], items: Sequence[_Item]) -> list[_Done]:
        """One round: ``work`` on every item at once, each in its own thread (in this one for a single item)."""
        self.rounds += 1
        if len(items) == 1:
            return [work(items[0])]
        with ThreadPoolExecutor(max_workers=len(items), thread_name_prefix="sal-search") as pool:
            return list(pool.map(work, items))


def _contradictions(trials: list[V], space: SearchSpace) -> list[str]:
    """Pairs where a more severe value passed while a milder one failed."""
    found = []
    passes = [t for t in trials if t.passed]
    fails = [t for t in trials if not t.passed]
    for p in passes:
        for f in fails:
            if space.worse(p.value, f.value):
                found.append(f"{p.value:g} passed but the milder {f.value:g} failed")
    return found
