"""The text reports over robustness outcomes, a terminal table and a Markdown summary for CI,
and the pieces of text (a test's status, its cells, its trials as rows) the HTML report shares.

Pure functions over a list of ``Outcome`` (no pytest here):

* ``summary_rows`` / ``terminal_table``: one row per test (short node id, system, parameter,
  the envelope, the boundary interval, trials, margin, change against the history, verdict).
* ``markdown_report`` / ``write_markdown``: headline counts, the table, and details (metrics at
  both ends of the bracket, the trials, contradictions, the reproduction line) for every test
  that failed, was flaky or regressed; GitHub-flavoured, for a CI job summary.

The HTML page (``pytest_sal.report.outcome_page``) and the metric plot (``pytest_sal.report.metric_plot``)
build on the pieces of text here.

Signs: ``margin`` and ``change`` count towards the severe side of the parameter, so ``+`` means
the system copes with more than the requirement asks (margin) or than it did before (change).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from pathlib import Path

from pytest_sal.engine.outcomes.outcome import Boundary, Outcome, Trial, failures_first
from pytest_sal.engine.outcomes.quantity import num, with_unit
from pytest_sal.history.gate import NOT_COMPARED
from pytest_sal.report.formatting import metric_text, metrics_text, short_id, signed, truncate_left, truncate_right
from sal_adapters.common.textfiles import atomic_write_text

__all__ = [
    "COLUMNS",
    "boundary_cell",
    "change_cell",
    "envelope_text",
    "headline",
    "markdown_report",
    "status",
    "summary_rows",
    "table_columns",
    "terminal_table",
    "trial_metric_names",
    "trial_rows",
    "trial_verdict",
    "write_markdown",
]

#: Table columns: (key in ``summary_rows``, header, alignment ``<``/``>``).
COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("test", "test", "<"),
    ("system", "system", "<"),
    ("parameter", "parameter", "<"),
    ("requirement", "requirement", "<"),
    ("boundary", "boundary", "<"),
    ("trials", "trials", ">"),
    ("confidence", "votes", "<"),
    ("margin", "margin", ">"),
    ("change", "change", ">"),
    ("verdict", "verdict", "<"),
)
#: Narrowest a column is squeezed to when the table is too wide, in turn: the first step
#: narrows all these columns together, the later ones (from where the step before left them)
#: the test id further, then parameter and system, then all (unlisted columns keep their width).
_MIN_WIDTHS: tuple[dict[str, int], ...] = (
    {"test": 24, "system": 8, "parameter": 16, "requirement": 11, "boundary": 14},
    {"test": 16, "system": 8, "parameter": 16, "requirement": 11, "boundary": 14},
    {"test": 16, "system": 6, "parameter": 12, "requirement": 11, "boundary": 14},
    {"test": 12, "system": 5, "parameter": 8, "requirement": 8, "boundary": 10},
)
#: How much of the narrowing each column takes (relative).
_SHARE = {"test": 3.0, "parameter": 1.5, "boundary": 1.5, "system": 1.0, "requirement": 1.0}
#: Columns left out, in turn, when the table cannot be narrowed enough.
_DROP_ORDER = ("confidence", "system", "change", "requirement", "parameter")
#: Columns whose end says most (test ids, ``(night>>fog).visibility_m``) lose their left end.
_LEFT_TRUNCATED = ("test", "parameter")
_SEP = "  "
#: Metrics shown in the trials tables, in order (others go to the details only through criteria).
SHOWN_METRICS = ("ate_rmse", "tracking_rate")
_VERDICT_TEXT = {"passed": "passed", "failed": "FAILED", "flaky": "FLAKY", "inconclusive": "INCONCLUSIVE", "regressed": "FAILED"}
#: verdicts that neither passed nor failed: counted apart in the headline (``flaky``: history before 0.2)
UNSETTLED = ("inconclusive", "flaky")


# ---------------------------------------------------------------- pieces of text


def status(outcome: Outcome) -> str:
    """``passed``, ``failed``, ``inconclusive`` (``flaky`` in older history) or ``regressed``
    (a regression outranks the verdict)."""
    return "regressed" if outcome.regression is not None else outcome.verdict


def envelope_text(outcome: Outcome) -> str:
    """The envelope of the requirement without the parameter: ``>= 25 m``; ``-`` without one."""
    return outcome.envelope or "-"


def boundary_cell(outcome: Outcome) -> str:
    """The boundary for a table cell (``Boundary.short_text``): ``14-16 m``, ``< 1 m (never
    failed)``; ``passed at 3 px`` for a single point."""
    return outcome.boundary.short_text(outcome.worse, single=outcome.termination == "single")


def boundary_shift(outcome: Outcome) -> float | None:
    """How far the boundary moved since ``previous``, towards the severe side (``+``: more robust).
    Midpoints when both are bracketed, else the pass ends, else the fail ends; ``None`` otherwise."""
    prev, cur = outcome.previous, outcome.boundary
    if prev is None:
        return None
    pairs = ((_midpoint(prev), _midpoint(cur)), (prev.pass_value, cur.pass_value), (prev.fail_value, cur.fail_value))
    for before, after in pairs:
        if before is not None and after is not None:
            delta = after - before
            return -delta if outcome.worse == "lower" else delta
    return None


def change_cell(outcome: Outcome) -> str:
    """``REGRESSED``, ``no baseline`` (``--sal-compare`` found nothing to compare with), the
    boundary's shift since the baseline, or ``-`` (not compared)."""
    not_compared = outcome.comparison.startswith(NOT_COMPARED)
    if outcome.regression is not None:
        return "NO BASELINE" if not_compared else "REGRESSED"
    if outcome.previous is None:
        return "no baseline" if not_compared else "-"
    shift = boundary_shift(outcome)
    return "changed" if shift is None else signed(shift, outcome.boundary.unit)


