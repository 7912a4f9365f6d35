"""The reliability plot of a noisy system's outcome (``Boundary.noisy``): the chance ``p`` that a
run holds the requirement against the searched parameter. The fitted curve with its band, every
run as a dot at ``p`` 1 (held) or 0 (failed), the required reliability ``R``, the interval and
one-sided bound of ``s_R`` and the envelope's edge with its required side shaded.
``pytest_sal.report.metric_plot`` draws it in place of the metric panels for such an outcome."""

from __future__ import annotations

import math
from collections import defaultdict

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from pytest_sal.analysis.plots import DPI, FIGSIZE
from pytest_sal.engine.outcomes.outcome import Boundary, Outcome
from pytest_sal.engine.outcomes.quantity import with_unit
from pytest_sal.report.formatting import short_id, truncate_left
from pytest_sal.report.outcome_report import boundary_cell, envelope_text, status

__all__ = ["JITTER", "reliability_figure", "run_points"]

# the colours of pytest_sal.report.metric_plot (pass, fail, boundary band, envelope edge)
PASS_COLOUR = "#2ca02c"
FAIL_COLOUR = "#d62728"
BAND_COLOUR = "#ff7f0e"
EDGE_COLOUR = "#1f77b4"
CURVE_COLOUR = "#6a3d9a"
BOUND_COLOUR = "#c44e00"
#: the largest vertical offset of a run's dot from 0 or 1 (repeated runs at a value fan out)
JITTER = 0.05
#: the offset between neighbouring dots of one value and result, while they fit within JITTER
JITTER_STEP = 0.02
#: the x axis shows the runs and the statistics, this share of their span wider on each side
#: (decades on a log axis), within the search range
PAD = 0.12


