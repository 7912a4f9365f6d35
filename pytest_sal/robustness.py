"""From a requirement to an ``Outcome``: the search range and tolerance, the boundary search
over trials, the verdict, the margin and the words a failed test shows."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pytest_sal.outcome import Boundary, Outcome, Trial
from pytest_sal.requirements import Requirement
from pytest_sal.search import SearchSpace, boundary_search
from pytest_sal.trials import TrialRunner
from sal_modules.refs import ParamRef

__all__ = ["SearchSettings", "failure_message", "search_outcome", "search_space", "single_outcome"]


@dataclass(frozen=True)
class SearchSettings:
    """Defaults a requirement may override (ini ``sal_tolerance``, ``sal_max_trials``,
    ``sal_noise``).

    Attributes:
        tolerance_pct: default tolerance, percent of the envelope's edge value.
        max_trials: default trial budget.
        noise: relative distance of a metric to its threshold within which the edge trial is
            run again to detect a flaky verdict (0.1: within 10 %).
    """

    tolerance_pct: float = 10.0
    max_trials: int = 8
    noise: float = 0.05


def search_space(ref: ParamRef, search_range: tuple[float, float] | None = None) -> SearchSpace:
    """Mild and severe ends of the parameter's search range (or of ``search_range``)."""
    scale = ref.param.search_space()
    lo, hi = (scale.min, scale.max) if search_range is None else sorted(search_range)
    mild, severe = (hi, lo) if ref.param.worse == "lower" else (lo, hi)
    return SearchSpace(mild=float(mild), severe=float(severe), domain=scale.domain)


def search_outcome(
    runner: TrialRunner,
    requirement: Requirement,
    settings: SearchSettings,
    test_id: str,
    warm_start: tuple[float | None, float | None] | None = None,
) -> Outcome:
    """Run the boundary search of ``requirement`` with ``runner`` and describe what it found."""
    envelope = requirement.envelope
    assert envelope is not None
    ref = envelope.ref
    space = search_space(ref, requirement.options.get("search_range"))
    edge = envelope.value
    tolerance = requirement.options.get("tolerance")
    if tolerance is None:
        tolerance = abs(edge) * settings.tolerance_pct / 100 or abs(space.mild - space.severe) * settings.tolerance_pct / 100
    if space.domain == "integer":
        tolerance = max(tolerance, 1.0)
    max_trials = requirement.options.get("max_trials", settings.max_trials)
    trials: list[Trial] = []

    def evaluate(value: float) -> tuple[bool, Trial]:
        # the edge evaluated again is the flakiness repeat: it must run, not read the first from the cache
        attempt = sum(t.value == value for t in trials) if value == edge else 0
        trial = runner.evaluate(value, attempt)
        trials.append(trial)
        return trial.passed, trial

    def near_threshold(trial: Trial) -> bool:
        return any(c.near(trial.metrics, settings.noise) for c in requirement.criteria)

    result = boundary_search(evaluate, space, edge, tolerance, max_trials, warm_start, recheck_edge=near_threshold)
    for point in result.trials:
        point.info.repeat = point.repeat
    verdict = "flaky" if result.flaky else "passed" if result.edge_passed else "failed"
    boundary = Boundary(result.pass_value, result.fail_value, ref.unit)
    return _outcome(runner, requirement, test_id, verdict, boundary, result.termination, trials, result.contradictions)


def single_outcome(runner: TrialRunner, requirement: Requirement, test_id: str, value: float) -> Outcome:
    """The outcome of one explicit point (``sal.sweep`` level or ``sal.at``)."""
    trial = runner.evaluate(value)
    boundary = Boundary(value if trial.passed else None, None if trial.passed else value, runner.ref.unit)
    return _outcome(runner, requirement, test_id, "passed" if trial.passed else "failed", boundary, "single", [trial], [])


