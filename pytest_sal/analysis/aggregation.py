"""The one aggregation of run metrics: ``aggregate`` summarises runs (``RunMetrics``, or the
mappings a trial's runs are), metric by metric with ``summary`` and its one rule for a value
some runs lack; a trial's metrics are its medians (``TrialMetrics.of``). Plain Python, so the
plugin can read outcomes without loading numpy.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Protocol

__all__ = ["AGGREGATED", "MetricsRow", "aggregate", "summary"]


class MetricsRow(Protocol):
    """What ``aggregate`` reads of a run that is not a mapping: its metrics as a dict
    (``pytest_sal.analysis.metrics.RunMetrics.to_dict``)."""

    def to_dict(self) -> dict[str, Any]: ...


#: ``RunMetrics`` fields that ``aggregate`` summarises (a trial's metrics are their medians)
AGGREGATED = ("ate_rmse", "rpe_trans", "rpe_rot", "t_rel", "r_rel", "tracking_rate", "scale_error", "first_tracked", "maps", "matched")


def summary(values: Iterable[Any]) -> dict[str, Any]:
    """One metric over runs: ``median``, ``mean``, ``min``, ``max``, ``count`` and ``values``
    (the known ones). The rule for a missing value: ``None`` or not finite is missing, and a
    metric missing in half the runs or more has no statistics (``None``): a run that crashed
    or tracked nothing counts against it."""
    given = list(values)
    known = [float(v) for v in given if v is not None and math.isfinite(float(v))]
    stats: dict[str, Any] = dict.fromkeys(("median", "mean", "min", "max"))
    if known and 2 * len(known) > len(given):
        stats = {"median": statistics.median(known), "mean": statistics.fmean(known), "min": min(known), "max": max(known)}
    return {**stats, "count": len(known), "values": known}


def aggregate(runs: Sequence[MetricsRow | Mapping[str, Any]]) -> dict[str, Any]:
    """Summary over runs (``RunMetrics``, or mappings of their ``to_dict()`` items as a trial's
    runs are): ``runs``, ``failures`` (how many have one), ``failure_reasons``,
    ``kitti_missing`` (why ``t_rel`` / ``r_rel`` are missing, the first run's reason, when they
    are) and, per metric of ``AGGREGATED``, its ``summary``."""
    rows = [r if isinstance(r, Mapping) else r.to_dict() for r in runs]
    out: dict[str, Any] = {"runs": len(rows), "failure_reasons": [r["failure"] for r in rows if r.get("failure")]}
    out["failures"] = sum(1 for r in rows if r.get("failure") is not None)
    for name in AGGREGATED:
        out[name] = summary(r.get(name) for r in rows)
    missing = next((r["kitti_missing"] for r in rows if r.get("kitti_missing")), None)
    out["kitti_missing"] = missing if out["t_rel"]["median"] is None else None
    return out
