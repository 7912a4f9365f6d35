"""The boundary search over free workers (speculative bisection): for a deterministic system
the same interval, termination and verdict as the sequential search, in fewer rounds."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_sal import tracking_rate
from pytest_sal.engine.execution.trial_runner import TrialRunner
from pytest_sal.engine.outcomes.outcome import Outcome, Trial
from pytest_sal.engine.requirements import Requirement
from pytest_sal.engine.search.bisection import SearchResult, SearchSpace, _Search, boundary_search
from pytest_sal.engine.search.requirement_search import SearchSettings, deterministic_search, search_outcome, search_width
from pytest_sal.report.formatting import trial_line
from pytest_sal.testing import FakeSlam, InProcessSlots
from sal_adapters import open_dataset
from sal_modules import fog

WIDTHS = (1, 2, 3, 4, 7)
DOMAINS: tuple[Literal["continuous", "integer"], ...] = ("continuous", "integer")
SCALES: tuple[Literal["linear", "log"], ...] = ("linear", "log")


@dataclass(frozen=True)
class Case:
    """One search problem: a monotone threshold system and the search's settings."""

    space: SearchSpace
    boundary: float
    edge: float
    tolerance: float | None
    rel_tolerance: float | None
    max_trials: int
    warm_start: tuple[float | None, float | None] | None

    def evaluate(self, value: float) -> Trial:
        """Passes exactly on the mild side of ``boundary`` (the boundary itself passes)."""
        return Trial(value, not self.space.worse(value, self.boundary))

    def search(self, width: Callable[[], int] | None = None) -> SearchResult[Trial]:
        return boundary_search(
            self.evaluate,
            self.space,
            self.edge,
            self.tolerance,
            self.max_trials,
            self.warm_start,
            rel_tolerance=self.rel_tolerance,
            width=width,
        )


@st.composite
def cases(draw: st.DrawFn) -> Case:
    """Linear, log and integer domains, either direction of severity, absolute and relative tolerances."""
    domain = draw(st.sampled_from(DOMAINS))
    scale = draw(st.sampled_from(SCALES))
    lo = draw(st.sampled_from([0.01, 0.5, 1.0, 3.0] if scale == "log" else [-50.0, 0.0, 1.0, 25.0]))
    hi = lo * draw(st.sampled_from([10.0, 1e3, 1e5])) if scale == "log" else lo + draw(st.sampled_from([7.0, 100.0, 1e4]))
    if domain == "integer":
        lo, hi = float(math.floor(lo)), float(math.ceil(hi))
    mild, severe = (hi, lo) if draw(st.booleans()) else (lo, hi)
    at = st.floats(min_value=lo, max_value=hi, allow_nan=False)
    edge = draw(at)
    edge = float(round(edge)) if domain == "integer" else edge
    absolute = draw(st.booleans())
    tolerance = draw(st.sampled_from([0.0, 0.5, 2.0, 0.01 * (hi - lo)])) if absolute else None
    rel_tolerance = None if absolute else draw(st.sampled_from([0.001, 0.05, 0.2]))
    warm = draw(st.none() | st.tuples(st.none() | at, st.none() | at))
    space = SearchSpace(mild=mild, severe=severe, domain=domain, scale=scale)
    return Case(space, draw(at), edge, tolerance, rel_tolerance, draw(st.integers(1, 16)), warm)


def fixed(k: int) -> Callable[[], int]:
    """A ``width`` that is always ``k``."""
    return lambda: k


def recording(asked: list[float], passes: Callable[[float], bool]) -> Callable[[float], Trial]:
    """An evaluator that appends each value it is asked to ``asked``."""

    def evaluate(value: float) -> Trial:
        asked.append(value)
        return Trial(value, passes(value))

    return evaluate


def differences(case: Case, width: Callable[[], int]) -> list[str]:
    """What differs between the sequential search and one of ``width`` (a callable), in words:
    the interval, termination, verdict and the search path (its trials in order)."""
    sequential, parallel = case.search(), case.search(width)
    found = [
        f"{name}: {getattr(sequential, name)} sequential, {getattr(parallel, name)} parallel"
        for name in ("pass_value", "fail_value", "termination", "edge_passed")
        if getattr(sequential, name) != getattr(parallel, name)
    ]
    path = [t.value for t in parallel.trials if not t.speculative]
    if path != [t.value for t in sequential.trials]:
        found.append(f"path {path} is not the sequential {[t.value for t in sequential.trials]}")
    return found