def _outcome(
    runner: TrialRunner,
    requirement: Requirement,
    test_id: str,
    verdict: str,
    boundary: Boundary,
    termination: str,
    trials: list[Trial],
    contradictions: list[str],
) -> Outcome:
    ref = runner.ref
    edge = requirement.envelope.value if requirement.envelope is not None else None
    margin = None
    if edge is not None and boundary.pass_value is not None:
        margin = (edge - boundary.pass_value) if ref.param.worse == "lower" else (boundary.pass_value - edge)
    deciding = edge if edge is not None else trials[0].value
    reproduction = (
        f"@sal.at({ref.label}, {deciding:g})  # seed {runner.seed}, runs {runner.runs}, "
        f"system {runner.system.name}, dataset {runner.dataset.name}"
    )
    return Outcome(
        test_id=test_id,
        system=runner.system.name,
        dataset=runner.dataset.name,
        parameter=ref.label,
        worse=str(ref.param.worse),
        edge=edge,
        requirement=str(requirement),
        criteria=[(c.metric.name, c.op, c.threshold) for c in requirement.criteria],
        envelope=requirement.envelope.condition if requirement.envelope is not None else "",
        verdict=verdict,
        boundary=boundary,
        termination=termination,
        trials=trials,
        contradictions=contradictions,
        margin=margin,
        reproduction=reproduction,
        system_options=runner.system.options(),
        dataset_fingerprint=runner.dataset.fingerprint,
        seed=runner.seed,
    )


def _metrics_text(metrics: dict[str, Any]) -> str:
    shown = []
    for name in ("ate_rmse", "tracking_rate", "rpe_trans", "scale_error"):
        value = metrics.get(name)
        if value is not None:
            shown.append(f"{name} {value:.4g}")
    failures = metrics.get("failures") or []
    if failures:
        shown.append(f"run failed: {failures[0]}")
    return ", ".join(shown) or "no metrics (nothing tracked)"


def failure_message(outcome: Outcome) -> str:
    """What a failed (or flaky) robustness test says: the requirement, where it failed, the
    boundary, the metrics at both ends and a one-line reproduction."""
    unit = f" {outcome.boundary.unit}" if outcome.boundary.unit else ""
    first = outcome.trials[0]
    lines = []
    if outcome.verdict == "flaky":
        repeat = next((t for t in outcome.trials if t.repeat), None)
        lines.append(
            f"FLAKY: {outcome.requirement}: at the edge {outcome.parameter} = {first.value:g}{unit} one run "
            f"{'passed' if first.passed else 'failed'} and the repeat {'passed' if repeat and repeat.passed else 'failed'}; "
            f"the metric sits within noise of its threshold"
        )
    elif outcome.verdict == "passed":  # failed by a --sal-compare-fail check only
        lines.append(f"regressed against the history (the requirement is met): {outcome.requirement}")
        lines.append(f"  at {outcome.parameter} = {first.value:g}{unit}: {_metrics_text(first.metrics)}")
    else:
        lines.append(f"requirement not met: {outcome.requirement}")
        lines.append(f"  at {outcome.parameter} = {first.value:g}{unit}: {_metrics_text(first.metrics)}; failed: {', '.join(first.failed)}")
    lines.append(f"  boundary: {outcome.parameter} {outcome.boundary.text()} ({len(outcome.trials)} trials, {outcome.termination})")
    for label, value in (("pass end", outcome.boundary.pass_value), ("fail end", outcome.boundary.fail_value)):
        trial = next((t for t in outcome.trials if value is not None and t.value == value), None)
        if trial is not None:
            lines.append(f"  {label} {value:g}{unit}: {_metrics_text(trial.metrics)}")
    for text in outcome.contradictions:
        lines.append(f"  not monotonic: {text}")
    if outcome.regression:
        lines.append(f"  regression: {outcome.regression}")
    lines.append(f"  reproduce: {outcome.reproduction}")
    return "\n".join(lines)