def trials_cell(outcome: Outcome) -> str:
    cached = outcome.cached_trials
    return f"{len(outcome.trials)} ({cached} cached)" if cached else str(len(outcome.trials))


def confidence_cell(outcome: Outcome) -> str:
    """The runs agreeing with the verdict at the edge, then at the pass and fail ends, short:
    ``3/3; 3/3 4/5`` (``1 run/trial`` for a deterministic system); a noisy system's
    confidence that ``p(edge) >= R``, and its runs: ``97 % sure (30 runs)``."""
    b = outcome.boundary
    if b.noisy and b.holds_at_edge is not None:
        return f"{100 * b.holds_at_edge:.3g} % sure ({b.runs} runs)"
    if all(len(t.runs) <= 1 for t in outcome.trials):
        return "1 run/trial"

    def share(t: Trial) -> str:
        return f"{t.agreeing}/{t.voting}"

    ends = [share(t) for t in outcome.end_trials() if t is not None and t is not outcome.trials[0]]
    return share(outcome.trials[0]) + (f"; {' '.join(ends)}" if ends else "")


def headline(outcomes: Sequence[Outcome]) -> str:
    """``3 robustness requirements: 2 passed, 1 failed`` (regressed and flaky counted apart)."""
    n = len(outcomes)
    passed = sum(o.passed for o in outcomes)
    unsettled = {verdict: sum(status(o) == verdict for o in outcomes) for verdict in UNSETTLED}
    regressed = sum(status(o) == "regressed" for o in outcomes)
    failed = n - passed - sum(unsettled.values())
    parts = [f"{passed} passed", f"{failed} failed" + (f" ({regressed} regressed)" if regressed else "")]
    parts += [f"{count} {verdict}" for verdict, count in unsettled.items() if count]
    noun = "robustness requirement" if n == 1 else "robustness requirements"
    return f"{n} {noun}: {', '.join(parts)}"


def trial_metric_names(criteria: list[tuple[str, str, float]]) -> list[str]:
    """Metrics for a trial's table row or line: ``SHOWN_METRICS`` and those of the
    ``criteria`` (``Outcome.criteria``), in that order."""
    return list(dict.fromkeys([*SHOWN_METRICS, *(name for name, _, _ in criteria)]))


def needs_details(outcome: Outcome) -> bool:
    return status(outcome) in ("failed", "regressed", *UNSETTLED)


def _midpoint(b: Boundary) -> float | None:
    return None if b.pass_value is None or b.fail_value is None else (b.pass_value + b.fail_value) / 2


# ---------------------------------------------------------------- table


def summary_rows(outcomes: Iterable[Outcome]) -> list[dict[str, str]]:
    """One dict of display strings per outcome, keyed by ``COLUMNS`` keys, with ``test_id`` (the
    full node id) and ``status`` (``passed``/``failed``/``flaky``/``regressed``) besides."""
    rows = []
    for o in outcomes:
        rows.append(
            {
                "test": short_id(o.test_id),
                "system": o.system,
                "parameter": o.parameter or "-",
                "requirement": envelope_text(o),
                "boundary": boundary_cell(o),
                "trials": trials_cell(o),
                "confidence": confidence_cell(o),
                "margin": signed(o.margin, o.boundary.unit),
                "change": change_cell(o),
                "verdict": _VERDICT_TEXT.get(status(o), status(o)),
                "test_id": o.test_id,
                "status": status(o),
            }
        )
    return rows


