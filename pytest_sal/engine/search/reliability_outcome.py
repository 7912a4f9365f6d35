"""A noisy system's requirement -> ``Outcome``: runs placed by ``reliability_search`` through
the ``TrialRunner`` (one ``Trial`` per severity, holding every run there), the fitted curve
written into the ``Boundary`` (``s_R``, its bound and interval, ``s50``, the transition, the
curve and its band), the verdict ``passed`` / ``failed`` / ``inconclusive``, and the words of a
test that did not pass: how sure the verdict is, about how many more runs would settle it,
and why the runs failed at each severity (``Trial.failure_summary``).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING

import numpy as np

from pytest_sal.engine.outcomes.outcome import Boundary, Outcome, Trial
from pytest_sal.engine.outcomes.quantity import with_unit
from pytest_sal.engine.search.bisection import SearchSpace
from pytest_sal.engine.search.reliability_curve import SeverityAxis
from pytest_sal.engine.search.reliability_search import Observation, ReliabilityResult, more_runs_needed, reliability_search
from pytest_sal.engine.tolerance import search_tolerances

if TYPE_CHECKING:
    from pytest_sal.engine.execution.trial_runner import TrialRunner
    from pytest_sal.engine.requirements import Requirement, SearchSettings

__all__ = ["Targets", "axis_of", "reliability_message", "reliability_outcome", "run_observations"]

#: points of the fitted curve kept for plots (evenly on the severity axis)
_CURVE_POINTS = 41


class Targets:
    """What a noisy requirement must show: ``reliability``, ``confidence`` and the run budget
    ``max_runs`` (the requirement's options, else the session's ``SearchSettings``)."""

    def __init__(self, requirement: Requirement, settings: SearchSettings):
        options = requirement.options
        self.reliability = float(options.get("reliability", settings.reliability))
        self.confidence = float(options.get("confidence", settings.confidence))
        self.max_runs = int(options.get("max_runs", settings.max_runs))
        self.tolerance, self.rel_tolerance = search_tolerances(options, settings.tolerance_pct)


def axis_of(space: SearchSpace, edge: float, targets: Targets) -> SeverityAxis:
    """The severity axis of a search range: log where the bisection is geometric (a ``log``
    parameter, or both ends positive and a decade or more apart), with a grid fine enough for
    the tolerance (taken at the edge for an absolute one)."""
    lo, hi = sorted((space.mild, space.severe))
    log = lo > 0 and (space.scale == "log" or hi / lo >= 10)
    if log:
        span = math.log(hi / lo)
        step = (
            math.log1p(targets.tolerance / max(abs(edge), lo))
            if targets.tolerance is not None
            else math.log1p(targets.rel_tolerance or 0.1)
        )
        tolerance_x = step / span
    else:
        tolerance_x = (
            targets.tolerance if targets.tolerance is not None else (targets.rel_tolerance or 0.1) * max(abs(lo), abs(hi)) / 2
        ) / (hi - lo)
    return SeverityAxis.for_range(space.mild, space.severe, log, tolerance_x, integer=space.domain == "integer")


def run_observations(trials: list[Trial]) -> list[Observation]:
    """Every run of ``trials`` as an ``Observation`` (an abstained run holds ``None``)."""
    return [Observation(t.value, None if r.get("abstained") else bool(r.get("passed"))) for t in trials for r in t.runs]


def reliability_outcome(
    runner: TrialRunner,
    requirement: Requirement,
    settings: SearchSettings,
    space: SearchSpace,
    edge: float,
    width: Callable[[], int],
    *,
    single: bool = False,
    earlier: list[Trial] | None = None,
) -> tuple[ReliabilityResult, list[Trial], Boundary]:
    """Search ``requirement`` (a noisy system) from ``edge``: the result, the trials (one per
    severity, the edge's first) and the statistical ``Boundary``. ``single``: every run at
    ``edge`` (a ``sal.sweep`` level or ``sal.at`` point), until the verdict settles.
    ``earlier``: trials of the same system, dataset, parameter and seed run earlier in the
    session (other requirements', sweep levels'): their runs are judged by this requirement and
    counted in the fit, free; new runs at their values are numbered on from them."""
    targets = Targets(requirement, settings)
    axis = axis_of(space, edge, targets)
    trials: dict[float, Trial] = {}
    for before in earlier or ():
        trials[before.value] = _judged(before, requirement)
    known = run_observations(list(trials.values()))

    def run_at(value: float, count: int) -> list[bool | None]:
        trial = trials.setdefault(value, Trial(value=value, passed=False))
        return [None if r.get("abstained") else bool(r["passed"]) for r in runner.add_runs(trial, count)]

    def run(values: list[float]) -> list[bool | None]:
        counts = Counter(values)
        for value in counts:  # trials are made here, in this thread, in the order runs asked for them
            trials.setdefault(value, Trial(value=value, passed=False))
        if len(counts) == 1:
            held = {value: run_at(value, count) for value, count in counts.items()}
        else:
            with ThreadPoolExecutor(max_workers=len(counts), thread_name_prefix="sal-search") as pool:
                held = dict(zip(counts, pool.map(run_at, counts, counts.values())))
        return [held[value].pop(0) for value in values]

    def cached(value: float) -> bool:
        return runner.run_cached(value, len(trials[value].runs) if value in trials else 0)

    result = reliability_search(
        run,
        axis,
        edge,
        targets.reliability,
        targets.confidence,
        targets.max_runs,
        tolerance=targets.tolerance,
        rel_tolerance=targets.rel_tolerance,
        width=width,
        cached=cached,
        at_edge_only=single,
        earlier=known,
    )
    ordered = sorted(trials.values(), key=lambda t: t.value != edge)  # the edge's trial first, then in the order they were made
    return result, ordered, _boundary(result, axis, targets, runner.ref.unit, space)


def _judged(trial: Trial, requirement: Requirement) -> Trial:
    """A copy of ``trial`` whose runs are judged by ``requirement`` (a run that failed after the
    machine starved it abstains), with its verdict (the majority) and failed criteria."""
    runs = tuple(run.judged(requirement.holds(run.metrics), cached=True) for run in trial.runs)
    copy = Trial(value=trial.value, passed=False, metrics=trial.metrics, runs=runs, cached=True, artifacts=dict(trial.artifacts))
    copy.passed = copy.passes > copy.fails
    copy.failed = [str(c) for c in requirement.failed(copy.metrics)]
    return copy


def _boundary(result: ReliabilityResult, axis: SeverityAxis, targets: Targets, unit: str, space: SearchSpace) -> Boundary:
    """The statistical boundary of ``result`` in the parameter's unit, clamped to the range."""
    fit, confidence = result.fit, targets.confidence

    def value(x: float) -> float:
        return float(axis.to_value(min(max(x, 0.0), 1.0)))

    s_r, s50 = result.s_r, result.s50
    severe_bound = fit.s_r(targets.reliability, 2 * confidence - 1).high  # the C quantile: s_R is milder with confidence C
    band = fit.band(np.linspace(0.0, 1.0, _CURVE_POINTS), confidence)
    start, end = fit.transition()
    return Boundary(
        pass_value=value(s_r.bound) if s_r.bound > 0 else None,
        fail_value=value(severe_bound) if severe_bound < 1 else None,
        unit=unit,
        estimate=value(s_r.estimate),
        bound=value(s_r.bound),
        interval=[value(s_r.low), value(s_r.high)],
        reliability=targets.reliability,
        confidence=confidence,
        runs=fit.runs,
        s50=value(s50.estimate),
        s50_interval=[value(s50.low), value(s50.high)],
        transition=[value(start), value(end)],
        holds_at_edge=round(result.holds_at_edge, 6),
        curve=[[float(axis.to_value(x)), round(m, 5), round(lo, 5), round(hi, 5)] for x, m, lo, hi in band],
        search_range=[float(space.mild), float(space.severe)],
        log_scale=axis.log,
        grid_step=axis.step,
    )


def reliability_message(outcome: Outcome) -> list[str]:
    """The lines a noisy system's test that did not pass shows: the verdict with its
    confidence, the boundary, and per severity the runs that held and why the others failed."""
    b = outcome.boundary
    assert b.reliability is not None and b.confidence is not None
    unit = b.unit
    edge = with_unit(outcome.edge if outcome.edge is not None else outcome.trials[0].value, unit)
    holds = b.holds_at_edge if b.holds_at_edge is not None else float("nan")
    share = f"{100 * b.reliability:.4g} %"
    sure = f"{100 * b.confidence:.4g} %"
    lines = []
    if outcome.verdict == "inconclusive":
        more = more_runs_needed(b.runs or 0, holds, b.confidence)
        settle = (
            f"about {more} more runs would settle it (max_runs={(b.runs or 0) + more})"
            if more is not None
            else "p at the edge sits on the required reliability, so more runs may not settle it"
        )
        lines.append(
            f"INCONCLUSIVE: {outcome.requirement}: after {b.runs} run{'s' if b.runs != 1 else ''}, the chance that a run holds it at {outcome.parameter} = {edge} "
            f"is at least {share} with confidence {100 * holds:.3g} %, not {sure}, nor below it with that confidence; {settle}"
        )
    elif outcome.verdict == "failed":
        lines.append(
            f"requirement not met: {outcome.requirement}: at {outcome.parameter} = {edge} fewer than {share} of runs hold it "
            f"(confidence {100 * (1 - holds):.3g} % >= {sure}; {b.runs} runs)"
        )
    else:  # failed by a --sal-compare-fail check only
        lines.append(f"regressed against the history (the requirement is met): {outcome.requirement}")
    lines.append(f"  boundary: {outcome.parameter} {b.text()} ({b.runs} runs at {len(outcome.trials)} values, {outcome.termination})")
    for trial in sorted(outcome.trials, key=lambda t: t.value):
        lines.append(f"  at {with_unit(trial.value, unit)}: {trial.failure_summary()}")
    return lines
