"""``sal compare REF [RUN]``: two runs of the history side by side; exit status 1 on a regression.

The gate outside pytest (as ``pytest-benchmark compare`` is): a CI step, or a person, compares a
pull request's run with the baseline after the fact. A regression is a test whose verdict got
worse (passed in REF, failed or flaky in RUN) or one that a ``--fail`` check fails (the forms of
``--sal-compare-fail``). Tests only one of the runs holds are listed, not counted.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from pytest_sal.history.run_history import DEFAULT_ROOT

if TYPE_CHECKING:
    from pytest_sal.engine.outcome import Outcome
    from pytest_sal.history.regression import RegressionCheck
    from pytest_sal.history.run_history import RunRecord

__all__ = ["add_compare_commands", "compare_runs"]

EPILOG = """\
examples:
  sal compare main                              the newest run against the newest run named main
  sal compare main 0012 --fail boundary:10%     run 12; a boundary 10 % closer to the requirement fails
  sal compare 0007 last --fail ate_rmse:15% --history-dir ci/.sal/history

REF and RUN: a run name (--sal-save=NAME), a run number, a commit prefix, or last.
Exit status: 0 no regression, 1 a regression, 2 a bad argument or an unknown run.
"""

#: ``Outcome.verdict`` from best to worst
VERDICT_RANK = {"passed": 0, "inconclusive": 1, "flaky": 1, "failed": 2}


def add_compare_commands(commands: argparse._SubParsersAction) -> None:
    """Add ``compare`` to the ``sal`` subcommands."""
    from pytest_sal.history.regression import COMPARE_FAIL_FORMS

    compare = commands.add_parser(
        "compare",
        help="compare a run of the history with a baseline run; exit 1 on a regression",
        description="One row per test of RUN: the baseline's boundary and verdict, this run's, the change. Regressions come first.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    compare.add_argument("ref", metavar="REF", help="the baseline run")
    compare.add_argument("run_ref", nargs="?", default="last", metavar="RUN", help="the run to check (default: last)")
    compare.add_argument(
        "--fail",
        dest="checks",
        action="append",
        default=[],
        metavar="CHECK",
        type=_check,
        help="also a regression: " + COMPARE_FAIL_FORMS.replace("%", "%%") + ". Repeatable",
    )  # argparse expands %
    compare.add_argument("--history-dir", type=Path, default=DEFAULT_ROOT, metavar="DIR", help="the run history (default: %(default)s)")
    compare.set_defaults(run=_run_compare)


def _check(text: str) -> RegressionCheck:
    from pytest_sal.history.regression import parse_compare_fail

    return parse_compare_fail(text)


def compare_runs(baseline: RunRecord, run: RunRecord, checks: list[RegressionCheck]) -> list[tuple[Outcome, Outcome | None, list[str]]]:
    """``(outcome, baseline outcome or None, regressions in words)`` for every outcome of
    ``run``, regressions first."""
    from pytest_sal.history.regression import regressions
    from pytest_sal.history.run_history import outcome_key

    rows = []
    for outcome in run.outcomes:
        before = baseline.get(outcome_key(outcome))
        found = [] if before is None else regressions(checks, outcome, before)
        if before is not None and VERDICT_RANK.get(outcome.verdict, 2) > VERDICT_RANK.get(before.verdict, 2):
            found.insert(0, f"{before.verdict} in {baseline.label}, {outcome.verdict} now")
        rows.append((outcome, before, found))
    return sorted(rows, key=lambda row: not row[2])


def _run_compare(args: argparse.Namespace) -> int:
    from pytest_sal.cli.history import change_text, print_table
    from pytest_sal.history.provenance import machine_text
    from pytest_sal.history.run_history import History

    history = History(args.history_dir)
    baseline, run = history.find_runs(args.ref)[-1], history.find_runs(args.run_ref)[-1]
    rows = compare_runs(baseline, run, args.checks)
    print(f"{_run_text(run)} against {_run_text(baseline)} in {args.history_dir}")
    machines = machine_text(baseline.machine), machine_text(run.machine)
    if machines[0] != machines[1]:
        print(
            f"note: the runs come from different machines ({machines[0]}; {machines[1]}): boundaries that depend on timing may differ for that alone"
        )
    table = [("test", "system", "dataset", f"boundary {baseline.label}", f"boundary {run.label}", "change", "verdict")]
    for outcome, before, found in rows:
        verdict = "REGRESSED" if found else outcome.verdict
        change = "not in the baseline" if before is None else change_text(before, outcome)
        table.append(
            (
                outcome.test_id,
                outcome.system,
                outcome.dataset,
                before.boundary.text() if before else "-",
                outcome.boundary.text(),
                change,
                verdict,
            )
        )
    print_table(table)
    regressed = [(outcome, found) for outcome, _, found in rows if found]
    for outcome, found in regressed:
        print(f"REGRESSED {outcome.test_id}: {'; '.join(found)}")
    gone = sorted({o.test_id for o in baseline.outcomes} - {o.test_id for o in run.outcomes})
    if gone:
        print(f"not in {run.label}: {', '.join(gone)}")
    print(f"{len(regressed)} regression{'s' if len(regressed) != 1 else ''} in {len(rows)} tests")
    return 1 if regressed else 0


def _run_text(run: RunRecord) -> str:
    parts = [f"run {run.label}"] + ([f"'{run.name}'"] if run.name else []) + ([f"commit {run.commit}"] if run.commit else [])
    return " ".join(parts)
