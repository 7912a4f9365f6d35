"""The documented import path of the trajectory metrics (``from pytest_sal.metrics import
evaluate, aggregate``); the code lives in :mod:`pytest_sal.analysis.metrics` (per-run metrics)
and :mod:`pytest_sal.analysis.trajectory_errors` (association, ATE, RPE, scale error)."""

from pytest_sal.analysis.metrics import AGGREGATED, RunMetrics, aggregate, evaluate
from pytest_sal.analysis.trajectory_errors import (
    MIN_POSES,
    Association,
    AteResult,
    ErrorStats,
    RpeResult,
    associate,
    ate,
    default_max_diff,
    relative_errors,
    rpe,
    scale_error,
)

__all__ = [
    "AGGREGATED",
    "MIN_POSES",
    "Association",
    "AteResult",
    "ErrorStats",
    "RpeResult",
    "RunMetrics",
    "aggregate",
    "associate",
    "ate",
    "default_max_diff",
    "evaluate",
    "relative_errors",
    "rpe",
    "scale_error",
]