@settings(max_examples=100, deadline=None, derandomize=True, database=None)
@given(case=cases(), widths=st.lists(st.sampled_from(WIDTHS), min_size=1, max_size=4))
def test_a_deterministic_system_gets_the_sequential_interval_at_every_width(case: Case, widths: list[int]) -> None:
    for k in WIDTHS:
        assert not differences(case, fixed(k)), k
    asked = iter(widths * 100)  # free workers change from round to round
    assert not differences(case, lambda: next(asked))


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(case=cases())
def test_off_path_trials_lie_outside_the_bracket_and_are_extra_to_the_budget(case: Case) -> None:
    result = case.search(fixed(7))
    path = [t for t in result.trials if not t.speculative]
    assert len(path) <= case.max_trials
    if result.pass_value is not None and result.fail_value is not None:
        lo, hi = sorted((result.pass_value, result.fail_value))
        assert all(not lo < t.value < hi for t in result.trials if t.speculative)
    assert result.speculative == len(result.trials) - len(path)


def test_breaking_the_node_rule_is_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    # a tree that evaluates nodes below brackets already within tolerance walks past the
    # sequential search's end: the equality check must see it
    honest = _Search._stop

    def past_tolerance(self: _Search, passing: float, failing: float, ahead: int = 0) -> str | None:
        stop = honest(self, passing, failing, ahead)
        return None if stop == "tolerance" and ahead > 0 else stop

    case = Case(SearchSpace(mild=0.0, severe=1000.0), 437.0, 0.0, 10.0, None, 30, None)
    assert not differences(case, fixed(7))
    monkeypatch.setattr(_Search, "_stop", past_tolerance)
    assert any(text.startswith(("pass_value", "fail_value")) for text in differences(case, fixed(7)))


def test_a_geometric_mean_that_underflows_ends_the_search_instead_of_leaving_the_bracket() -> None:
    # sqrt(3e-246 * 1.3e-122) underflows to 0, outside the bracket: the sequential search
    # evaluated 0 again and again; every search now stops there, at the float resolution
    case = Case(SearchSpace(mild=-50.0, severe=50.0), 3.1e-246, 3.1e-246, None, 0.001, 8, None)
    result = case.search()
    assert [t.value for t in result.trials] == [3.1e-246, 50.0, pytest.approx(math.sqrt(3.1e-246) * math.sqrt(50.0), rel=1e-9, abs=0)]
    assert result.termination == "domain_resolution" and not differences(case, fixed(7))


def test_a_4_ary_round_needs_half_the_rounds_of_bisection() -> None:
    # 0..1000 to 0.5: the edge, the far end, then 11 halvings; the 4-ary search (k = 3) takes
    # them two a round and the 8-ary (k = 7) three
    space = SearchSpace(mild=0.0, severe=1000.0)
    for boundary in (0.3, 137.0, 500.0, 734.2, 999.9):
        case = Case(space, boundary, 0.0, 0.5, None, 40, None)
        rounds = {k: case.search(fixed(k)).rounds - 2 for k in WIDTHS}
        assert rounds[1] == 11 == len(case.search().trials) - 2
        assert rounds[3] == 6 and rounds[7] == 4
        assert rounds[7] <= rounds[4] <= rounds[3] <= rounds[2] < rounds[1]


def test_a_partial_level_spreads_evenly_from_the_side_the_last_verdict_leads_to() -> None:
    # 0..1000, fails beyond 600: the far end failed, so the first round leans to the pass side;
    # after 500 passes, the second leans to the fail side
    space = SearchSpace(mild=0.0, severe=1000.0)
    rounds = {2: ({500.0, 250.0}, [500.0], {750.0, 875.0}), 5: ({500.0, 250.0, 750.0, 125.0, 625.0}, [500.0, 750.0, 625.0], None)}
    for k, (first, path, second) in rounds.items():
        asked: list[float] = []
        evaluate = recording(asked, lambda value: value <= 600.0)
        result = boundary_search(evaluate, space, 0.0, tolerance=1.0, max_trials=20, width=fixed(k))
        assert set(asked[2 : 2 + k]) == first  # after the edge and the far end
        assert [t.value for t in result.trials[2 : 2 + len(path)]] == path  # the walk along the verdicts
        assert {t.value for t in result.trials[2 + len(path) : 2 + k]} == first - set(path)
        assert all(t.speculative for t in result.trials[2 + len(path) : 2 + k])
        if second is not None:
            assert set(asked[2 + k : 2 + 2 * k]) == second


def test_the_budget_counts_the_path_and_speculation_stops_where_it_ends() -> None:
    # 4 trials: edge, far end and two on the path; the round after the far end holds only 2 levels
    case = Case(SearchSpace(mild=0.0, severe=1000.0), 437.0, 0.0, 0.5, None, 4, None)
    result = case.search(fixed(7))
    assert result.termination == "max_trials" and result.rounds == 3
    assert [t.value for t in result.trials if not t.speculative] == [0.0, 1000.0, 500.0, 250.0]
    assert result.speculative == 1  # 750: level 2 would be a fifth trial on the path