def reliability_figure(outcome: Outcome) -> Figure:
    """``p`` (0 to 1) against the parameter (log x when ``boundary.log_scale``): the fitted
    median curve of ``boundary.curve`` with its band at ``confidence`` shaded, each run that
    voted as a dot at its value (green at 1: held, red cross at 0: failed; abstained runs are
    left out), fanned out vertically by up to ``JITTER`` so repeated runs show, ``R`` as a
    dotted line, ``s_R`` on it, its interval as a band and its bound ``s_R/C`` as a line, and
    the envelope's edge dashed with its required side shaded. The x axis spans the runs and
    these values, within the search range."""
    b = outcome.boundary
    fig = Figure(figsize=FIGSIZE, dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    log_x = bool(b.log_scale)
    if log_x:
        ax.set_xscale("log")
    xlim = _x_limits(outcome, log_x)
    _draw_edge(ax, outcome, xlim)
    _draw_s_r(ax, b)
    _draw_curve(ax, b)
    _draw_runs(ax, outcome)
    ax.set_xlim(*xlim)
    ax.set_ylim(-0.1, 1.1)
    ax.set_yticks(np.linspace(0.0, 1.0, 6))
    ax.set_ylabel("p: chance that a run holds the requirement")
    ax.grid(True, color="0.9", linewidth=0.8)
    unit = b.unit
    arrow = "← more severe" if outcome.worse == "lower" else "more severe →"
    ax.set_xlabel(f"{outcome.parameter or 'value'}{f' [{unit}]' if unit else ''}    ({arrow})")
    fig.legend(loc="outside lower center", ncols=3, fontsize="x-small", framealpha=0.9)
    verdict = status(outcome)
    fig.suptitle(f"{truncate_left(short_id(outcome.test_id), 70)}\n{verdict}: {boundary_cell(outcome)}", fontsize="medium")
    return fig


def run_points(outcome: Outcome) -> list[tuple[float, bool, float]]:
    """Each run that voted as ``(value, held, y)``: ``y`` is 1 (held) or 0 (failed) offset by
    at most ``JITTER``, the runs of one value and result spread evenly around it (a trial
    without runs counts as one run of its verdict)."""
    groups: dict[tuple[float, bool], int] = defaultdict(int)
    for t in outcome.trials:
        for run in t.runs or [{"passed": t.passed}]:
            if not run.get("abstained"):
                groups[(t.value, bool(run.get("passed", t.passed)))] += 1
    points = []
    for (value, held), n in groups.items():
        step = min(JITTER_STEP, 2 * JITTER / (n - 1)) if n > 1 else 0.0
        points += [(value, held, float(held) + (i - (n - 1) / 2) * step) for i in range(n)]
    return points


def _x_limits(outcome: Outcome, log_x: bool) -> tuple[float, float]:
    b = outcome.boundary
    stats = [b.estimate, b.bound, b.s50, *(b.interval or ()), *(b.s50_interval or ()), *(b.transition or ())]
    xs = [t.value for t in outcome.trials] + [v for v in (outcome.edge, *stats) if v is not None and math.isfinite(v)]
    ends = sorted(b.search_range) if b.search_range else None
    if log_x:
        xs = [x for x in xs if x > 0]
    if not xs:
        if ends and ends[0] < ends[1] and (ends[0] > 0 or not log_x):
            return (ends[0], ends[1])
        return (0.1, 1.0) if log_x else (0.0, 1.0)
    lo, hi = min(xs), max(xs)
    if log_x:
        pad = max((hi / lo) ** PAD, 1.25)
        lo, hi = lo / pad, hi * pad
    else:
        pad = PAD * (hi - lo) if hi > lo else max(abs(lo) * 0.1, 1.0)
        lo, hi = lo - pad, hi + pad
    if ends:  # the curve ends there; the padding is not stretched past it
        lo, hi = max(lo, min(ends[0], min(xs))), min(hi, max(ends[1], max(xs)))
    return (lo, hi)


def _draw_edge(ax: Axes, outcome: Outcome, xlim: tuple[float, float]) -> None:
    """The envelope's edge and its required side, as ``metric_plot`` draws them."""
    edge, b = outcome.edge, outcome.boundary
    if edge is None or not xlim[0] <= edge <= xlim[1]:
        return
    mild_end = xlim[1] if outcome.worse == "lower" else xlim[0]
    ax.axvspan(*sorted((edge, mild_end)), color=EDGE_COLOUR, alpha=0.08, linewidth=0, label="required (envelope)", gid="required")
    sure = ""
    if b.holds_at_edge is not None and b.reliability is not None:
        sure = f"; p >= {100 * b.reliability:.4g} % there: {100 * b.holds_at_edge:.3g} % sure"
    ax.axvline(edge, color=EDGE_COLOUR, linestyle="--", linewidth=1.3, label=f"envelope edge {envelope_text(outcome)}{sure}", gid="edge")


def _draw_s_r(ax: Axes, b: Boundary) -> None:
    """``R`` as a dotted line, the interval of ``s_R`` as a band, its bound as a line, and the
    estimate as a diamond on ``R``."""
    assert b.reliability is not None
    r, c = f"{100 * b.reliability:.4g}", f"{100 * (b.confidence or 0):.4g}"
    ax.axhline(b.reliability, color="0.35", linestyle=":", linewidth=1.3, label=f"R = {r} % (required reliability)", gid="reliability")
    if b.interval:
        low, high = sorted(b.interval)
        label = f"s{r} interval at {c} %: {with_unit(low, b.unit)} to {with_unit(high, b.unit)}"
        ax.axvspan(low, high, color=BAND_COLOUR, alpha=0.22, linewidth=0, label=label, gid="interval")
    if b.bound is not None:
        ax.axvline(b.bound, color=BOUND_COLOUR, linewidth=1.6, label=f"bound s{r}/{c} {with_unit(b.bound, b.unit)}", gid="bound")
    if b.estimate is not None:
        label = f"s{r} {with_unit(b.estimate, b.unit)} (median)"
        ax.plot([b.estimate], [b.reliability], "D", color=BOUND_COLOUR, markersize=7, zorder=5, label=label, gid="estimate")


def _draw_curve(ax: Axes, b: Boundary) -> None:
    """The fitted median ``p`` and its band, as the curve's rows give them."""
    if not b.curve:
        return
    x, median, low, high = np.asarray(b.curve, dtype=float).T
    band = f"{100 * b.confidence:.4g} % band" if b.confidence is not None else "band"
    ax.fill_between(x, low, high, color=CURVE_COLOUR, alpha=0.18, linewidth=0, label=f"fitted p, {band}", gid="band")
    ax.plot(x, median, color=CURVE_COLOUR, linewidth=2.0, label="fitted p (median)", gid="curve", zorder=3)


def _draw_runs(ax: Axes, outcome: Outcome) -> None:
    points = run_points(outcome)
    for held, colour, marker, name in ((True, PASS_COLOUR, "o", "held"), (False, FAIL_COLOUR, "X", "failed")):
        xy = np.array([(x, y) for x, h, y in points if h == held], dtype=float).reshape(-1, 2)
        if len(xy):
            ax.scatter(
                xy[:, 0],
                xy[:, 1],
                s=30,
                color=colour,
                marker=marker,
                alpha=0.8,
                linewidths=0,
                zorder=4,
                label=f"run {name} ({len(xy)})",
                gid=f"runs {name}",
            )
