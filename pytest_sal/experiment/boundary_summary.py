"""``boundary_summary.json``, the file ``sal boundary`` writes beside its plot: the search's
``Outcome`` as ``Outcome.to_dict()`` gives it, and apart from it what only the experiment
knows::

    {"outcome": {...Outcome.to_dict()...},
     "experiment": {"config", "name", "boundary", "target_perturbation", "module",
                    "lower_bound", "upper_bound", "tolerance", "max_trials", "reliability",
                    "confidence", "max_runs", "linear_sweep_trials", "plot"}}

``read_boundary_summary`` reads it back; a summary of the flat form written before (one
object with ``pass_value``, ``edge_verdict``, trials with a ``verdict`` and a count of
``runs``) is upgraded first (``upgrade_boundary_summary``); ``max_iters``, the old name of
``max_trials``, is read as it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from pytest_sal.engine.outcomes.outcome import Outcome

__all__ = ["EXPERIMENT_KEYS", "BoundarySummary", "boundary_summary_data", "read_boundary_summary", "upgrade_boundary_summary"]

#: the keys of the summary's ``experiment`` block
EXPERIMENT_KEYS = (
    "config",
    "name",
    "boundary",
    "target_perturbation",
    "module",
    "lower_bound",
    "upper_bound",
    "tolerance",
    "max_trials",
    "reliability",
    "confidence",
    "max_runs",
    "linear_sweep_trials",
    "plot",
)


@dataclass(frozen=True)
class BoundarySummary:
    """A boundary summary read back: the search's ``outcome`` and the ``experiment`` block
    (``EXPERIMENT_KEYS``; bounds and tolerance in the parameter's unit, ``plot`` a path or ``None``)."""

    outcome: Outcome
    experiment: dict[str, Any]


def boundary_summary_data(outcome: Outcome, experiment: dict[str, Any]) -> dict[str, Any]:
    """The file's content: ``outcome`` as ``Outcome.to_dict()`` gives it and the ``experiment``
    block (exactly the keys of ``EXPERIMENT_KEYS``)."""
    if set(experiment) != set(EXPERIMENT_KEYS):
        raise ValueError(f"the experiment block needs the keys {', '.join(EXPERIMENT_KEYS)}; got {', '.join(experiment)}")
    return {"outcome": outcome.to_dict(), "experiment": dict(experiment)}


def read_boundary_summary(data: Any) -> BoundarySummary:
    """The summary ``data`` (the file's JSON), of either form; ``ValueError`` naming what is
    wrong when it is not one."""
    if isinstance(data, dict) and "outcome" not in data and "pass_value" in data:
        data = upgrade_boundary_summary(data)
    if not isinstance(data, dict) or not isinstance(data.get("outcome"), dict) or not isinstance(data.get("experiment"), dict):
        raise ValueError("not a boundary summary (no 'outcome' and 'experiment' objects)")
    try:
        outcome = Outcome.from_dict(data["outcome"])
    except (TypeError, KeyError, AttributeError) as exc:  # a field missing, unknown or of the wrong kind
        raise ValueError(f"its outcome cannot be read: {type(exc).__name__}: {exc}") from None
    return BoundarySummary(outcome, _experiment_block(data["experiment"]))


def _experiment_block(block: dict[str, Any]) -> dict[str, Any]:
    """The ``EXPERIMENT_KEYS`` of ``block`` (a summary written before: ``max_trials`` under its
    old name ``max_iters``)."""
    if "max_trials" not in block and "max_iters" in block:
        block = {**block, "max_trials": block["max_iters"]}
    return {key: block.get(key) for key in EXPERIMENT_KEYS}


#: ``Trial.votes()`` as the flat form stored it: ``2 of 3 runs failed (1 starved by the machine, not counted)``
_VOTES = re.compile(r"(\d+) of (\d+) runs? (?:passed|failed)(?: \((\d+) starved)?")


def upgrade_boundary_summary(old: dict[str, Any]) -> dict[str, Any]:
    """The flat summary ``old`` in the form ``sal boundary`` writes now. The old form kept no
    per-run records: each trial gets as many runs as it counted, voting as its ``votes`` text
    says (``criteria`` and ``envelope`` stay empty: it kept them only as words)."""
    outcome = {
        "test_id": f"sal boundary {old.get('experiment', '')}/{old.get('boundary', '')}",
        "verdict": old.get("edge_verdict"),
        "boundary": {"pass_value": old.get("pass_value"), "fail_value": old.get("fail_value"), "unit": old.get("unit") or ""},
        "trials": [_upgraded_trial(t) for t in old.get("trials") or [] if isinstance(t, dict)],
    }
    for key in ("system", "dataset", "parameter", "worse", "edge", "requirement", "termination"):
        outcome[key] = old.get(key)
    for key in ("contradictions", "system_options", "dataset_fingerprint", "seed"):
        if key in old:
            outcome[key] = old[key]
    experiment = {key: value for key, value in _experiment_block(old).items() if key not in ("config", "name")}
    return {"outcome": outcome, "experiment": {"config": None, "name": old.get("experiment"), **experiment}}


def _upgraded_trial(old: dict[str, Any]) -> dict[str, Any]:
    passed = old.get("verdict") == "pass"
    match = _VOTES.match(str(old.get("votes") or ""))
    if match is None:
        agreeing, voting, starved = int(old.get("runs") or 1), int(old.get("runs") or 1), 0
    else:
        agreeing, voting, starved = int(match[1]), int(match[2]), int(match[3] or 0)
    runs = [{"passed": passed} for _ in range(agreeing)] + [{"passed": not passed} for _ in range(voting - agreeing)]
    runs += [{"passed": False, "abstained": True} for _ in range(starved)]
    return {
        "value": old.get("value"),
        "passed": passed,
        "metrics": old.get("metrics") or {},
        "runs": runs,
        "cached": bool(old.get("cached")),
        "wall_time_s": old.get("wall_time_s") or 0.0,
        "failed": old.get("failed") or [],
    }
