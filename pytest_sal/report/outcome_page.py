"""The HTML report of robustness outcomes (``--sal-report-html``): one page with the summary
table and, per test, its facts, the metric plot (``pytest_sal.report.metric_plot``), the trials
and copies of their artifacts (example frames, trajectory plots) under ``assets/``, referenced by
relative paths so the folder can be moved or uploaded as a CI artifact (``html_page``).

Importing this module is light (the plugin imports it when the session ends, with or without
``--sal-report-html``): matplotlib loads with ``metric_plot`` when the first plot is drawn."""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Iterable, Sequence
from pathlib import Path

from pytest_sal.engine.outcomes.outcome import Boundary, Outcome, failures_first
from pytest_sal.engine.outcomes.quantity import with_unit
from pytest_sal.report.formatting import metrics_text, short_id, signed
from pytest_sal.report.html_page import REPORT_CSS, asset_src, esc, html_page, page_folder
from pytest_sal.report.outcome_report import (
    change_cell,
    headline,
    status,
    summary_rows,
    table_columns,
    trial_metric_names,
    trial_rows,
    trial_verdict,
)
from sal_adapters.common.atomic import copy_file
from sal_adapters.common.textfiles import atomic_write_text

__all__ = ["write_html_report"]


def write_html_report(outcomes: Iterable[Outcome], directory: str | Path, *, title: str = "Robustness report") -> Path:
    """Write ``index.html`` and ``assets/`` into ``directory`` (replacing both together);
    return the page's path. Failed, flaky and regressed tests come first."""
    with page_folder(Path(directory)) as folder:
        _write_page(failures_first(outcomes), folder, title)
    return Path(directory) / "index.html"


def _write_page(outcomes: list[Outcome], directory: Path, title: str) -> None:
    slugs = _slugs(outcomes)
    sections = [_section(o, slug, directory) for o, slug in zip(outcomes, slugs)]
    rows = summary_rows(outcomes)
    columns = table_columns(rows)
    head = "".join(f"<th{_num_cls(align == '>')}>{esc(h)}</th>" for _, h, align in columns)
    body = []
    for row, slug in zip(rows, slugs):
        cells = []
        for key, _, align in columns:
            text = esc(row[key])
            if key == "test":
                text = f"<a href='#{slug}' title='{esc(row['test_id'])}'>{text}</a>"
            elif key == "verdict":
                text = _badge(row["status"])
            cells.append(f"<td{_num_cls(align == '>')}>{text}</td>")
        body.append(f"<tr class='{row['status']}'>{''.join(cells)}</tr>")
    where = sorted({" on ".join(x for x in (o.commit, o.machine) if x) for o in outcomes if o.commit or o.machine})
    page = html_page(
        title,
        REPORT_CSS,
        _BODY.format(
            title=esc(title),
            headline=esc(headline(outcomes)),
            where=f"<p class='where'>{esc(', '.join(where))}</p>" if where else "",
            head=head,
            rows="\n".join(body),
            sections="\n".join(sections),
        ),
    )
    atomic_write_text(directory / "index.html", page)


def _section(o: Outcome, slug: str, directory: Path) -> str:
    assets = directory / "assets" / slug
    unit = o.boundary.unit
    facts = [
        ("requirement", f"<code>{esc(o.requirement)}</code>"),
        ("system", esc(o.system)),
        ("dataset", esc(o.dataset)),
        ("boundary", f"{esc(o.boundary.text())} <span class='dim'>({esc(o.termination)})</span>"),
        ("margin", esc(signed(o.margin, unit))),
        ("confidence", f"{esc(o.confidence())} <span class='dim'>({len(o.trials)} trials, {o.runs} runs)</span>"),
    ]
    if o.boundary.noisy:
        facts.append(("reliability curve", esc(_reliability_text(o.boundary))))
    if o.previous is not None:
        facts.append(("previous", f"{esc(o.previous.text())} <span class='dim'>(change {esc(change_cell(o))})</span>"))
    if o.regression:
        facts.append(("regression", f"<span class='bad'>{esc(o.regression)}</span>"))
    for label, trial in zip(("last pass", "first fail"), o.end_trials()):
        if trial is not None:
            metrics = metrics_text(trial.metrics, trial_metric_names(o.criteria))
            facts.append((label, f"{esc(with_unit(trial.value, unit))}: {esc(metrics)}"))
    if o.reproduction:
        facts.append(("reproduce", f"<code>{esc(o.reproduction)}</code>"))
    parts = [
        f"<section id='{slug}' class='test {status(o)}'>",
        f"<h2>{_badge(status(o))} <span class='id'>{esc(o.test_id)}</span></h2>",
        "<dl>" + "".join(f"<dt>{esc(k)}</dt><dd>{v}</dd>" for k, v in facts) + "</dl>",
    ]
    if o.trials:
        from pytest_sal.report.metric_plot import metric_plot  # matplotlib: only when there is a plot to draw

        plot = metric_plot(o, assets / "metrics.png")
        shows = f"the chance that a run holds against {o.parameter}" if o.boundary.noisy else f"{o.parameter} against the metrics"
        parts.append(f"<img class='plot' src='{asset_src(plot, directory)}' alt='{esc(shows)}' width='800' height='600'>")
        parts.append(_trials_table(o))
    if o.contradictions:
        items = "".join(f"<li>{esc(c)}</li>" for c in o.contradictions)
        parts.append(f"<h3>Contradictions</h3><p class='dim'>a pass more severe than a fail</p><ul>{items}</ul>")
    for kind, heading in (("frame", "Example frames"), ("trajectory", "Trajectories")):
        figures = _artifact_figures(o, kind, assets, directory)
        if figures:
            parts.append(f"<h3>{heading}</h3><div class='gallery {kind}'>{''.join(figures)}</div>")
    parts.append("</section>")
    return "\n".join(parts)


