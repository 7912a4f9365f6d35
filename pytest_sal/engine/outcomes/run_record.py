"""One SLAM run, one type from the score to the report: ``RunRecord``.

``run_job`` makes it where the run happens (with the report images as PNG bytes and the whole
``RunResult`` for the trip back), the trial runner stores it in the cache (``entry`` /
``from_entry``), judges it (``judged``) and keeps it in its ``Trial``; the outcome's JSON (test
report, xdist, history) holds it as ``to_dict`` and reads it back with ``from_dict``.

It reads like the dict a trial's run was before (``run["ate_rmse"]``, ``run.get("stopped")``,
``"not_cached" in run``): a read-only mapping of its metrics and, once judged, ``passed``,
``abstained`` and ``cached`` (the form ``to_dict`` writes), equal to a dict of the same items.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

from pytest_sal.analysis.aggregation import AGGREGATED

__all__ = ["RunRecord"]

#: The keys of a run's ``to_dict`` that are its verdict, not its metrics.
_VERDICT = ("passed", "abstained", "cached", "not_cached")


@dataclass(frozen=True, eq=False)
class RunRecord(Mapping[str, Any]):
    """One run of a trial.

    Attributes:
        metrics: what the run measured, JSON-ready: ``RunMetrics.to_dict()`` (a metric that is
            not finite as ``None``) with ``wall_time_s``, ``starved``, ``load`` and, for a run
            stopped early, ``stopped`` (why).
        value: the severity it ran at, ``module`` the module configured there (``to_dict()``);
            ``None`` in a run read back from an outcome.
        artifacts: report files by kind (``frame``, ``trajectory``), paths.
        not_cached: why the run is not stored (the machine decided its failure), or ``None``.
        passed: it met every criterion (``None``: not judged yet); ``abstained``: it failed
            only because the machine starved it (no vote); ``cached``: read from the cache.
        images: report images as PNG bytes, on the way back from the worker (then
            ``artifacts``); ``result``: the whole ``RunResult.to_dict()``, on the way back;
            ``worker``: where it ran (``host:pid``).
    """

    metrics: Mapping[str, Any]
    value: float | None = None
    module: dict[str, Any] | None = None
    artifacts: Mapping[str, str] = field(default_factory=dict)
    not_cached: str | None = None
    passed: bool | None = None
    abstained: bool = False
    cached: bool = False
    images: dict[str, bytes] = field(default_factory=dict, repr=False)
    result: dict[str, Any] = field(default_factory=dict, repr=False)
    worker: str = ""

    @cached_property
    def _view(self) -> dict[str, Any]:
        """The run as a mapping (``to_dict``)."""
        view, judged = dict(self.metrics), self.passed is not None
        if judged:
            view["passed"] = self.passed
        for name in ("abstained", "cached"):  # a run read back unjudged keeps what it said
            if judged or getattr(self, name):
                view[name] = getattr(self, name)
        if self.not_cached is not None:
            view["not_cached"] = self.not_cached
        return view

    def __getitem__(self, name: str) -> Any:
        return self._view[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._view)

    def __len__(self) -> int:
        return len(self._view)

    def to_dict(self) -> dict[str, Any]:
        """The run in an outcome's JSON: its metrics with ``passed``, ``abstained``, ``cached``
        (once judged; else those that are true) and ``not_cached`` (when given), flat."""
        return dict(self._view)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RunRecord:
        """Inverse of ``to_dict`` (a run of an outcome, of any history: what it lacks reads as
        not judged)."""
        metrics = {k: v for k, v in data.items() if k not in _VERDICT}
        passed = data.get("passed")
        return cls(
            metrics,
            not_cached=data.get("not_cached"),
            passed=None if passed is None else bool(passed),
            abstained=bool(data.get("abstained")),
            cached=bool(data.get("cached")),
        )

    def entry(self) -> dict[str, Any]:
        """The run's cache entry: ``value``, ``module``, ``metrics``, ``artifacts`` and, when
        given, ``not_cached`` (never stored: it says why)."""
        data = {"value": self.value, "module": self.module, "metrics": dict(self.metrics), "artifacts": dict(self.artifacts)}
        return data | ({} if self.not_cached is None else {"not_cached": self.not_cached})

    @classmethod
    def from_entry(cls, data: Mapping[str, Any]) -> RunRecord:
        """Inverse of ``entry`` (check it with ``entry_problem`` first)."""
        return cls(
            data["metrics"],
            value=data.get("value"),
            module=data.get("module"),
            artifacts=data.get("artifacts", {}),
            not_cached=data.get("not_cached"),
        )

    @staticmethod
    def entry_problem(data: Any) -> str | None:
        """What a stored entry lacks for judging, in words (``None``: it can be used):
        ``metrics`` holds every metric of ``AGGREGATED`` as a finite number or null, ``failure``
        as text or null and ``starved`` as a bool; ``artifacts``, when present, maps names to paths."""
        metrics = data.get("metrics") if isinstance(data, Mapping) else None
        if not isinstance(metrics, dict):
            return "no 'metrics' object"
        for name in AGGREGATED:
            if name not in metrics:
                return f"metrics.{name} is missing"
            value = metrics[name]
            if value is not None and (not isinstance(value, numbers.Real) or isinstance(value, bool) or not math.isfinite(value)):
                return f"metrics.{name} is {value!r:.40}, not a finite number or null"
        if not isinstance(metrics.get("failure"), (str, type(None))):
            return "metrics.failure is not text or null"
        if not isinstance(metrics.get("starved"), bool):
            return "metrics.starved is not true or false"
        artifacts = data.get("artifacts", {})
        if not isinstance(artifacts, dict) or not all(isinstance(v, str) for v in artifacts.values()):
            return "artifacts is not an object of paths"
        return None

    def judged(self, passed: bool, cached: bool) -> RunRecord:
        """This run with its verdict: ``passed``; a failed run the machine starved abstains;
        ``cached``: it was read from the cache. Without the trip's images and ``result``."""
        abstained = bool(self.metrics.get("starved")) and not passed
        return replace(self, passed=passed, abstained=abstained, cached=cached, images={}, result={})
