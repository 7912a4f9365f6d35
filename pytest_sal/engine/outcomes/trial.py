"""A trial: one severity evaluated by one or more runs (``Trial``), and its metrics, the
medians of its runs (``TrialMetrics``). The search takes trials as its verdicts and an
``Outcome`` holds them (``pytest_sal.engine.outcomes.outcome``, which also exports both).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, NoReturn

from pytest_sal.analysis.aggregation import AGGREGATED, aggregate
from pytest_sal.engine.outcomes.run_record import RunRecord
from sal_adapters.common.suggest import suggestion

__all__ = ["Trial", "TrialMetrics"]


class TrialMetrics(dict[str, Any]):
    """A trial's metrics, read like ``RunMetrics`` or like the dict they are stored as.

    ``m.ate_rmse == m["ate_rmse"]`` (m), ``m.get(name)``, ``name in m``, ``m.items()``; equal to a
    dict with the same items and written to JSON as one. A metric of ``AGGREGATED`` a trial
    lacks (no run tracked, an older history) reads as ``None``; an unknown name is an
    ``AttributeError`` (``KeyError`` for ``m[name]``) with the closest name or the known ones.
    Read-only: a trial's metrics are its runs' medians (``TrialMetrics({**m, "maps": 2})`` for
    a changed copy).
    """

    __slots__ = ()

    def __missing__(self, name: str) -> Any:
        if name in AGGREGATED:
            return None
        raise KeyError(self._unknown(name))

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        try:
            return self[name]
        except KeyError:
            raise AttributeError(self._unknown(name)) from None

    def __dir__(self) -> list[str]:
        return sorted({*super().__dir__(), *AGGREGATED, *(k for k in self if k.isidentifier())})

    @classmethod
    def of(cls, runs: Iterable[Mapping[str, Any]]) -> TrialMetrics:
        """The metrics of a trial with ``runs``: the median of each metric of ``AGGREGATED``
        (``analysis.metrics.aggregate``, with its rule for a metric runs lack), ``failures`` (the
        runs' reasons) and ``kitti_missing`` (why ``t_rel`` / ``r_rel`` are missing)."""
        summary = aggregate(list(runs))
        medians = {name: summary[name]["median"] for name in AGGREGATED}
        return cls(medians, failures=summary["failure_reasons"], kitti_missing=summary["kitti_missing"])

    def __reduce__(self) -> tuple[type, tuple[dict[str, Any]]]:
        return TrialMetrics, (dict(self),)

    def _unknown(self, name: str) -> str:
        return f"trial metrics have no {name!r}" + suggestion(name, [*AGGREGATED, *self], "metrics")

    def _read_only(self, *args: Any, **kwargs: Any) -> NoReturn:
        raise TypeError(
            "trial metrics are read-only (the medians of the trial's runs); make a changed copy: TrialMetrics({**metrics, name: value})"
        )

    __setitem__ = __delitem__ = clear = pop = popitem = setdefault = update = __ior__ = _read_only


@dataclass
class Trial:
    """One severity evaluated by one or more runs.

    Attributes:
        value: the searched parameter's value (its declared unit).
        passed: the majority of runs met every criterion (a tie fails).
        metrics: aggregated metrics (median over runs): ``ate_rmse``, ``rpe_trans``,
            ``rpe_rot``, ``t_rel``, ``r_rel``, ``tracking_rate``, ``scale_error``,
            ``first_tracked``, ``maps`` (``None`` where not available; ``kitti_missing`` says
            why ``t_rel`` / ``r_rel`` are), as ``TrialMetrics`` (``metrics.ate_rmse`` or
            ``metrics["ate_rmse"]``; a dict given is wrapped).
        runs: the runs, judged (``RunRecord``: ``run["ate_rmse"]``, ``run["passed"]``, ...;
            mappings given are read with ``RunRecord.from_dict``).
        cached: every run came from the cache (no SLAM run).
        wall_time_s: time spent on this trial (s), perturbing and SLAM included.
        failed: the criteria that did not hold on the median metrics, in words.
        artifacts: files made for reports, by kind: ``frame`` (an example perturbed frame,
            PNG), ``trajectory`` (ground truth and estimate, PNG).
        speculative: evaluated by a parallel search beside its path and left off it (extra to
            the trial budget; see ``pytest_sal.engine.search.bisection``).
    """

    value: float
    passed: bool
    metrics: TrialMetrics = field(default_factory=TrialMetrics)
    runs: tuple[RunRecord, ...] = ()
    cached: bool = False
    wall_time_s: float = 0.0
    failed: list[str] = field(default_factory=list)
    artifacts: dict[str, str] = field(default_factory=dict)
    speculative: bool = False

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "metrics" and not isinstance(value, TrialMetrics):
            value = TrialMetrics(value)
        if name == "runs":
            value = tuple(run if isinstance(run, RunRecord) else RunRecord.from_dict(run) for run in value)
        super().__setattr__(name, value)

    @property
    def passes(self) -> int:
        """Runs that met every criterion."""
        return sum(bool(r.get("passed", self.passed)) for r in self.runs)

    @property
    def fails(self) -> int:
        """Runs that did not (a run the machine starved, which fell behind the sensor clock
        even re-paced, is not counted: it abstains)."""
        return len(self.runs) - self.passes - self.abstained

    @property
    def abstained(self) -> int:
        """Runs that failed only after falling behind the sensor clock: no vote."""
        return sum(bool(r.get("abstained")) for r in self.runs)

    @property
    def agreeing(self) -> int:
        """Runs whose vote agrees with the trial's verdict."""
        return self.passes if self.passed else self.fails

    @property
    def voting(self) -> int:
        """Runs that voted (all but the starved ones)."""
        return self.passes + self.fails

    def failure_summary(self) -> str:
        """The runs that held and why the others failed, grouped by kind: ``4 of 6 runs held;
        2 initialised late (first pose at frame 28-33)``. Kinds: the run failed (its reason),
        initialised late, stopped early (the first one's reason), else lost
        tracking or a large ATE (the ranges of the runs' values). Late: the first pose at frame
        10 or later, or a tenth of the frames."""
        failed = [r for r in self.runs if not r.get("passed") and not r.get("abstained")]
        text = f"{self.passes} of {self.voting} run{'s' if self.voting != 1 else ''} held"
        if self.abstained:
            text += f" ({self.abstained} starved by the machine, not counted)"
        kinds: dict[str, list[RunRecord]] = {}
        for run in failed:
            kinds.setdefault(_failure_kind(run), []).append(run)
        parts = []
        for kind, runs in kinds.items():
            if kind == "late":
                parts.append(f"{len(runs)} initialised late (first pose at frame {_span([r['first_tracked'] for r in runs], 'g')})")
            elif kind == "tracking":
                parts.append(f"{len(runs)} lost tracking (tracking rate {_span([r.get('tracking_rate') for r in runs], '.2f')})")
            elif kind == "stopped":
                parts.append(f"{len(runs)} stopped early ({str(runs[0]['stopped']).strip()[:100]})")
            elif kind == "ate":
                parts.append(f"{len(runs)} drifted (ATE {_span([r.get('ate_rmse') for r in runs], '.3g')} m)")
            else:
                parts.append(f"{len(runs)} {kind}")
        return text + ("; " + ", ".join(parts) if parts else "")

    def votes(self) -> str:
        """``3 of 3 runs passed``, ``2 of 3 runs failed``: the runs behind the verdict."""
        voting = self.voting
        text = f"{self.agreeing} of {voting} run{'s' if voting != 1 else ''} {'passed' if self.passed else 'failed'}"
        return text + (f" ({self.abstained} starved by the machine, not counted)" if self.abstained else "")


def _failure_kind(run: RunRecord) -> str:
    """What kind of failure a failed run shows (``Trial.failure_summary``)."""
    if run.get("failure"):
        return f"failed: {str(run['failure']).split(';')[0][:80]}"
    first, frames = run.get("first_tracked"), run.get("frames")
    late_from = max(10, 0.1 * frames) if isinstance(frames, (int, float)) else 10
    if isinstance(first, (int, float)) and first >= late_from:
        return "late"
    if run.get("stopped"):
        return "stopped"
    rate = run.get("tracking_rate")
    return "tracking" if isinstance(rate, (int, float)) and rate < 0.95 else "ate"


def _span(values: list[Any], spec: str) -> str:
    """``28-33`` (or ``30``) over the known numbers of ``values``; ``-`` when none is known."""
    known = sorted(float(v) for v in values if isinstance(v, (int, float)) and math.isfinite(v))
    if not known:
        return "-"
    low, high = format(known[0], spec), format(known[-1], spec)
    return low if low == high else f"{low}-{high}"
