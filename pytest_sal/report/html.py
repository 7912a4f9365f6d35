"""The HTML robustness report and its metric-against-parameter plot.

``write_html_report`` writes one self-contained page (``index.html``: inline CSS, no script, no
network resources) into a folder, with what it shows beside it under ``assets/``: per test a
metric plot (``metric_plot``) and copies of the trials' artifacts (example frames, trajectory
plots), referenced by relative paths so the folder can be moved or uploaded as a CI artifact.
"""

from __future__ import annotations

import hashlib
import html
import math
import re
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from urllib.parse import quote

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.transforms import blended_transform_factory

from pytest_sal.analysis.plots import DPI, FIGSIZE, save_png
from pytest_sal.engine.outcome import Outcome, Trial, failures_first
from pytest_sal.engine.quantity import num, with_unit
from pytest_sal.engine.requirements import METRICS
from pytest_sal.report.formatting import metric_text, metrics_text, short_id, signed, truncate_left
from pytest_sal.report.outcome_report import (
    boundary_cell,
    change_cell,
    envelope_text,
    headline,
    status,
    summary_rows,
    table_columns,
    trial_metric_names,
    trial_verdict,
)
from sal_adapters.atomic import Replacement, copy_file
from sal_adapters.textfiles import atomic_write_text

__all__ = ["REPORT_CSS", "asset_src", "esc", "html_page", "metric_figure", "metric_plot", "page_folder", "write_html_report"]

PASS_COLOUR = "#2ca02c"
FAIL_COLOUR = "#d62728"
BAND_COLOUR = "#ff7f0e"
EDGE_COLOUR = "#1f77b4"
#: most metric panels in one plot
MAX_PANELS = 3
#: trials spanning this ratio (and all positive) get a log x axis; metrics too (not rates)
LOG_SPAN = 100.0


# ---------------------------------------------------------------- plot