def table_columns(rows: list[dict[str, str]]) -> list[tuple[str, str, str]]:
    """``COLUMNS``, without "votes" when every test ran one run per trial (it would say nothing)."""
    quiet = all(r["confidence"] == "1 run/trial" for r in rows)
    return [c for c in COLUMNS if not (quiet and c[0] == "confidence")]


def terminal_table(outcomes: Iterable[Outcome], width: int = 120) -> list[str]:
    """The summary as lines of at most ``width`` characters (header, rule, one line per test:
    failed, flaky and regressed tests first).

    Columns fit their contents. When that is too wide, test ids lose their file, then the
    test, parameter, boundary, system and requirement columns give way, the test id most
    (marked ``…``: test ids and parameters lose their left end, the others their right end);
    when even their narrowest is too wide, the system, change, requirement and parameter
    columns are left out, in that order."""
    rows = summary_rows(failures_first(outcomes))
    shown = table_columns(rows)
    natural = {key: max([len(header)] + [len(r[key]) for r in rows]) for key, header, _ in shown}
    if sum(natural.values()) + len(_SEP) * (len(COLUMNS) - 1) > width:  # the tests' names say more than their files
        rows = [{**r, "test": r["test"].split("::", 1)[-1]} for r in rows]
        natural["test"] = max([len("test")] + [len(r["test"]) for r in rows])
    columns, widths = list(shown), dict(natural)
    for drop in (None, *_DROP_ORDER):
        columns = [c for c in columns if c[0] != drop]
        widths = {key: natural[key] for key, _, _ in columns}
        if any(_shrink(widths, mins, width - len(_SEP) * (len(columns) - 1)) for mins in _MIN_WIDTHS):
            break

    def line(cells: dict[str, str], header: bool = False) -> str:
        out = []
        for key, _, align in columns:
            text, w = cells[key], widths[key]
            text = truncate_left(text, w) if key in _LEFT_TRUNCATED and not header else truncate_right(text, w)
            out.append(f"{text:{align}{w}}")
        return _SEP.join(out).rstrip()

    lines = [line({key: header for key, header, _ in columns}, header=True)]
    lines.append(_SEP.join("-" * widths[key] for key, _, _ in columns))
    lines += [line(r) for r in rows]
    return [text[:width] for text in lines]


def _shrink(widths: dict[str, int], mins: dict[str, int], total: int) -> bool:
    """Narrow the columns in ``mins`` (not below it), each by its share of what is over its
    minimum, until the widths sum to ``total``; whether they do."""
    excess = sum(widths.values()) - total
    while excess > 0:
        room = {k: (widths[k] - m) / _SHARE[k] for k, m in mins.items() if k in widths and widths[k] > m}
        if not room:
            return False
        widths[max(room, key=lambda k: room[k])] -= 1
        excess -= 1
    return True


# ---------------------------------------------------------------- Markdown

_MD_SPECIAL = re.compile(r"([\\`*_\[\]<>|#~!])")


def md(text: str) -> str:
    """Plain Markdown text: punctuation that could format or form HTML is backslash-escaped."""
    return _MD_SPECIAL.sub(r"\\\1", str(text).replace("&", "&amp;")).replace("\n", " ")


def md_code(text: str) -> str:
    """An inline code span (safe in a table: ``|`` escaped) holding ``text`` literally."""
    text = str(text).replace("\n", " ").replace("|", "\\|")
    fence = "`" * (max((len(m) for m in re.findall(r"`+", text)), default=0) + 1)
    pad = " " if text.startswith("`") or text.endswith("`") else ""
    return f"{fence}{pad}{text}{pad}{fence}"


def _md_table(header: Sequence[str], rows: Iterable[Sequence[str]], align: Sequence[str]) -> list[str]:
    rule = ["---:" if a == ">" else "---" for a in align]
    return ["| " + " | ".join(r) + " |" for r in [list(header), rule, *map(list, rows)]]


