"""From a requirement to an ``Outcome``: a ``Search`` (what one robustness test searches) run
by ``run_search``, the one entry point of the plugin and of ``sal boundary``; the search range
and tolerance, the boundary search over trials (several at once where the executor has free
workers), the verdict, the margin and the words a failed test shows."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pytest_sal.analysis.kitti_segments import KITTI_SEGMENTS_M
from pytest_sal.engine.outcomes.outcome import Boundary, Outcome, Trial
from pytest_sal.engine.requirements import InvalidRequirement, Requirement, SearchSettings
from pytest_sal.engine.search.bisection import SearchResult, SearchSpace, boundary_search
from pytest_sal.engine.tolerance import search_tolerances
from sal_modules.params import ParamRef

if TYPE_CHECKING:  # the plugin reads SearchSettings at configure time, before any trial runs
    from pytest_sal.engine.execution.executor import Executor
    from pytest_sal.engine.execution.trial_runner import TrialRunner
    from pytest_sal.store.content_cache import ContentCache
    from sal_adapters import Sequence
    from sal_wrappers import SlamSystem

__all__ = [
    "Search",
    "SearchSettings",
    "deterministic_search",
    "failure_message",
    "run_search",
    "search_outcome",
    "search_space",
    "search_width",
    "single_outcome",
]


@dataclass(frozen=True)
class Search:
    """What one robustness test searches, as a value: built by the plugin (``SalSession``) and
    by ``sal boundary`` (``prepare_boundary_search``), run by ``run_search``.

    Attributes:
        dataset: the clean sequence; ``ref`` the searched parameter (values in its unit);
            ``system`` the SLAM system; ``requirement`` what each run is judged by.
        test_id: who asked (the pytest node id, ``sal boundary <experiment>/<name>``).
        settings: the defaults the requirement may override (tolerance, budgets, reliability).
        point: one value to try (``sal.sweep`` level, ``sal.at``); ``None``: search the envelope.
        runs, seed, timeout, workdir, artifacts, cache_frames, kitti_segments, early_stop: the
            trials' settings, as ``TrialRunner`` takes them.
        warm_start: the previous boundary, tried after the edge (``history.regression.warm_start``).
        earlier: a noisy system's trials of the same family run earlier (their runs count).
    """

    dataset: Sequence
    ref: ParamRef
    system: SlamSystem
    requirement: Requirement
    test_id: str
    settings: SearchSettings = field(default_factory=SearchSettings)
    point: float | None = None
    runs: int | None = None
    seed: int = 0
    timeout: float | None = 600.0
    workdir: Path = Path(".")
    artifacts: bool = False
    cache_frames: bool = False
    kitti_segments: tuple[float, ...] = KITTI_SEGMENTS_M
    early_stop: bool = True
    warm_start: tuple[float | None, float | None] | None = None
    earlier: tuple[Trial, ...] = ()


def run_search(
    search: Search, cache: ContentCache | None, executor: Executor | None = None, progress: Callable[[Trial], None] | None = None
) -> Outcome:
    """The outcome of ``search``: its boundary search, or its one ``point``, with runs read from
    and stored in ``cache`` (``None``: none) and run by ``executor`` (``None``: here, one at a
    time); ``progress`` is called with each trial as runs are added to it. The one place a
    ``TrialRunner`` is built outside the tests."""
    from pytest_sal.engine.execution.executor import LocalExecutor
    from pytest_sal.engine.execution.trial_runner import TrialRunner

    runner = TrialRunner(
        search.dataset,
        search.ref,
        search.system,
        search.requirement,
        runs=search.runs,
        seed=search.seed,
        cache=cache,
        workdir=search.workdir,
        timeout=search.timeout,
        artifacts=search.artifacts,
        cache_frames=search.cache_frames,
        progress=progress,
        kitti_segments=search.kitti_segments,
        executor=executor or LocalExecutor(),
        early_stop=search.early_stop,
    )
    earlier = list(search.earlier)
    if search.point is not None:
        return single_outcome(runner, search.requirement, search.test_id, search.point, search.settings, earlier)
    return search_outcome(runner, search.requirement, search.settings, search.test_id, search.warm_start, earlier)


def search_space(ref: ParamRef, search_range: tuple[float, float] | None = None) -> SearchSpace:
    """Mild and severe ends of the parameter's search range (or of ``search_range``)."""
    scale = ref.param.search_space()
    lo, hi = (scale.min, scale.max) if search_range is None else sorted(search_range)
    mild, severe = (hi, lo) if ref.param.worse == "lower" else (lo, hi)
    return SearchSpace(mild=float(mild), severe=float(severe), domain=scale.domain, scale=scale.scale)


