"""The regression gate: an outcome compared with its baseline in the run history.

``--sal-compare=REF`` names the baseline: a run name saved with ``--sal-save=NAME`` (the ini
``sal_baseline``, ``main`` by default, when no REF is given), a run number, a commit prefix, or
``last`` (the newest run whose outcome did not fail a gate, so rerunning a regressed commit
compares with the last good run). Of the runs REF names, the newest that holds the test is its
baseline (``History.baseline``). A test with nothing to compare against is said so in its
``comparison``; under ``--sal-compare-missing=fail`` it fails. A regression is what
``regression.judge`` finds; without ``--sal-compare-fail`` it is said, not failed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sal_adapters.common.errors import SalError

if TYPE_CHECKING:
    from pytest_sal.engine.outcomes.outcome import Outcome
    from pytest_sal.history.regression import RegressionCheck
    from pytest_sal.history.run_history import History

__all__ = ["MISSING_POLICIES", "NOT_COMPARED", "compare_with_baseline"]

#: what a test with no baseline does: ``pass`` (said in its row and the summary) or ``fail``
MISSING_POLICIES = ("pass", "fail")
#: how ``Outcome.comparison`` starts when there was nothing to compare with
NOT_COMPARED = "not compared: "


def compare_with_baseline(
    outcome: Outcome,
    history: History,
    ref: str,
    checks: list[RegressionCheck],
    *,
    missing: str = "pass",
) -> Outcome:
    """``outcome`` compared with the same test's outcome in the baseline ``ref``
    (``History.baseline``, the rule ``sal compare`` follows too): sets ``previous`` (the
    baseline's boundary), ``comparison`` (what it was compared with, or why not, and, without
    ``checks``, a regression the default check finds) and ``regression`` (the failed
    ``checks``; with ``missing="fail"``, also a missing baseline). A worse verdict is not
    repeated here: the test fails by its requirement. Returns ``outcome``."""
    from pytest_sal.history.regression import DEFAULT_CHECKS, judge
    from pytest_sal.history.run_history import outcome_key

    try:
        found = history.baseline(outcome_key(outcome), ref)
        reason = "" if found else f"no outcome of this test ({outcome.system} on {outcome.dataset}) in {_ref_text(ref)} of {history.root}"
    except SalError as exc:  # ref names no run: a missing baseline (the message lists the runs there)
        found, reason = None, str(exc)
    if found is None:
        outcome.comparison = NOT_COMPARED + reason
        if missing == "fail":
            outcome.regression = f"{outcome.comparison} (--sal-compare-missing=fail)"
        return outcome
    run, previous = found
    outcome.previous = previous.boundary
    where = f"run {run.label}" + (f", commit {run.commit}" if run.commit else "")
    notes = [f"{run.name or ref} ({where})"]
    if previous.machine and outcome.machine and previous.machine != outcome.machine:
        notes.append(f"on another machine: baseline {previous.machine}, this run {outcome.machine}")
    if previous.system_version and outcome.system_version and previous.system_version != outcome.system_version:
        notes.append(f"system {previous.system_version} -> {outcome.system_version}")
    judgement = judge(outcome, previous, checks)
    notes += [f"regressed (the default check {DEFAULT_CHECKS[0]}; --sal-compare-fail fails it): {said}" for said in judgement.said]
    outcome.comparison = "; ".join(notes)
    outcome.regression = "; ".join(judgement.failing) if judgement.failing else None
    return outcome


def _ref_text(ref: str) -> str:
    return "the runs of the history" if ref == "last" else f"the baseline {ref!r}"