def markdown_report(outcomes: Iterable[Outcome], *, title: str = "Robustness") -> str:
    """GitHub-flavoured Markdown: headline counts, the summary table, then a section for each
    test that failed, was flaky or regressed; those tests come first."""
    outcomes = failures_first(outcomes)
    lines = [f"## {md(title)}", "", f"**{md(headline(outcomes))}**", ""]
    if outcomes:
        rows = summary_rows(outcomes)
        columns = table_columns(rows)
        cells = [[md_code(r["test"]) if key == "test" else md(r[key]) for key, _, _ in columns] for r in rows]
        lines += _md_table([h for _, h, _ in columns], cells, [a for _, _, a in columns])
        lines += ["", "_margin and change: + towards the severe side (the system copes with more)_"]
        if any(c[0] == "confidence" for c in columns):
            lines += ["", "_votes: runs agreeing with the verdict at the envelope's edge; then at the pass and fail ends_"]
    for o in outcomes:
        if needs_details(o):
            lines += ["", *_md_details(o)]
    return "\n".join(lines).rstrip() + "\n"


def _md_details(o: Outcome) -> list[str]:
    unit = o.boundary.unit
    lines = [f"### {status(o).upper()}: {md_code(o.test_id)}", ""]
    lines.append(f"- **requirement**: {md_code(o.requirement)}")
    lines.append(f"- **system**: {md(o.system)}; **dataset**: {md(o.dataset)}")
    lines.append(f"- **boundary**: {md(o.boundary.text())}; **margin**: {md(signed(o.margin, unit))}")
    lines.append(f"- **search**: {len(o.trials)} trials, {o.runs} runs ({o.cached_trials} trials cached), stopped: {md(o.termination)}")
    lines.append(f"- **confidence**: {md(o.confidence())}")
    if o.previous is not None:
        lines.append(f"- **previous boundary**: {md(o.previous.text())}; **change**: {md(change_cell(o))}")
    if o.regression:
        lines.append(f"- **regression**: {md(o.regression)}")
    pass_trial, fail_trial = o.end_trials()
    for label, trial in (("last pass", pass_trial), ("first fail", fail_trial)):
        if trial is not None:
            lines.append(f"- **{label}** at {md(with_unit(trial.value, unit))}: {md(_metrics_summary(o, trial))}")
    if o.trials:
        header, rows = trial_rows(o, times=False)
        align = ["<", ">", "<", *[">"] * (len(header) - 5), "<", "<"]  # the metrics' columns right-aligned
        lines += ["", *_md_table([md(h) for h in header], [[md(c) for c in r] for r in rows], align)]
    if o.contradictions:
        lines += ["", "**contradictions** (a pass more severe than a fail):", ""]
        lines += [f"- {md(c)}" for c in o.contradictions]
    if o.reproduction:
        lines += ["", f"reproduce: {md_code(o.reproduction)}"]
    return lines


def trial_rows(o: Outcome, *, times: bool) -> tuple[list[str], list[list[str]]]:
    """The trials of ``o`` as a table's header and rows of text: #, value (the header with the
    unit), verdict, the metrics of ``trial_metric_names``, cached, the seconds spent when
    ``times``, the failed criteria."""
    names = trial_metric_names(o.criteria)
    unit = o.boundary.unit
    header = ["#", f"value [{unit}]" if unit else "value", "verdict", *names, "cached", *(["time"] if times else []), "failed criteria"]
    rows = [
        [
            str(i),
            num(t.value),
            trial_verdict(t),
            *(metric_text(n, t.metrics.get(n)) for n in names),
            "yes" if t.cached else "",
            *([f"{t.wall_time_s:.1f} s"] if times else []),
            "; ".join(t.failed),
        ]
        for i, t in enumerate(o.trials, 1)
    ]
    return header, rows


def trial_verdict(t: Trial) -> str:
    """``pass``, or ``fail (2 of 3 runs failed)`` when more than one run voted."""
    return ("pass" if t.passed else "fail") + (f" ({t.votes()})" if len(t.runs) > 1 else "")


def _metrics_summary(o: Outcome, t: Trial) -> str:
    text = metrics_text(t.metrics, trial_metric_names(o.criteria))
    return text + (f" (failed: {'; '.join(t.failed)})" if t.failed else "")


def write_markdown(outcomes: Iterable[Outcome], path: str | Path, *, title: str = "Robustness") -> Path:
    """Write ``markdown_report`` to ``path`` atomically; return the path."""
    return atomic_write_text(path, markdown_report(outcomes, title=title))