def metric_figure(outcome: Outcome) -> Figure:
    """The criteria's metrics (else ATE and tracking rate) against the parameter value, one panel
    each: a marker per trial (green pass, red cross fail, a triangle at the
    top where the metric is missing), the criterion threshold, the boundary interval as a band,
    the previous boundary hatched, the envelope's edge as a dashed line with its required side
    shaded. Log x when the trials
    span two decades or more."""
    names = _plotted_metrics(outcome)
    fig = Figure(figsize=FIGSIZE, dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(max(len(names), 1), 1, sharex=True, squeeze=False)[:, 0]
    values = [t.value for t in outcome.trials]
    log_x = bool(values) and min(values) > 0 and max(values) / min(values) >= LOG_SPAN
    xlim = _x_limits(outcome, log_x)
    thresholds = {name: (op, value) for name, op, value in outcome.criteria}
    for i, (ax, name) in enumerate(zip(axes, names or ["passed"])):
        if log_x:
            ax.set_xscale("log")
        _draw_envelope(ax, outcome, xlim, first=i == 0)
        _draw_trials(ax, outcome, name, first=i == 0)
        if name in thresholds:
            op, value = thresholds[name]
            ax.axhline(value, color="0.35", linestyle=":", linewidth=1.2, label=f"{name} {op} {value:g}{_unit_suffix(name)}")
        _y_range(ax, outcome, name, thresholds[name][1] if name in thresholds else None)
        ax.set_ylabel(_metric_label(name))
        ax.grid(True, color="0.9", linewidth=0.8)
        ax.set_xlim(*xlim)
        ax.legend(loc="best", fontsize="x-small", framealpha=0.9)
    unit = outcome.boundary.unit
    arrow = "← more severe" if outcome.worse == "lower" else "more severe →"
    axes[-1].set_xlabel(f"{outcome.parameter or 'value'}{f' [{unit}]' if unit else ''}    ({arrow})")
    verdict = status(outcome)
    fig.suptitle(f"{truncate_left(short_id(outcome.test_id), 70)}\n{verdict}: boundary {boundary_cell(outcome)}", fontsize="medium")
    return fig


def metric_plot(outcome: Outcome, path: str | Path) -> Path:
    """Write ``metric_figure(outcome)`` as a PNG at ``path`` (800 x 600 px); return the path."""
    return save_png(metric_figure(outcome), path)


def _plotted_metrics(outcome: Outcome) -> list[str]:
    def present(name: str) -> bool:
        return any(_finite(t.metrics.get(name)) is not None for t in outcome.trials)

    names = list(dict.fromkeys(name for name, _, _ in outcome.criteria))
    if not names:
        names = [n for n in ("ate_rmse", "tracking_rate") if present(n)]
    return names[:MAX_PANELS]


def _finite(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return None
    return float(value)


def _x_limits(outcome: Outcome, log_x: bool) -> tuple[float, float]:
    b, prev = outcome.boundary, outcome.previous
    ends = (outcome.edge, b.pass_value, b.fail_value, *((prev.pass_value, prev.fail_value) if prev else ()))
    xs = [t.value for t in outcome.trials] + [v for v in ends if v is not None]
    if log_x:
        xs = [x for x in xs if x > 0]
    if not xs:
        return (0.0, 1.0)
    lo, hi = min(xs), max(xs)
    if log_x:
        pad = (hi / lo) ** 0.05
        return (lo / pad, hi * pad)
    pad = 0.05 * (hi - lo) if hi > lo else max(abs(lo) * 0.1, 1.0)
    return (lo - pad, hi + pad)


def _draw_envelope(ax: Axes, outcome: Outcome, xlim: tuple[float, float], *, first: bool) -> None:
    b = outcome.boundary
    if b.pass_value is not None and b.fail_value is not None:
        lo, hi = sorted((b.pass_value, b.fail_value))
        ax.axvspan(lo, hi, color=BAND_COLOUR, alpha=0.25, linewidth=0, label=f"boundary {b.text()}" if first else None)
    prev = outcome.previous
    if prev is not None and prev.pass_value is not None and prev.fail_value is not None:
        lo, hi = sorted((prev.pass_value, prev.fail_value))
        label = f"previous boundary {prev.text()}" if first else None
        ax.axvspan(lo, hi, facecolor="none", edgecolor="0.55", hatch="///", linewidth=0, label=label)
    edge = outcome.edge
    if edge is not None and xlim[0] <= edge <= xlim[1]:
        mild_end = xlim[1] if outcome.worse == "lower" else xlim[0]
        ax.axvspan(*sorted((edge, mild_end)), color=EDGE_COLOUR, alpha=0.08, linewidth=0, label="required (envelope)" if first else None)
        label = f"envelope edge {envelope_text(outcome)}" if first else None
        ax.axvline(edge, color=EDGE_COLOUR, linestyle="--", linewidth=1.3, label=label)


def _draw_trials(ax: Axes, outcome: Outcome, name: str, *, first: bool) -> None:
    def y_of(t: Trial) -> float | None:
        return float(t.passed) if name == "passed" else _finite(t.metrics.get(name))

    shown = sorted((t.value, y) for t in outcome.trials if (y := y_of(t)) is not None)
    if len(shown) > 1:
        ax.plot(*np.array(shown).T, color="0.6", linewidth=1.0, zorder=2)
    top = blended_transform_factory(ax.transData, ax.transAxes)
    labelled: set[str] = set()
    for t in outcome.trials:
        colour = PASS_COLOUR if t.passed else FAIL_COLOUR
        y = y_of(t)
        key = ("pass" if t.passed else "fail") + (" (no value)" if y is None else "")
        label = key if first and key not in labelled else None
        labelled.add(key)
        style: dict[str, object] = {"color": colour, "markersize": 8, "linestyle": "none", "zorder": 4, "label": label}
        if y is None:
            ax.plot([t.value], [0.96], marker="v", transform=top, clip_on=False, **style)  # type: ignore[arg-type]
        else:
            ax.plot([t.value], [y], marker="o" if t.passed else "X", **style)  # type: ignore[arg-type]


def _y_range(ax: Axes, outcome: Outcome, name: str, threshold: float | None) -> None:
    """Rates 0..1; metrics spanning two decades log; other non-negative metrics from 0 to
    above both the data and the threshold."""
    if name in ("tracking_rate", "passed"):
        ax.set_ylim(-0.05, 1.1)
        return
    ys = [y for t in outcome.trials if (y := _finite(t.metrics.get(name))) is not None]
    if ys and min(ys) > 0 and max(ys) / min(ys) >= LOG_SPAN:
        ax.set_yscale("log")
    elif all(y >= 0 for y in ys):
        top = max([*ys, 1.5 * threshold if threshold is not None and threshold > 0 else 0.0]) or 1.0
        ax.set_ylim(0.0, top * 1.08)


def _metric_label(name: str) -> str:
    unit = METRICS[name].unit if name in METRICS else ""
    return f"{name} [{unit}]" if unit else name


def _unit_suffix(name: str) -> str:
    unit = METRICS[name].unit if name in METRICS else ""
    return f" {unit}" if unit else ""


# ---------------------------------------------------------------- page


@contextmanager
def page_folder(directory: Path) -> Iterator[Path]:
    """``with page_folder(directory) as folder:`` write ``index.html`` and ``assets/`` into
    ``folder`` (a staging folder, ``assets/`` already made); when the block ends without error
    both replace those in ``directory`` together, even an empty ``assets/`` (an earlier page's
    pictures go); the other files in ``directory`` stay."""
    with Replacement() as outputs:
        folder = outputs.entries(directory)
        (folder / "assets").mkdir()
        yield folder


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
        plot = metric_plot(o, assets / "metrics.png")
        parts.append(
            f"<img class='plot' src='{asset_src(plot, directory)}' alt='{esc(o.parameter)} against the metrics' width='800' height='600'>"
        )
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


def _trials_table(o: Outcome) -> str:
    names = trial_metric_names(o.criteria)
    unit = o.boundary.unit
    head = ["#", f"value [{unit}]" if unit else "value", "verdict", *names, "cached", "time", "failed criteria"]
    num_cols = {0, 1, *range(3, 3 + len(names)), 4 + len(names)}  # #, value, metrics, time
    rows = []
    for i, t in enumerate(o.trials, 1):
        verdict = trial_verdict(t)
        cells = [str(i), num(t.value), verdict, *(metric_text(n, t.metrics.get(n)) for n in names)]
        cells += ["yes" if t.cached else "", f"{t.wall_time_s:.1f} s", "; ".join(t.failed)]
        tds = "".join(f"<td{_num_cls(j in num_cols)}>{esc(c)}</td>" for j, c in enumerate(cells))
        rows.append(f"<tr class='{'passed' if t.passed else 'failed'}'>{tds}</tr>")
    ths = "".join(f"<th{_num_cls(j in num_cols)}>{esc(h)}</th>" for j, h in enumerate(head))
    return f"<table class='trials'><thead><tr>{ths}</tr></thead><tbody>{''.join(rows)}</tbody></table>"


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


def asset_src(path: Path, directory: Path) -> str:
    """``path`` relative to the page's ``directory``, URL-quoted and escaped for an attribute."""
    return esc(quote(path.relative_to(directory).as_posix()))


def esc(text: object) -> str:
    """``text`` escaped for HTML text and attribute values."""
    return html.escape(str(text), quote=True)


def _num_cls(numeric: bool) -> str:
    return " class='num'" if numeric else ""


def _badge(state: str) -> str:
    return f"<span class='badge {esc(state)}'>{esc(state)}</span>"


def html_page(title: str, css: str, body: str) -> str:
    """A whole HTML document: UTF-8, a responsive viewport, ``title`` (escaped here), ``css``
    in a style element and ``body`` (HTML) as the body."""
    return _DOCUMENT.format(title=esc(title), css=css, body=body)


_DOCUMENT = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{title}</title>
<style>{css}</style>
</head>
<body>
{body}
</body>
</html>
"""

_BODY = """<header><h1>{title}</h1><p class="headline">{headline}</p>{where}</header>
<table class="summary"><thead><tr>{head}</tr></thead>
<tbody>
{rows}
</tbody></table>
<p class="dim">margin and change: + towards the severe side (the system copes with more)</p>
{sections}"""

REPORT_CSS = """
body { font: 14px/1.45 system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; color: #1f2328;
  margin: 0 auto; padding: 1.5em 2em 4em; max-width: 1200px; }
h1 { margin: 0 0 .2em; font-size: 1.6em; }
h2 { font-size: 1.15em; margin: 0 0 .6em; display: flex; align-items: center; gap: .6em; }
h3 { font-size: 1em; margin: 1.2em 0 .4em; }
.headline { font-size: 1.1em; font-weight: 600; margin: .2em 0 1em; }
.where, .dim { color: #656d76; }
code { font: 12.5px ui-monospace, SFMono-Regular, Menlo, Consolas, monospace; background: #f3f4f6;
  padding: .1em .35em; border-radius: 4px; word-break: break-all; }
table { border-collapse: collapse; margin: .5em 0 1em; }
th, td { padding: .3em .7em; border-bottom: 1px solid #e5e7eb; text-align: left; vertical-align: top; }
th { background: #f6f8fa; font-weight: 600; white-space: nowrap; }
td.num, th.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
table.summary td:first-child { max-width: 28em; overflow-wrap: anywhere; }
table.summary a { color: inherit; }
table.trials tr.failed td:nth-child(3) { color: #b42318; font-weight: 600; }
table.trials tr.passed td:nth-child(3) { color: #1a7f37; }
section.test { border: 1px solid #d0d7de; border-left: 6px solid #1a7f37; border-radius: 6px;
  padding: 1em 1.3em; margin: 1.6em 0; }
section.test.failed, section.test.regressed { border-left-color: #cf222e; }
section.test.flaky { border-left-color: #bf8700; }
.id { font-family: ui-monospace, SFMono-Regular, Menlo, Consolas, monospace; font-weight: 500; overflow-wrap: anywhere; }
dl { display: grid; grid-template-columns: max-content 1fr; gap: .25em 1em; margin: 0 0 1em; }
dt { color: #656d76; }
dd { margin: 0; }
.bad { color: #b42318; font-weight: 600; }
.badge { display: inline-block; padding: .1em .6em; border-radius: 1em; font-size: 12px; font-weight: 700;
  text-transform: uppercase; letter-spacing: .03em; color: #fff; background: #1a7f37; white-space: nowrap; }
.badge.failed { background: #cf222e; }
.badge.regressed { background: #8250df; }
.badge.flaky { background: #bf8700; }
img.plot { display: block; max-width: 100%; height: auto; border: 1px solid #e5e7eb; border-radius: 4px; }
.gallery { display: flex; flex-wrap: wrap; gap: .8em; }
.gallery figure { margin: 0; border: 3px solid #1a7f37; border-radius: 5px; padding: 3px; background: #fff; }
.gallery figure.failed { border-color: #cf222e; }
.gallery img { display: block; width: 220px; height: auto; }
.gallery.trajectory img { width: 320px; }
.gallery figcaption { text-align: center; font-size: 12.5px; padding-top: .2em; }
.gallery .none { width: 220px; height: 80px; display: flex; align-items: center; justify-content: center;
  color: #656d76; background: #f6f8fa; font-size: 12px; }
"""