def search_width(runner: TrialRunner) -> int:
    """How many trials (a deterministic system's: one run each) or runs (a noisy system's) a
    round of the search may hold now: the runs ``runner``'s executor can take at once; at least
    1 (``local``: always 1, the sequential search)."""
    return max(1, runner.executor.slots(runner.system))


def deterministic_search(
    runner: TrialRunner,
    requirement: Requirement,
    settings: SearchSettings,
    warm_start: tuple[float | None, float | None] | None = None,
) -> SearchResult[Trial]:
    """The boundary search of ``requirement`` with ``runner`` (a deterministic system: one run
    a trial, every verdict final): a round's trials are run in threads, as many as
    ``search_width`` allows; a trial left off the search path is marked ``Trial.speculative``."""
    envelope = requirement.envelope
    assert envelope is not None
    space = search_space(envelope.ref, requirement.options.get("search_range"))
    tolerance, rel_tolerance = search_tolerances(requirement.options, settings.tolerance_pct)
    max_trials = requirement.options.get("max_trials", settings.max_trials)
    _refuse_unchanged(runner, requirement)

    return boundary_search(
        runner.run_trial,
        space,
        envelope.value,
        tolerance,
        max_trials,
        warm_start,
        rel_tolerance=rel_tolerance,
        width=functools.partial(search_width, runner),
        cached=runner.cached,
    )


def _refuse_unchanged(runner: TrialRunner, requirement: Requirement) -> None:
    """``InvalidRequirement`` when the envelope's edge leaves the frames unchanged."""
    envelope = requirement.envelope
    assert envelope is not None
    unchanged = runner.unchanged_frames(envelope.value)
    if unchanged is not None:
        raise InvalidRequirement(
            f"{envelope}: the envelope's edge leaves the frames of {runner.dataset.name} unchanged (frames "
            f"{', '.join(map(str, unchanged))} differ from the clean ones by rounding only), so the test would pass whatever "
            f"the system does; bound a severity that perturbs this dataset"
        )


def search_outcome(
    runner: TrialRunner,
    requirement: Requirement,
    settings: SearchSettings,
    test_id: str,
    warm_start: tuple[float | None, float | None] | None = None,
    earlier: list[Trial] | None = None,
) -> Outcome:
    """Run the boundary search of ``requirement`` with ``runner`` (``run_search`` builds it; a
    test may give its own) and describe what it found (a noisy system's: the curve of its
    chance to hold, ``reliability_outcome``, which also counts the runs of ``earlier`` trials
    of the session)."""
    if runner.policy.noisy:
        return _noisy_outcome(runner, requirement, settings, test_id, requirement.envelope.value, earlier=earlier)  # type: ignore[union-attr]
    result = deterministic_search(runner, requirement, settings, warm_start)
    verdict = "passed" if result.edge_passed else "failed"
    boundary = Boundary(result.pass_value, result.fail_value, runner.ref.unit)
    trials = result.trials
    return _outcome(runner, requirement, test_id, verdict, boundary, result.termination, trials, result.contradictions)


def single_outcome(
    runner: TrialRunner,
    requirement: Requirement,
    test_id: str,
    value: float,
    settings: SearchSettings | None = None,
    earlier: list[Trial] | None = None,
) -> Outcome:
    """The outcome of one explicit point (``sal.sweep`` level or ``sal.at``): one run for a
    deterministic system; a noisy one's runs there until ``p >= reliability`` (or below it) is
    settled at ``confidence``, or ``max_runs`` are spent."""
    if runner.policy.noisy:
        return _noisy_outcome(runner, requirement, settings or SearchSettings(), test_id, value, single=True, earlier=earlier)
    trial = runner.run_trial(value)
    boundary = Boundary(value if trial.passed else None, None if trial.passed else value, runner.ref.unit)
    return _outcome(runner, requirement, test_id, "passed" if trial.passed else "failed", boundary, "single", [trial], [])