def _reliability_text(b: Boundary) -> str:
    """A noisy system's fitted numbers: ``s80 19.68 m (90 % interval 14.72 m to 23.24 m), bound
    s80/90 21.94 m; s50 18.1 m (90 % interval beyond 1 m to 21.2 m); p falls from 20.55 m to
    18.01 m (10 % to 90 % of its drop)`` (a value at an end of the search range as ``beyond`` or
    ``before`` it)."""
    r, c = f"{100 * (b.reliability or 0):.4g}", f"{100 * (b.confidence or 0):.4g}"

    def value(v: float | None) -> str:
        if v is not None and b.search_range:
            for word, end in zip(("before", "beyond"), b.search_range):
                if math.isclose(v, end, rel_tol=1e-9, abs_tol=1e-12):
                    return f"{word} {with_unit(end, b.unit)}"
        return with_unit(v, b.unit)

    def interval(ends: list[float] | None) -> str:
        return f" ({c} % interval {value(min(ends))} to {value(max(ends))})" if ends else ""

    parts = [f"s{r} {value(b.estimate)}{interval(b.interval)}, bound s{r}/{c} {value(b.bound)}"]
    if r != "50":
        parts.append(f"s50 {value(b.s50)}{interval(b.s50_interval)}")
    if b.transition:
        parts.append(f"p falls from {value(b.transition[0])} to {value(b.transition[1])} (10 % to 90 % of its drop)")
    return "; ".join(parts)


def _trials_table(o: Outcome) -> str:
    head, rows = trial_rows(o, times=True)
    metrics = len(head) - 6  # the columns #, value, verdict, cached, time and failed criteria besides
    num_cols = {0, 1, *range(3, 3 + metrics), 4 + metrics}  # #, value, metrics, time
    body = []
    for t, cells in zip(o.trials, rows):
        tds = "".join(f"<td{_num_cls(j in num_cols)}>{esc(c)}</td>" for j, c in enumerate(cells))
        body.append(f"<tr class='{'passed' if t.passed else 'failed'}'>{tds}</tr>")
    ths = "".join(f"<th{_num_cls(j in num_cols)}>{esc(h)}</th>" for j, h in enumerate(head))
    return f"<table class='trials'><thead><tr>{ths}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _artifact_figures(o: Outcome, kind: str, assets: Path, directory: Path) -> list[str]:
    """Copy each trial's ``kind`` artifact into ``assets`` (once per file) and return <figure>s,
    mild to severe."""
    order = sorted(enumerate(o.trials), key=lambda it: (it[1].value if o.worse != "lower" else -it[1].value, it[0]))
    seen: set[str] = set()
    figures = []
    unit = o.boundary.unit
    for index, t in order:
        source = t.artifacts.get(kind)
        if not source or source in seen:
            continue
        seen.add(source)
        caption = f"{with_unit(t.value, unit)}: {trial_verdict(t)}"
        cls = "passed" if t.passed else "failed"
        src = Path(source)
        if not src.is_file():
            figures.append(
                f"<figure class='{cls} missing'><div class='none'>missing: {esc(src.name)}</div><figcaption>{esc(caption)}</figcaption></figure>"
            )
            continue
        target = assets / f"{kind}-{index + 1:02d}{src.suffix.lower() or '.png'}"
        copy_file(src, target)
        rel = asset_src(target, directory)
        figures.append(
            f"<figure class='{cls}'><a href='{rel}'><img src='{rel}' alt='{esc(kind)} at {esc(caption)}' loading='lazy'></a>"
            f"<figcaption>{esc(caption)}</figcaption></figure>"
        )
    return figures


def _slugs(outcomes: Sequence[Outcome]) -> list[str]:
    """An anchor and folder name per outcome: readable, file-system safe, unique."""
    slugs = []
    for i, o in enumerate(outcomes):
        stem = re.sub(r"[^A-Za-z0-9._-]+", "-", short_id(o.test_id)).strip("-.")[-60:] or "test"
        digest = hashlib.sha1(f"{i}:{o.test_id}".encode()).hexdigest()[:8]
        slugs.append(f"t-{stem}-{digest}")
    return slugs


def _num_cls(numeric: bool) -> str:
    return " class='num'" if numeric else ""


def _badge(state: str) -> str:
    return f"<span class='badge {esc(state)}'>{esc(state)}</span>"


_BODY = """<header><h1>{title}</h1><p class="headline">{headline}</p>{where}</header>
<table class="summary"><thead><tr>{head}</tr></thead>
<tbody>
{rows}
</tbody></table>
<p class="dim">margin and change: + towards the severe side (the system copes with more)</p>
{sections}"""
