"""What a robustness test found: its trials, the boundary interval and the verdict.

``Outcome`` is JSON-ready (``to_dict`` / ``from_dict``): it travels from xdist workers to the
controller on the test report, goes into the history store, the reports and JUnit XML.
Values are in the search unit of the parameter (``%`` for ``frame_drop.drop_rate``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

__all__ = ["Boundary", "Outcome", "Trial"]


@dataclass
class Trial:
    """One severity evaluated.

    Attributes:
        value: the searched parameter's value (search unit).
        passed: every criterion held (on the metrics aggregated over the runs).
        metrics: aggregated metrics (median over runs): ``ate_rmse``, ``rpe_trans``,
            ``rpe_rot``, ``tracking_rate``, ``scale_error``, ``first_tracked``, ``maps``
            (``None`` where not available).
        runs: per-run metrics (``RunMetrics.to_dict()``), failure reasons included.
        cached: the result came from the trial cache (no SLAM run).
        wall_time_s: time spent on this trial (s), perturbing and SLAM included.
        repeat: a re-run of the envelope's edge (flakiness check).
        failed: the criteria that did not hold, in words.
        artifacts: files made for reports, by kind: ``frame`` (an example perturbed frame,
            PNG), ``trajectory`` (ground truth and estimate, PNG).
    """

    value: float
    passed: bool
    metrics: dict[str, Any] = field(default_factory=dict)
    runs: list[dict[str, Any]] = field(default_factory=list)
    cached: bool = False
    wall_time_s: float = 0.0
    repeat: bool = False
    failed: list[str] = field(default_factory=list)
    artifacts: dict[str, str] = field(default_factory=dict)


@dataclass
class Boundary:
    """The failure boundary lies between ``pass_value`` and ``fail_value`` (either may be
    ``None`` when the search range did not bracket it)."""

    pass_value: float | None
    fail_value: float | None
    unit: str = ""

    def text(self) -> str:
        """``14-16 m``, ``> 1 m (never failed)``, ``< 100000 m (never passed)``."""
        unit = f" {self.unit}" if self.unit else ""
        if self.pass_value is not None and self.fail_value is not None:
            lo, hi = sorted((self.pass_value, self.fail_value))
            return f"{lo:.4g}-{hi:.4g}{unit}"
        if self.pass_value is not None:
            return f"beyond {self.pass_value:.4g}{unit} (passed everywhere searched)"
        if self.fail_value is not None:
            return f"beyond {self.fail_value:.4g}{unit} (failed everywhere searched)"
        return "unknown"


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
        verdict: ``passed``, ``failed`` or ``flaky``.
        boundary: the interval found.
        termination: ``tolerance``, ``max_trials``, ``not_bracketed``, ``domain_resolution``
            (``single`` for a sweep level or ``sal.at`` point).
        trials: every trial, in order.
        contradictions: trials contradicting monotonicity, in words.
        margin: distance from the envelope's edge to the boundary's pass end, towards the
            severe side (positive: the system copes beyond the requirement).
        previous: the boundary of the same test in the history, when compared.
        regression: why the comparison failed the test, when it did.
        reproduction: one line that re-runs the deciding trial.
        commit, machine: where it ran.
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
    reproduction: str = ""
    system_options: dict[str, Any] = field(default_factory=dict)
    dataset_fingerprint: str = ""
    seed: int = 0
    commit: str = ""
    machine: str = ""
    criteria: list[tuple[str, str, float]] = field(default_factory=list)
    envelope: str = ""

    @property
    def passed(self) -> bool:
        return self.verdict == "passed" and self.regression is None

    @property
    def cached_trials(self) -> int:
        return sum(t.cached for t in self.trials)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Outcome:
        data = dict(data)
        data["boundary"] = Boundary(**data["boundary"])
        data["previous"] = None if data.get("previous") is None else Boundary(**data["previous"])
        data["trials"] = [Trial(**t) for t in data.get("trials", [])]
        data["criteria"] = [(str(m), str(op), float(v)) for m, op, v in data.get("criteria", [])]
        return cls(**data)