def _noisy_outcome(
    runner: TrialRunner,
    requirement: Requirement,
    settings: SearchSettings,
    test_id: str,
    edge: float,
    *,
    single: bool = False,
    earlier: list[Trial] | None = None,
) -> Outcome:
    """A noisy system's outcome at ``edge`` (``reliability_outcome``); a single point counts
    only the ``earlier`` runs at its own value."""
    from pytest_sal.engine.search.reliability_outcome import reliability_outcome

    if not single:
        _refuse_unchanged(runner, requirement)
    space = search_space(runner.ref, requirement.options.get("search_range") if requirement.envelope is not None else None)
    result, trials, boundary = reliability_outcome(
        runner,
        requirement,
        settings,
        space,
        edge,
        functools.partial(search_width, runner),
        single=single,
        earlier=[t for t in earlier or () if not single or t.value == edge],
    )
    termination = "single" if single else result.termination
    if single:  # the point passed or failed: the one-sided forms of a sweep level's cell
        boundary.pass_value, boundary.fail_value = (edge, None) if result.verdict == "passed" else (None, edge)
    return _outcome(runner, requirement, test_id, result.verdict, boundary, termination, trials, [])


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
        f"@sal.at({ref.label}, {deciding:g})  # {ref.unit or 'no unit'}; seed {runner.seed}, up to {runner.policy.max_runs} run(s), "
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
        criteria=requirement.criteria_rows(),
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


def _stopped_text(trial: Trial) -> str:
    """``; stopped early: <why>`` when runs of ``trial`` were stopped early (their metrics cover
    only the frames they ran), else nothing."""
    stopped = [run["stopped"] for run in trial.runs if run.get("stopped")]
    return f"; {len(stopped)} of {len(trial.runs)} run(s) stopped early: {stopped[0]}" if stopped else ""


def _metrics_text(metrics: dict[str, Any], judged: tuple[str, ...] = ()) -> str:
    """The trial's main metrics and those ``judged`` by a criterion; a judged KITTI metric
    that is missing says why (the sequence is shorter than the shortest segment...)."""
    shown = []
    for name in dict.fromkeys(("ate_rmse", "tracking_rate", "rpe_trans", "scale_error", *judged)):
        value = metrics.get(name)
        if value is not None:
            shown.append(f"{name} {value:.4g}")
        elif name in ("t_rel", "r_rel") and metrics.get("kitti_missing"):
            shown.append(f"{name} missing: {metrics['kitti_missing']}")
    failures = metrics.get("failures") or []
    if failures:
        shown.append(f"run failed: {failures[0]}")
    return ", ".join(shown) or "no metrics (nothing tracked)"


def failure_message(outcome: Outcome) -> str:
    """What a failed (or inconclusive) robustness test says: the requirement, where it failed,
    the boundary, the metrics at both ends (a noisy system's: how sure the verdict is and why
    runs failed at each severity) and a one-line reproduction. An outcome read from history
    written before may be ``flaky`` (a vote of runs that disagreed at the edge)."""
    if outcome.boundary.noisy:
        from pytest_sal.engine.search.reliability_outcome import reliability_message

        lines = reliability_message(outcome)
        if outcome.regression:
            lines.append(f"  regression: {outcome.regression}")
        lines.append(f"  reproduce: {outcome.reproduction}")
        return "\n".join(lines)
    unit = f" {outcome.boundary.unit}" if outcome.boundary.unit else ""
    first = outcome.trials[0]
    judged = tuple(name for name, _, _ in outcome.criteria)
    lines = []
    if outcome.verdict == "flaky":  # history written before: a vote of runs at the edge that disagreed
        lines.append(f"FLAKY: {outcome.requirement}: at {outcome.parameter} = {first.value:g}{unit} the runs disagreed ({first.votes()})")
    elif outcome.verdict == "passed":  # failed by a --sal-compare-fail check only
        lines.append(f"regressed against the history (the requirement is met): {outcome.requirement}")
        lines.append(f"  at {outcome.parameter} = {first.value:g}{unit}: {_metrics_text(first.metrics, judged)}{_stopped_text(first)}")
    else:
        lines.append(f"requirement not met: {outcome.requirement}")
        lines.append(
            f"  at {outcome.parameter} = {first.value:g}{unit}: {_metrics_text(first.metrics, judged)}; failed: {', '.join(first.failed)}"
            f"{_stopped_text(first)}"
        )
    speculative = sum(t.speculative for t in outcome.trials)
    trials = f"{len(outcome.trials)} trials" + (f" ({speculative} speculative)" if speculative else "")
    lines.append(
        f"  boundary: {outcome.parameter} {outcome.boundary.text()} ({trials}, {outcome.runs} runs, {outcome.termination}); "
        f"{outcome.confidence()}"
    )
    for label, trial in zip(("pass end", "fail end"), outcome.end_trials()):
        if trial is not None:
            lines.append(f"  {label} {trial.value:g}{unit}: {_metrics_text(trial.metrics, judged)} ({trial.votes()}){_stopped_text(trial)}")
    for text in outcome.contradictions:
        lines.append(f"  not monotonic: {text}")
    if outcome.regression:
        lines.append(f"  regression: {outcome.regression}")
    lines.append(f"  reproduce: {outcome.reproduction}")
    return "\n".join(lines)