def test_hints_go_in_one_round() -> None:
    active, most = [0], [0]
    lock = threading.Lock()

    def slow(value: float) -> Trial:
        with lock:
            active[0] += 1
            most[0] = max(most[0], active[0])
        time.sleep(0.05)
        with lock:
            active[0] -= 1
        return Trial(value, value >= 14.3)

    space = SearchSpace(mild=30.0, severe=10.0)

    def search(k: int) -> SearchResult[Trial]:
        return boundary_search(slow, space, 25, tolerance=1, max_trials=12, warm_start=(15.0, 13.0), width=fixed(k))

    sequential, parallel = search(1), search(2)
    assert (parallel.pass_value, parallel.fail_value) == (sequential.pass_value, sequential.fail_value) == (15.0, 14.0)
    # the edge, the hints, bisection to 14-15 (14.0: one trial)
    assert sequential.rounds == 1 + 2 + 1 and parallel.rounds == 1 + 1 + 1 and most[0] == 2


# -- through the TrialRunner: an executor with k free slots ------------------------------------------------------


def fake_runner(tmp_path: Path, k: int) -> TrialRunner:
    dataset = open_dataset("synthetic", scene="indoor", frames=8, sensor="rgbd")
    requirement = Requirement.build([tracking_rate >= 0.5, fog.visibility_m >= 25], search_range=(1.0, 200.0))
    system = FakeSlam()  # tracks round(8 * v / 40) of 8 frames: passes from 17.5 m (4 of 8), fails below
    return TrialRunner(dataset, fog.visibility_m.ref(), system, requirement, workdir=tmp_path / f"work{k}", executor=InProcessSlots(k))


def test_free_slots_give_the_same_outcome_in_fewer_rounds_through_the_runner(tmp_path: Path) -> None:
    settings = SearchSettings(tolerance_pct=5.0, max_trials=12)
    one, four = fake_runner(tmp_path, 1), fake_runner(tmp_path, 4)
    sequential = deterministic_search(one, one.requirement, settings)
    parallel = deterministic_search(four, four.requirement, settings)
    assert (parallel.pass_value, parallel.fail_value, parallel.termination) == (sequential.pass_value, sequential.fail_value, "tolerance")
    assert sequential.fail_value is not None and sequential.pass_value is not None
    assert sequential.fail_value < 17.5 <= sequential.pass_value and not sequential.speculative
    assert parallel.rounds < sequential.rounds == len(sequential.trials) and parallel.speculative > 0
    assert four.executor.submitted == len(parallel.trials)  # one run per trial, speculative ones included

    outcome = search_outcome(four, four.requirement, settings, "test_fog")
    assert outcome.verdict == "passed" and (outcome.boundary.pass_value, outcome.boundary.fail_value) == (
        sequential.pass_value,
        sequential.fail_value,
    )
    marked = [t for t in outcome.trials if t.speculative]
    assert len(marked) == parallel.speculative and "(speculative)" in trial_line(marked[0], "fog.visibility_m", "m", [])
    assert not any(t.speculative for t in outcome.trials[:2])  # the edge and the far end are on the path
    stored = outcome.to_dict()
    assert [t.speculative for t in Outcome.from_dict(stored).trials] == [t.speculative for t in outcome.trials]
    for trial in stored["trials"]:
        del trial["speculative"]  # history written before the field existed
    assert not any(t.speculative for t in Outcome.from_dict(stored).trials)


def test_the_width_is_the_free_runs_one_a_trial(tmp_path: Path) -> None:
    assert search_width(fake_runner(tmp_path, 4)) == 4  # deterministic: one run a trial
    assert search_width(fake_runner(tmp_path, 1)) == 1
    assert search_width(fake_runner(tmp_path, 0)) == 1  # no free slot now: still one trial a round


def test_a_search_cached_along_its_path_sends_no_run_and_does_not_speculate(tmp_path: Path) -> None:
    """A second session with free workers walks the cached path trial by trial: speculating
    beside a cached midpoint would send runs the first session never made."""
    from pytest_sal.store.content_cache import ContentCache

    settings = SearchSettings(tolerance_pct=5.0, max_trials=12)
    cache = ContentCache(tmp_path / "cache")
    first = fake_runner(tmp_path, 1)
    first.cache = cache
    sequential = deterministic_search(first, first.requirement, settings)
    again = fake_runner(tmp_path, 4)
    again.cache = cache
    cached = deterministic_search(again, again.requirement, settings)
    assert again.executor.submitted == 0 and cached.speculative == 0
    assert [(t.value, t.passed) for t in cached.trials] == [(t.value, t.passed) for t in sequential.trials]
    # the pure search: a cached midpoint goes alone, an uncached one beside speculative trials
    case = Case(SearchSpace(mild=0.0, severe=1000.0), 400.0, 0.0, 0.5, None, 40, None)
    walked = boundary_search(case.evaluate, case.space, 0.0, 0.5, 40, width=fixed(7), cached=lambda value: True)
    assert walked.rounds == len(walked.trials) and walked.speculative == 0
