"""What a robustness test found: its trials, the boundary interval and the verdict.

``Outcome`` is JSON-ready (``to_dict`` / ``from_dict``): it travels from xdist workers to the
controller on the test report, goes into the history store, the reports and JUnit XML.
Values are in the parameter's declared unit (what ``sal modules`` prints: lx, ISO, m, ...).

The boundary interval's text has its one implementation here, ``Boundary.text`` (long, for
messages) and ``Boundary.short_text`` (for a table cell), on ``pytest_sal.engine.outcomes.quantity``:
the engine writes it into a failing test's message, and the reports, the plugin and the
commands above re-use it. The trials at a value (the bracket's ends, the envelope's edge) are
looked up by one rule, ``Outcome.trial_at``. ``Trial`` and ``TrialMetrics`` live in
``pytest_sal.engine.outcomes.trial`` and are exported here too.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from typing import Any

from pytest_sal.engine.outcomes.json_shape import nesting_problem, read_fields
from pytest_sal.engine.outcomes.legacy_units import upgrade_outcome
from pytest_sal.engine.outcomes.quantity import num, with_unit
from pytest_sal.engine.outcomes.trial import Trial, TrialMetrics

__all__ = ["Boundary", "Outcome", "Trial", "TrialMetrics", "failures_first"]


@dataclass
class Boundary:
    """The failure boundary lies between ``pass_value`` and ``fail_value`` (either may be
    ``None`` when the search range did not bracket it).

    A noisy system's boundary is statistical (``noisy``; ``pytest_sal.engine.search.reliability_curve``):
    ``estimate`` is ``s_R`` (the most severe value where the chance ``p`` that a run holds the
    requirement is at least ``reliability``), ``bound`` its one-sided bound ``s_R/C`` at
    ``confidence`` (``s_R`` is at least this severe with that confidence), ``interval`` the
    equal-tailed interval of ``s_R`` at ``confidence``, ``s50`` / ``s50_interval`` the same for
    ``p = 0.5``, ``transition`` the values where ``p`` has fallen by 10 % and by 90 % of its
    drop, ``holds_at_edge`` the confidence that ``p(edge) >= reliability``, ``runs`` the runs
    fitted, ``curve`` rows ``(value, median p, low, high)`` of the fitted curve and its band,
    and ``search_range`` / ``log_scale`` / ``grid_step`` the axis the curve was fitted on (to
    refit it from the trials' runs). A value at an end of ``search_range`` may lie beyond it.
    ``pass_value`` is then ``bound`` and ``fail_value`` the bound on the severe side (``s_R``
    is milder than it with ``confidence``).
    """

    pass_value: float | None
    fail_value: float | None
    unit: str = ""
    estimate: float | None = None
    bound: float | None = None
    interval: list[float] | None = None
    reliability: float | None = None
    confidence: float | None = None
    runs: int | None = None
    s50: float | None = None
    s50_interval: list[float] | None = None
    transition: list[float] | None = None
    holds_at_edge: float | None = None
    curve: list[list[float]] | None = None
    search_range: list[float] | None = None
    log_scale: bool | None = None
    grid_step: float | None = None

    @property
    def noisy(self) -> bool:
        """A statistical boundary (a noisy system's fitted curve)."""
        return self.reliability is not None

    def text(self) -> str:
        """The interval in words: ``14-16 m`` (``-3.5 to -1.25 m`` when it reaches below 0),
        ``beyond 1 m (passed everywhere searched)``, ``beyond 1e+05 m (failed everywhere
        searched)``, ``unknown``; a noisy system's ``s80/90 >= 540 particles (s80 610; s50 790,
        700-900)`` (``statistical_text``)."""
        if self.noisy:
            return self.statistical_text()
        if self.pass_value is not None and self.fail_value is not None:
            lo, hi = sorted((self.pass_value, self.fail_value))
            return f"{num(lo)}{'-' if lo >= 0 else ' to '}{with_unit(hi, self.unit)}"
        if self.pass_value is not None:
            return f"beyond {with_unit(self.pass_value, self.unit)} (passed everywhere searched)"
        if self.fail_value is not None:
            return f"beyond {with_unit(self.fail_value, self.unit)} (failed everywhere searched)"
        return "unknown"

    def statistical_text(self) -> str:
        """``s80/90 >= 540 particles (s80 610; s50 790, 700-900)``: the one-sided bound, then the
        point estimates and ``s50``'s interval (``<=`` where lower values are more severe);
        ``s80/90 beyond 1000 particles`` when the bound lies past the severe end,
        ``s80/90 not reached (...)`` when ``p`` may be below 80 % from the mild end on."""
        assert self.reliability is not None and self.confidence is not None and self.search_range
        mild, severe = self.search_range
        name = f"s{_pct(self.reliability)}/{_pct(self.confidence)}"
        sign = ">=" if severe > mild else "<="
        if self.bound is None or self._at(self.bound, severe):
            head = f"{name} beyond {with_unit(severe, self.unit)} (searched to there)"
        elif self._at(self.bound, mild):
            head = f"{name} not reached (p may be below {_pct(self.reliability)} % from {with_unit(mild, self.unit)} on)"
        else:
            head = f"{name} {sign} {with_unit(self.bound, self.unit)}"
        estimate = f"s{_pct(self.reliability)} {self._value(self.estimate)}"
        if self.s50_interval:
            low, high = sorted(self.s50_interval)
            s50 = f"s50 {self._value(self.s50)}, {self._value(low)} to {self._value(high)}"
            estimate = s50 if self.reliability == 0.5 else f"{estimate}; {s50}"
        return f"{head} ({estimate})"

    def _at(self, value: float, end: float) -> bool:
        return math.isclose(value, end, rel_tol=1e-9, abs_tol=1e-12)

    def _value(self, value: float | None) -> str:
        """A value of the fitted curve with its unit, or ``beyond 1000 particles`` / ``before 0
        particles`` at an end of the range."""
        if value is None or not self.search_range:
            return with_unit(value, self.unit)
        mild, severe = self.search_range
        if self._at(value, severe):
            return f"beyond {with_unit(severe, self.unit)}"
        if self._at(value, mild):
            return f"before {with_unit(mild, self.unit)}"
        return with_unit(value, self.unit)

    def short_text(self, worse: str, *, single: bool = False) -> str:
        """The interval for a table cell: ``14-16 m`` as ``text``; one-sided as a bound on
        the severe side (``worse``: ``lower`` or ``higher`` values are more severe), ``< 1 m
        (never failed)`` or ``> 1e+05 m (never passed)``; ``passed at 3 px`` or ``failed at 3
        px`` when ``single`` (one sweep level or ``sal.at`` point was tried); a noisy system's
        ``statistical_text`` (``p 0.93 (0.81-0.99)`` at a single point)."""
        if self.noisy and not single:
            return self.statistical_text()
        if (self.pass_value is None) == (self.fail_value is None):
            return self.text()
        if single:
            if self.pass_value is not None:
                return f"passed at {with_unit(self.pass_value, self.unit)}"
            return f"failed at {with_unit(self.fail_value, self.unit)}"
        severe_below = worse == "lower"  # the severe side is below the passing values
        if self.pass_value is not None:
            return f"{'<' if severe_below else '>'} {with_unit(self.pass_value, self.unit)} (never failed)"
        return f"{'>' if severe_below else '<'} {with_unit(self.fail_value, self.unit)} (never passed)"


def _pct(probability: float) -> str:
    """``0.9`` -> ``90``, ``0.975`` -> ``97.5``."""
    return f"{100 * probability:.4g}"


@dataclass
class Outcome:
    """The result of one robustness test (one boundary search, or one sweep level).

    Attributes:
        test_id: pytest node id.
        system: SLAM system name and ``system_options``.
        dataset: the dataset's name and ``dataset_fingerprint``.
        parameter: the searched parameter's label (``fog.visibility_m``), ``worse`` its
            direction (``lower``/``higher``), ``edge`` the envelope's edge value.
        requirement: the requirement in words; ``criteria`` its pass criteria as
            ``(metric, op, threshold)`` and ``envelope`` its envelope without the parameter
            (``>= 25 m``; empty without one).
        verdict: ``passed``, ``failed`` or ``inconclusive`` (a noisy system's runs did not
            settle whether ``p(edge) >= reliability``; ``flaky`` in history written before).
        boundary: the interval found.
        termination: ``tolerance``, ``max_trials``, ``not_bracketed``, ``domain_resolution``
            (``single`` for a sweep level or ``sal.at`` point).
        trials: every trial, in order.
        contradictions: trials contradicting monotonicity, in words.
        margin: distance from the envelope's edge to the boundary's pass end, towards the
            severe side (positive: the system copes beyond the requirement).
        previous: the boundary of the same test in the history, when compared.
        regression: why the comparison failed the test, when it did.
        comparison: what it was compared with (``main (run 0003, commit 1a2b3c4)``, and a
            note when that ran on another machine or system version), or why it was not
            (``not compared: ...``); empty without ``--sal-compare``.
        reproduction: one line that re-runs the deciding trial.
        commit, machine: where it ran (``machine``: the CPU model and cores).
        system_version: ``SlamSystem.version_text()`` of the system that ran.
    """

    test_id: str
    system: str
    dataset: str
    parameter: str
    worse: str
    edge: float | None
    requirement: str
    verdict: str
    boundary: Boundary
    termination: str
    trials: list[Trial] = field(default_factory=list)
    contradictions: list[str] = field(default_factory=list)
    margin: float | None = None
    previous: Boundary | None = None
    regression: str | None = None
    comparison: str = ""
    reproduction: str = ""
    system_options: dict[str, Any] = field(default_factory=dict)
    dataset_fingerprint: str = ""
    seed: int = 0
    commit: str = ""
    machine: str = ""
    system_version: str = ""
    criteria: list[tuple[str, str, float]] = field(default_factory=list)
    envelope: str = ""

    @property
    def passed(self) -> bool:
        return self.verdict == "passed" and self.regression is None

    @property
    def cached_trials(self) -> int:
        return sum(t.cached for t in self.trials)

    @property
    def runs(self) -> int:
        """SLAM runs behind the outcome (cached ones included)."""
        return sum(len(t.runs) for t in self.trials)

    def trial_at(self, value: float | None) -> Trial | None:
        """The trial at ``value`` (``None`` when none was tried there, or ``value`` is
        ``None``). The rule: equal within float rounding (``math.isclose``, relative 1e-9,
        absolute 1e-12: a value converted from an older unit or through JSON still finds its
        trial), and of several trials at that value the last, the latest evidence."""
        if value is None:
            return None
        return next((t for t in reversed(self.trials) if math.isclose(t.value, value, rel_tol=1e-9, abs_tol=1e-12)), None)

    def end_trials(self) -> tuple[Trial | None, Trial | None]:
        """The trials at the bracket's pass and fail ends (``trial_at`` each end)."""
        return self.trial_at(self.boundary.pass_value), self.trial_at(self.boundary.fail_value)

    def confidence(self) -> str:
        """How sure the result is, from the runs behind the deciding verdicts:
        ``edge 3 of 3 runs passed; pass end 3 of 3 runs passed, fail end 4 of 5 runs failed``,
        or ``1 run per trial`` (a deterministic system); a noisy system's ``p >= 80 % at the edge
        with confidence 97.3 % (30 runs)``."""
        b = self.boundary
        if b.noisy and b.holds_at_edge is not None and b.reliability is not None:
            where = "at the edge" if self.termination != "single" else "here"
            return f"p >= {_pct(b.reliability)} % {where} with confidence {100 * b.holds_at_edge:.3g} % ({b.runs} runs)"
        if not self.trials or all(len(t.runs) <= 1 for t in self.trials):
            return "1 run per trial"
        parts = [f"edge {self.trials[0].votes()}" if self.termination != "single" else self.trials[0].votes()]
        ends = [
            f"{label} {t.votes()}"
            for label, t in zip(("pass end", "fail end"), self.end_trials())
            if t is not None and t is not self.trials[0]
        ]
        return "; ".join(parts + ([", ".join(ends)] if ends else []))

    def to_dict(self) -> dict[str, Any]:
        data = dict(asdict(self), confidence=self.confidence())
        for trial, data_trial in zip(self.trials, data["trials"]):
            data_trial.update(metrics=dict(trial.metrics), runs=[run.to_dict() for run in trial.runs])  # plain JSON-ready dicts
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Outcome:
        """Inverse of ``to_dict``; an outcome stored in an older unit is converted
        (``pytest_sal.engine.outcomes.legacy_units``).

        Raises:
            ValueError: ``data`` is not an outcome: a field missing or of another type, a number
                not finite, nesting deeper than ``json_shape.MAX_NESTING`` (a hand-edited
                history), naming the key. A non-finite metric reads as ``None``.
        """
        problem = nesting_problem(data)
        if problem is not None:
            raise ValueError(problem)
        if not isinstance(data, dict) or not isinstance(data.get("boundary"), dict):
            raise ValueError("not an outcome (no boundary)")
        fields = upgrade_outcome(read_fields(cls, data))
        fields["boundary"] = Boundary(**fields["boundary"])
        fields["previous"] = None if fields.get("previous") is None else Boundary(**fields["previous"])
        fields["trials"] = [Trial(**trial) for trial in fields.get("trials", [])]
        fields["criteria"] = [tuple(criterion) for criterion in fields.get("criteria", [])]
        return cls(**fields)


def failures_first(outcomes: Iterable[Outcome]) -> list[Outcome]:
    """``outcomes`` with the tests that failed (flaky and regressed ones included: every one
    not ``passed``) first, then the rest, each group sorted by test id: what a report lists.
    Sorted, not in the order given, so that a report reads the same whatever order the
    ``pytest -n`` workers finished the tests in."""
    ordered = sorted(outcomes, key=lambda o: (o.test_id, o.system, o.dataset))
    return [o for o in ordered if not o.passed] + [o for o in ordered if o.passed]
