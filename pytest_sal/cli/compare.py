"""``sal compare REF [RUN]``: a run of the history against its baseline; exit status 1 on a regression that fails.

The gate outside pytest (as ``pytest-benchmark compare`` is): a CI step, or a person, compares a
pull request's run with the baseline after the fact, by the plugin's rules. Each test of RUN is
compared with its own baseline, ``History.baseline``: the newest run REF names that holds the
test, never RUN itself (so a ``-k`` run or an errored test in the newest ``main`` falls back
to an older ``main``, as the gate does). A regression is what ``regression.judge`` finds: a
verdict that got worse (passed in the baseline, failed or inconclusive now) or a ``--fail``
check that fails (the forms of ``--sal-compare-fail``) fail, exit status 1; without ``--fail``,
a boundary the default check (``boundary:10%``) finds regressed is listed and counted as a
regression, exit status 0, as ``--sal-compare`` alone reports it and passes the test. Tests
without a baseline are listed, not counted.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

from pytest_sal.history.run_history import DEFAULT_ROOT

if TYPE_CHECKING:
    from pytest_sal.engine.outcomes.outcome import Outcome
    from pytest_sal.history.regression import Judgement, RegressionCheck
    from pytest_sal.history.run_history import History, RunRecord

__all__ = ["CompareRow", "add_compare_commands", "compare_runs"]

EPILOG = """\
examples:
  sal compare main                              the newest run against main: each test against the newest main run holding it
  sal compare main 0012 --fail boundary:10%     run 12; a boundary 10 % closer to the requirement fails
  sal compare 0007 last --fail ate_rmse:15% --history-dir ci/.sal/history

REF and RUN: a run name (--sal-save=NAME), a run number, a commit prefix, or last.
RUN defaults to the newest run. A test's baseline is the newest run REF names that holds the
test, other than RUN (with REF last: that did not fail the gate either).
A regression: a verdict worse than the baseline's, a --fail check that fails, or (no --fail
given) a boundary the default check boundary:10% finds regressed, listed but not failing.
Exit status: 0 no regression that fails, 1 a regression that fails, 2 a bad argument or an unknown run.
"""


class CompareRow(NamedTuple):
    """One test of the compared run: its outcome, its baseline ``(run, outcome)`` (``None``:
    no run of REF holds it) and what ``judge`` found (``None`` without a baseline)."""

    outcome: Outcome
    baseline: tuple[RunRecord, Outcome] | None
    judgement: Judgement | None

    @property
    def regressions(self) -> list[str]:
        return [] if self.judgement is None else self.judgement.found


def add_compare_commands(commands: argparse._SubParsersAction) -> None:
    """Add ``compare`` to the ``sal`` subcommands."""
    from pytest_sal.history.regression import COMPARE_FAIL_FORMS

    compare = commands.add_parser(
        "compare",
        help="compare a run of the history with its baseline; exit 1 on a regression that fails",
        description="One row per test of RUN: the baseline's boundary and verdict, this run's, the change. Regressions come first.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    compare.add_argument("ref", metavar="REF", help="the baseline: each test against the newest run REF names that holds it")
    compare.add_argument("run_ref", nargs="?", default="last", metavar="RUN", help="the run to check (default: last, the newest run)")
    compare.add_argument(
        "--fail",
        dest="checks",
        action="append",
        default=[],
        metavar="CHECK",
        type=_check,
        help="a regression that fails (instead of the default check boundary:10%%, said only): "
        + COMPARE_FAIL_FORMS.replace("%", "%%")
        + ". Repeatable",
    )  # argparse expands %
    compare.add_argument("--history-dir", type=Path, default=DEFAULT_ROOT, metavar="DIR", help="the run history (default: %(default)s)")
    compare.set_defaults(run=_run_compare)


def _check(text: str) -> RegressionCheck:
    from pytest_sal.history.regression import parse_compare_fail

    return parse_compare_fail(text)


def compare_runs(history: History, ref: str, run: RunRecord, checks: list[RegressionCheck]) -> list[CompareRow]:
    """A ``CompareRow`` for every outcome of ``run`` against its baseline in ``ref``
    (``History.baseline``, ``run`` excluded), regressions that fail first, then those said.

    Raises:
        SalError: ``ref`` names no run.
    """
    from pytest_sal.history.regression import judge
    from pytest_sal.history.run_history import outcome_key

    rows = []
    for outcome in run.outcomes:
        found = history.baseline(outcome_key(outcome), ref, exclude=run.number)
        judgement = None if found is None else judge(outcome, found[1], checks, found[0].label)
        rows.append(CompareRow(outcome, found, judgement))
    return sorted(rows, key=lambda row: (not (row.judgement and row.judgement.fails), not row.regressions))


def _run_compare(args: argparse.Namespace) -> int:
    from pytest_sal.cli.history import change_text, print_table
    from pytest_sal.history.provenance import machine_text
    from pytest_sal.history.regression import DEFAULT_CHECKS
    from pytest_sal.history.run_history import History

    history = History(args.history_dir)
    run = history.find_runs(args.run_ref)[-1]
    others = [r for r in history.find_runs(args.ref) if r.number != run.number]  # an unknown REF: exit 2
    rows = compare_runs(history, args.ref, run, args.checks)
    used = sorted({row.baseline[0].number: row.baseline[0] for row in rows if row.baseline}.items())
    if len(used) == 1:
        print(f"{_run_text(run)} against {_run_text(used[0][1])} in {args.history_dir}")
    else:
        runs = ", ".join(r.label for _, r in used) or "none holds a test of it"
        print(
            f"{_run_text(run)} against {args.ref!r}, each test against the newest of its runs holding it (runs {runs}) in {args.history_dir}"
        )
    machines = {machine_text(r.machine) for _, r in used} - {machine_text(run.machine)}
    if machines:
        print(
            f"note: the runs come from different machines ({'; '.join(sorted(machines))}; {machine_text(run.machine)}): "
            "boundaries that depend on timing may differ for that alone"
        )
    label = used[0][1].label if len(used) == 1 else "baseline"
    table = [("test", "system", "dataset", f"boundary {label}", f"boundary {run.label}", "change", "verdict")]
    for outcome, found, judgement in rows:
        before = found[1] if found else None
        verdict = "REGRESSED" if judgement and judgement.found else outcome.verdict
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
    for row in rows:
        if row.regressions:
            print(f"REGRESSED {row.outcome.test_id}: {'; '.join(row.regressions)}")
    gone = sorted({o.test_id for o in others[-1].outcomes} - {o.test_id for o in run.outcomes}) if others else []
    if gone:
        print(f"not in {run.label}: {', '.join(gone)}")
    regressed = [row for row in rows if row.regressions]
    failing = [row for row in regressed if row.judgement and row.judgement.fails]
    print(f"{len(regressed)} regression{'s' if len(regressed) != 1 else ''} in {len(rows)} tests")
    if len(failing) < len(regressed):
        print(
            f"note: {len(regressed) - len(failing)} found by the default check {DEFAULT_CHECKS[0]}, which does not fail; give --fail CHECK to fail on a regression"
        )
    return 1 if failing else 0


def _run_text(run: RunRecord) -> str:
    parts = [f"run {run.label}"] + ([f"'{run.name}'"] if run.name else []) + ([f"commit {run.commit}"] if run.commit else [])
    return " ".join(parts)
