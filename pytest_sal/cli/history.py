"""``sal history``: the boundaries of the saved runs, per test, as a table and a plot."""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING

from pytest_sal.cli.arg_types import age_seconds, positive_int
from pytest_sal.engine.outcomes.outcome import Outcome
from pytest_sal.history.gate import NOT_COMPARED
from pytest_sal.history.run_history import DEFAULT_ROOT, History, OutcomeKey, RunRecord
from sal_adapters import SalError

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["add_history_commands", "change_text", "history_figure", "plot_history", "print_table", "verdict_text"]

EPILOG = """\
examples:
  sal history                                   every test: latest boundary, change since the run before
  sal history test_fog                          one test (a node id, or part of one): each run and a plot
  sal history test_fog --system orbslam3 -o fog.png
  sal history --history-dir ci-runs/.sal/history
  sal history prune --keep 20                   remove all but the newest 20 runs
  sal history prune --older-than 30d --dry-run  list the runs older than 30 days

Prune never removes the newest run of each name (a baseline saved with --sal-save=main
survives) nor the newest run.

Runs are saved by pytest-sal sessions under .sal/history (one JSON file per session run).
"""

VERDICT_COLOURS = {"passed": "#2ca02c", "failed": "#d62728", "inconclusive": "#ff7f0e", "flaky": "#ff7f0e"}
BAND_COLOUR = "#1f77b4"


