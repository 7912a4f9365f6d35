"""The metric-against-parameter plot of one outcome: per metric a panel of the trials' values
against the searched parameter, with the criterion's threshold, the boundary interval as a band,
the previous boundary hatched and the envelope's edge with its required side shaded; for a noisy
system's outcome (a statistical boundary) the reliability plot (``reliability_plot``) instead.
The HTML report, the pytest-html rows and ``sal boundary`` show it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.transforms import blended_transform_factory

from pytest_sal.analysis.plots import DPI, FIGSIZE, save_png
from pytest_sal.engine.outcomes.outcome import Outcome, Trial
from pytest_sal.engine.requirements import METRICS
from pytest_sal.report.formatting import short_id, truncate_left
from pytest_sal.report.outcome_report import boundary_cell, envelope_text, status
from pytest_sal.report.reliability_plot import reliability_figure

__all__ = ["metric_figure", "metric_plot"]

PASS_COLOUR = "#2ca02c"
FAIL_COLOUR = "#d62728"
BAND_COLOUR = "#ff7f0e"
EDGE_COLOUR = "#1f77b4"
#: most metric panels in one plot
MAX_PANELS = 3
#: trials spanning this ratio (and all positive) get a log x axis; metrics too (not rates)
LOG_SPAN = 100.0


def metric_figure(outcome: Outcome) -> Figure:
    """The criteria's metrics (else ATE and tracking rate) against the parameter value, one panel
    each: a marker per trial (green pass, red cross fail, a triangle at the
    top where the metric is missing), the criterion threshold, the boundary interval as a band,
    the previous boundary hatched, the envelope's edge as a dashed line with its required side
    shaded. Log x when the trials
    span two decades or more. A noisy system's outcome (``boundary.noisy``) gets
    ``reliability_figure`` instead: the chance that a run holds the requirement, fitted."""
    if outcome.boundary.noisy:
        return reliability_figure(outcome)
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