def add_history_commands(commands: argparse._SubParsersAction) -> None:
    """Add ``history`` to the ``sal`` subcommands."""
    history = commands.add_parser(
        "history",
        help="boundaries of the saved runs: every test, or one test's runs and a plot",
        description="Without TEST: every test in the run history with its latest boundary and the\n"
        "change since the run before. With TEST: one line per run (run, commit, date, boundary,\n"
        "verdict, trials) and a PNG of the boundary interval over the runs.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    history.add_argument("test", nargs="?", metavar="TEST", help="a test's node id, or a part of it that matches one test")
    history.add_argument("--history-dir", type=Path, default=DEFAULT_ROOT, metavar="DIR", help="the run history (default: %(default)s)")
    history.add_argument("--system", metavar="S", help="only outcomes of this SLAM system")
    history.add_argument("--dataset", metavar="D", help="only outcomes on this dataset")
    history.add_argument("-o", "--out", type=Path, metavar="PNG", help="plot file (default: sal-history-<test>.png)")
    prune = history.add_argument_group(
        "sal history prune",
        "remove old runs: those beyond the newest N, those older than AGE, "
        "or (both given) those that are both; each name's newest run and the newest run stay",
    )
    prune.add_argument("--keep", type=positive_int, metavar="N", help="keep the newest N runs")
    prune.add_argument("--older-than", type=age_seconds, metavar="AGE", help="remove runs written more than AGE ago: 30d, 12h, 2w")
    prune.add_argument("--dry-run", action="store_true", help="list what would be removed, remove nothing")
    history.set_defaults(run=_run_history)


def _run_prune(args: argparse.Namespace) -> int:
    history = History(args.history_dir)
    before = history.runs()
    removed = history.prune(keep=args.keep, older_than_s=args.older_than, dry_run=args.dry_run)
    verb = "would remove" if args.dry_run else "removed"
    for run in removed:
        print(f"{verb} {run.path.name}" + (f" (name {run.name})" if run.name else ""))
    print(f"{args.history_dir}: {verb} {len(removed)} of {len(before)} runs; {len(before) - len(removed)} kept")
    return 0


def _run_history(args: argparse.Namespace) -> int:
    if args.test == "prune":
        return _run_prune(args)
    if args.keep is not None or args.older_than is not None or args.dry_run:
        raise SalError("--keep, --older-than and --dry-run belong to sal history prune")
    history = History(args.history_dir)
    runs = history.runs()
    if not runs:
        raise SalError(f"no runs saved in {args.history_dir} (give the folder with --history-dir)")
    keys = [
        k for k in history.outcome_keys() if (args.system is None or k[1] == args.system) and (args.dataset is None or k[2] == args.dataset)
    ]
    if not keys:
        raise SalError(f"no outcome in {args.history_dir} for {_filter_text(args)}")
    if args.test is None:
        _print_listing(history, runs, keys)
        return 0
    test_id = _select_test(args.test, [k[0] for k in keys], args.history_dir)
    series = sorted({k for k in keys if k[0] == test_id})
    if len(series) > 1:
        choices = "; ".join(f"{system} on {dataset}" for _, system, dataset in series)
        raise SalError(
            f"{test_id} ran with {len(series)} systems/datasets in the history ({choices}): choose one with --system and --dataset"
        )
    _, system, dataset = series[0]
    trend = history.trend(test_id, system, dataset)
    _print_trend(test_id, system, dataset, trend)
    out = args.out or Path(f"sal-history-{_file_part(test_id)}.png")
    print(f"plot: {plot_history(trend, out)}")
    return 0


def _filter_text(args: argparse.Namespace) -> str:
    parts = [f"--system {args.system}" if args.system else "", f"--dataset {args.dataset}" if args.dataset else ""]
    return " ".join(p for p in parts if p)


def _select_test(text: str, test_ids: list[str], root: Path) -> str:
    unique = list(dict.fromkeys(test_ids))
    if text in unique:
        return text
    found = [t for t in unique if text in t]
    if len(found) == 1:
        return found[0]
    if not found:
        shown = "\n  ".join(unique[:20]) + ("\n  ..." if len(unique) > 20 else "")
        raise SalError(f"no test matching {text!r} in {root}; tests there:\n  {shown}")
    raise SalError(f"{text!r} matches {len(found)} tests; give more of the node id:\n  " + "\n  ".join(found))


# -- text -------------------------------------------------------------------------------------


def _print_listing(history: History, runs: list[RunRecord], keys: list[OutcomeKey]) -> None:
    first, last = runs[0], runs[-1]
    print(f"{history.root}: {len(runs)} run{'s' if len(runs) != 1 else ''}, {first.label} ({_date(first)}) .. {last.label} ({_date(last)})")
    rows = [("test", "system", "dataset", "run", "boundary", "verdict", "change since the run before")]
    for key in keys:
        trend = [(r, o) for r, o in ((r, r.get(key)) for r in runs) if o is not None]
        run, latest = trend[-1]
        before = trend[-2][1] if len(trend) > 1 else None
        rows.append((key[0], key[1], key[2], run.label, latest.boundary.text(), verdict_text(latest), change_text(before, latest)))
    print_table(rows)


def _print_trend(test_id: str, system: str, dataset: str, trend: list[tuple[RunRecord, Outcome]]) -> None:
    latest = trend[-1][1]
    print(f"{test_id}  ({system} on {dataset})")
    edge = "no envelope edge" if latest.edge is None else f"envelope edge {latest.edge:.4g} {latest.boundary.unit}".rstrip()
    print(f"{latest.parameter}, more severe when {latest.worse}, {edge}; requirement: {latest.requirement}")
    rows = [("run", "commit", "date", "boundary", "verdict", "trials", "")]
    for run, outcome in trend:
        commit = (run.commit or "-") + ("+dirty" if run.dirty else "")
        trials = f"{len(outcome.trials)}" + (f" ({outcome.cached_trials} cached)" if outcome.cached_trials else "")
        notes = [f"name {run.name}"] if run.name else []
        if outcome.parameter != latest.parameter:
            notes.append(f"searched {outcome.parameter}")
        if outcome.regression:
            notes.append(f"regression: {outcome.regression}")
        rows.append((run.label, commit, _date(run, minutes=True), outcome.boundary.text(), verdict_text(outcome), trials, "; ".join(notes)))
    print_table(rows)


def print_table(rows: Sequence[Sequence[str]]) -> None:
    """``rows`` (the first one the heading) in left-aligned columns two spaces apart."""
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    for row in rows:
        print("  ".join(cell.ljust(width) for cell, width in zip(row, widths)).rstrip())


def verdict_text(outcome: Outcome) -> str:
    """The verdict pytest reported: a test the regression gate failed is ``failed (regressed)``
    (or ``failed (not compared)`` under ``--sal-compare-missing=fail``) even when its
    requirement held."""
    if not outcome.regression:
        return outcome.verdict
    return "failed (not compared)" if outcome.regression.startswith(NOT_COMPARED) else "failed (regressed)"


def _date(run: RunRecord, minutes: bool = False) -> str:
    try:
        created = datetime.fromisoformat(run.created)
    except ValueError:
        return run.created or "?"
    return created.strftime("%Y-%m-%d %H:%M" if minutes else "%Y-%m-%d")


def change_text(before: Outcome | None, now: Outcome) -> str:
    """The pass value's move since ``before``, with whether that is better or worse."""
    if before is None:
        return "first run"
    if before.parameter != now.parameter:
        return f"searched {before.parameter} before"
    old, new, unit = before.boundary.pass_value, now.boundary.pass_value, now.boundary.unit
    if old is None and new is None:
        return "unchanged (never passed)"
    if old is None:
        return "passes now (failed everywhere searched before)"
    if new is None:
        return "fails everywhere searched now (worse)"
    if old == new:
        return "unchanged"
    severer = new < old if now.worse == "lower" else new > old
    relative = f", {100 * (new - old) / abs(old):+.0f} %" if old else ""
    return f"pass {old:.4g} -> {new:.4g} {unit}".rstrip() + f"{relative} ({'better' if severer else 'worse'})"


def _file_part(test_id: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", test_id).strip("_")[:100] or "test"


# -- plot -------------------------------------------------------------------------------------


def history_figure(trend: list[tuple[RunRecord, Outcome]], *, title: str | None = None) -> Figure:
    """The boundary interval of each run as a vertical bar (pass end: dot, fail end: cross), the
    pass values joined by a line, and the envelope's edge dashed; y in the parameter's unit,
    logarithmic when the values span more than a decade. An unbracketed boundary is a triangle
    at its one end, pointing to where the boundary lies. Runs of another parameter than the
    latest run's are left out."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # matplotlib only when plotting
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter

    if not trend:
        raise SalError("nothing to plot: no run holds this test")
    latest = trend[-1][1]
    shown = [(run, o) for run, o in trend if o.parameter == latest.parameter]
    unit = latest.boundary.unit
    severe_down = latest.worse == "lower"
    fig = Figure(figsize=(max(7.0, min(14.0, 3.0 + 0.55 * len(shown))), 5.5), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    xs = list(range(len(shown)))
    values = []
    for x, (_, outcome) in zip(xs, shown):
        p, f = outcome.boundary.pass_value, outcome.boundary.fail_value
        values += [v for v in (p, f, outcome.edge) if v is not None]
        if p is not None and f is not None:
            ax.vlines(x, min(p, f), max(p, f), color=BAND_COLOUR, linewidth=9, alpha=0.35, zorder=2)
        if p is not None:
            marker = "o" if f is not None else ("v" if severe_down else "^")
            ax.plot(x, p, marker, color=VERDICT_COLOURS["passed"], markersize=7, zorder=4)
        if f is not None:
            marker = "X" if p is not None else ("^" if severe_down else "v")
            ax.plot(x, f, marker, color=VERDICT_COLOURS["failed"], markersize=7, zorder=4)
    passes = [math.nan if o.boundary.pass_value is None else o.boundary.pass_value for _, o in shown]
    if len(passes) > 1:  # broken where a run had no pass value
        ax.plot(xs, passes, color=VERDICT_COLOURS["passed"], linewidth=1.0, alpha=0.6, zorder=3)
    edges = [(x, o.edge) for x, (_, o) in zip(xs, shown) if o.edge is not None]
    if edges:
        ex, ey = zip(*edges)
        ax.plot([ex[0] - 0.4, *ex, ex[-1] + 0.4], [ey[0], *ey, ey[-1]], "--", color="0.25", linewidth=1.3, drawstyle="steps-mid", zorder=3)
    if values and min(values) > 0 and max(values) / min(values) > 10:
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))  # 1000, not 10^3
    # legend entries (proxies, so that each appears once)
    ax.plot([], [], color=BAND_COLOUR, linewidth=9, alpha=0.35, label="boundary interval")
    ax.plot([], [], "o", color=VERDICT_COLOURS["passed"], label="pass end (most severe pass)")
    ax.plot([], [], "X", color=VERDICT_COLOURS["failed"], label="fail end (mildest fail)")
    if any(o.boundary.pass_value is None or o.boundary.fail_value is None for _, o in shown):
        ax.plot([], [], "^", color="0.45", label="not bracketed: points to the boundary")
    if edges:
        ax.plot([], [], "--", color="0.25", label="envelope edge (requirement)")
    ax.set_xticks(xs, [f"{run.label}\n{run.commit or '-'}{'+' if run.dirty else ''}" for run, _ in shown], fontsize="small")
    for tick, (_, outcome) in zip(ax.get_xticklabels(), shown):
        tick.set_color(VERDICT_COLOURS.get(outcome.verdict, "0.2"))
    ax.set_xlim(-0.6, len(shown) - 0.4)
    ax.set_xlabel("run (tick colour: verdict at the edge, green passed / red failed / orange inconclusive)", fontsize="small")
    arrow = "\u2193" if severe_down else "\u2191"
    ax.set_ylabel(f"{latest.parameter}" + (f" [{unit}]" if unit else "") + f"   (more severe {arrow})")
    ax.set_title(title or f"{latest.test_id}\n{latest.system} on {latest.dataset}", fontsize="medium")
    ax.grid(True, axis="y", color="0.9", linewidth=0.8)
    fig.legend(loc="outside lower center", ncols=2, fontsize="small", frameon=False)
    return fig


def plot_history(trend: list[tuple[RunRecord, Outcome]], path: str | Path, *, title: str | None = None) -> Path:
    """Write ``history_figure`` as a PNG at ``path`` (atomically); return the path."""
    from pytest_sal.analysis.plots import save_png

    return save_png(history_figure(trend, title=title), path)
