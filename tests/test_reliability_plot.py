"""The reliability plot of a noisy system's outcome: the fitted curve, its band, the runs, R, the
s_R interval and bound and the envelope's edge where the boundary says; the metric plot, the
HTML report and the pytest-html rows show it."""

from __future__ import annotations

import base64
import re
from collections import Counter
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from pytest_sal.engine.outcomes.outcome import Boundary, Outcome, Trial
from pytest_sal.html_extras import outcome_html
from pytest_sal.report.metric_plot import metric_figure, metric_plot
from pytest_sal.report.outcome_page import write_html_report
from pytest_sal.report.reliability_plot import JITTER, reliability_figure, run_points

HELD, FAILED, ABSTAINED = {"passed": True, "abstained": False}, {"passed": False, "abstained": False}, {"passed": False, "abstained": True}


def x_extent(patch) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    """The x range of an ``axvspan`` patch in data units (a Rectangle from matplotlib 3.9, a Polygon before)."""
    xs = patch.get_patch_transform().transform(patch.get_path().vertices)[:, 0]
    return float(xs.min()), float(xs.max())


def curve(values: np.ndarray, location: float, width: float, *, log: bool, falls_to_higher: bool) -> list[list[float]]:
    """Rows (value, median p, low, high) of a logistic falling from 0.98 to 0.35 towards the
    severe side, its band 0.1 below and 0.05 above."""
    x = np.log10(values) if log else values
    sign = 1.0 if falls_to_higher else -1.0
    median = 0.35 + 0.63 / (1.0 + np.exp(sign * (x - location) / width))
    return [[float(v), round(p, 5), round(max(p - 0.1, 0.0), 5), round(min(p + 0.05, 1.0), 5)] for v, p in zip(values, median)]


def fog_outcome() -> Outcome:
    """Fog visibility, searched from 100000 m down to 1 m on a log axis: s80/90 <= 21.94 m;
    30 runs voted, one starved run abstained."""
    trials = [
        Trial(25.0, True, runs=[HELD] * 12),
        Trial(2.69, False, runs=[FAILED, FAILED]),
        Trial(8.66, False, runs=[FAILED, HELD, FAILED, ABSTAINED]),
        Trial(15.54, False, runs=[HELD, FAILED, FAILED]),
        Trial(22.27, True, runs=[HELD] * 6),
        Trial(17.78, False, runs=[FAILED, HELD]),
        Trial(13.58, True, runs=[HELD]),
        Trial(27.88, True, runs=[HELD]),
    ]
    boundary = Boundary(
        21.94,
        16.91,
        "m",
        estimate=19.68,
        bound=21.94,
        interval=[23.24, 14.72],
        reliability=0.8,
        confidence=0.9,
        runs=30,
        s50=18.1,
        s50_interval=[21.2, 1.0],
        transition=[20.55, 18.01],
        holds_at_edge=0.964,
        curve=curve(np.geomspace(1e5, 1.0, 41), np.log10(19.0), 0.05, log=True, falls_to_higher=False),
        search_range=[100000.0, 1.0],
        log_scale=True,
        grid_step=0.00390625,
    )
    return Outcome(
        test_id="tests/robustness/test_weather.py::test_fog_noisy[orbslam3-indoor]",
        system="orbslam3",
        dataset="synthetic/indoor",
        parameter="fog.visibility_m",
        worse="lower",
        edge=25.0,
        requirement="tracking_rate >= 0.9 wherever fog.visibility_m >= 25 m",
        criteria=[("tracking_rate", ">=", 0.9)],
        envelope=">= 25 m",
        verdict="passed",
        boundary=boundary,
        termination="max_runs",
        trials=trials,
        margin=25.0 - 21.94,
    )


def blur_outcome() -> Outcome:
    """Motion blur, searched from 0 to 40 px on a linear axis (higher is more severe): failed,
    s90/95 <= 6.2 px below the edge 8 px."""
    trials = [
        Trial(8.0, False, runs=[HELD, HELD, FAILED, HELD, FAILED]),
        Trial(3.0, True, runs=[HELD] * 3),
        Trial(14.0, False, runs=[FAILED] * 2),
    ]
    boundary = Boundary(
        6.2,
        11.5,
        "px",
        estimate=7.1,
        bound=6.2,
        interval=[6.0, 8.3],
        reliability=0.9,
        confidence=0.95,
        runs=10,
        s50=9.4,
        s50_interval=[8.1, 10.9],
        transition=[6.5, 12.0],
        holds_at_edge=0.12,
        curve=curve(np.linspace(0.0, 40.0, 41), 9.4, 1.5, log=False, falls_to_higher=True),
        search_range=[0.0, 40.0],
        log_scale=False,
        grid_step=0.01,
    )
    return Outcome(
        test_id="tests/robustness/test_motion.py::test_blur_noisy",
        system="orbslam3",
        dataset="synthetic/indoor",
        parameter="motion_blur.length_px",
        worse="higher",
        edge=8.0,
        requirement="tracking_rate >= 0.9 wherever motion_blur.length_px <= 8 px",
        criteria=[("tracking_rate", ">=", 0.9)],
        envelope="<= 8 px",
        verdict="failed",
        boundary=boundary,
        termination="max_runs",
        trials=trials,
    )


def by_gid(fig: Figure, gid: str) -> list[Any]:
    ax = fig.axes[0]
    return [a for a in [*ax.lines, *ax.collections, *ax.patches] if a.get_gid() == gid]


def only(fig: Figure, gid: str) -> Any:
    found = by_gid(fig, gid)
    assert len(found) == 1, f"{gid}: {found}"
    return found[0]


def test_noisy_outcome_plot_is_an_800x600_png_of_the_fitted_curve(tmp_path: Path) -> None:
    path = metric_plot(fog_outcome(), tmp_path / "plot" / "fog.png")
    image = cv2.imread(str(path))
    assert image is not None and image.shape == (600, 800, 3)
    assert np.mean(image == 255) < 0.95 and len(np.unique(image.reshape(-1, 3) // 16, axis=0)) >= 10

    def share(bgr: tuple[int, int, int], tol: int = 30) -> float:
        return float(np.mean(np.all(np.abs(image.astype(int) - bgr) <= tol, axis=2)))

    assert share((154, 61, 106)) > 1e-3  # the purple fitted curve
    assert share((40, 39, 214), 50) > 1e-4 and share((44, 160, 44), 50) > 1e-4  # red failed, green held runs
    assert [p.name for p in path.parent.iterdir()] == ["fog.png"]


def test_curve_band_runs_and_lines_are_where_the_boundary_says() -> None:
    for outcome in (fog_outcome(), blur_outcome()):
        b = outcome.boundary
        assert b.curve is not None and b.interval is not None and b.reliability is not None and b.bound is not None
        assert b.estimate is not None and outcome.edge is not None
        fig = metric_figure(outcome)
        assert len(fig.axes) == 1
        ax: Axes = fig.axes[0]
        rows = np.array(b.curve)

        line = only(fig, "curve")
        assert np.allclose(line.get_xdata(), rows[:, 0]) and np.allclose(line.get_ydata(), rows[:, 1])

        vertices = np.concatenate([p.vertices for p in only(fig, "band").get_paths()])
        for x, _, low, high in rows:
            at_x = vertices[np.isclose(vertices[:, 0], x), 1]
            assert np.isclose(at_x.min(), low) and np.isclose(at_x.max(), high), x

        expected = Counter((t.value, bool(r["passed"])) for t in outcome.trials for r in t.runs if not r["abstained"])
        shown: Counter[tuple[float, bool]] = Counter()
        for held, gid in ((True, "runs held"), (False, "runs failed")):
            offsets = only(fig, gid).get_offsets()
            assert np.all(np.abs(offsets[:, 1] - float(held)) <= JITTER + 1e-9)
            shown.update((float(x), held) for x in offsets[:, 0])
        assert shown == expected

        assert np.allclose(only(fig, "reliability").get_ydata(), b.reliability)
        assert np.allclose(only(fig, "bound").get_xdata(), b.bound)
        assert np.allclose(only(fig, "edge").get_xdata(), outcome.edge)
        assert np.allclose(only(fig, "estimate").get_xydata(), [[b.estimate, b.reliability]])
        span = only(fig, "interval")
        left, right = x_extent(span)
        assert np.isclose(left, min(b.interval)) and np.isclose(right, max(b.interval))

        assert ax.get_xscale() == ("log" if b.log_scale else "linear")
        assert ax.get_ylim()[0] < 0 < 1 < ax.get_ylim()[1]
        lo, hi = ax.get_xlim()
        assert lo <= min(t.value for t in outcome.trials) and max(t.value for t in outcome.trials) <= hi
        assert ("← more severe" in ax.get_xlabel()) == (outcome.worse == "lower") and "more severe" in ax.get_xlabel()
        title = fig.get_suptitle()
        assert title.startswith(outcome.test_id.split("/")[-1]) or outcome.verdict in title
        assert f"{outcome.verdict}: {b.statistical_text()}" in title
        labels = [t.get_text() for t in fig.legends[0].get_texts()]
        assert "fitted p (median)" in labels and f"R = {100 * b.reliability:.4g} % (required reliability)" in labels


def test_the_required_side_of_the_edge_is_shaded_towards_the_mild_end() -> None:
    for outcome in (fog_outcome(), blur_outcome()):
        fig = reliability_figure(outcome)
        lo, hi = fig.axes[0].get_xlim()
        shade = only(fig, "required")
        assert shade.get_label() == "required (envelope)"
        left, right = x_extent(shade)
        assert (left, right) == ((outcome.edge, hi) if outcome.worse == "lower" else (lo, outcome.edge))


def test_repeated_runs_fan_out_within_the_jitter_and_abstained_runs_are_left_out() -> None:
    outcome = fog_outcome()
    points = run_points(outcome)
    assert len(points) == 30 and sum(held for _, held, _ in points) == 23  # 31 runs, one abstained
    at_edge = [y for x, held, y in points if x == 25.0]
    assert len(at_edge) == 12 and len(set(at_edge)) == 12 and np.isclose(np.mean(at_edge), 1.0)
    assert max(abs(y - 1.0) for y in at_edge) <= JITTER + 1e-9
    assert [(held, y) for x, held, y in points if x == 27.88] == [(True, 1.0)]  # a lone run sits on 1 exactly
    assert sorted(y for x, held, y in points if x == 2.69) == pytest.approx([-0.01, 0.01])  # two runs, one step apart around 0
    assert sorted(held for x, held, _ in points if x == 8.66) == [False, False, True]


def test_a_deterministic_outcome_keeps_the_metric_panels() -> None:
    outcome = blur_outcome()
    outcome.boundary = Boundary(6.0, 7.0, "px")
    for t in outcome.trials:
        t.runs = []
    fig = metric_figure(outcome)
    assert not by_gid(fig, "curve") and fig.axes[0].get_ylabel() != "p: chance that a run holds the requirement"


def test_html_report_of_a_noisy_outcome_shows_the_plot_and_the_s_r_numbers(tmp_path: Path) -> None:
    index = write_html_report([fog_outcome()], tmp_path / "report")
    page = index.read_text(encoding="utf-8")
    (src,) = re.findall(r"<img class='plot' src='([^']+)' alt='([^']+)'", page)
    image = cv2.imread(str(tmp_path / "report" / src[0]))
    assert image is not None and image.shape == (600, 800, 3)
    assert src[1] == "the chance that a run holds against fog.visibility_m"
    assert "s80/90 &lt;= 21.94 m (s80 19.68 m; s50 18.1 m, beyond 1 m to 21.2 m)" in page  # the boundary, escaped
    (fact,) = re.findall(r"<dt>reliability curve</dt><dd>([^<]+)</dd>", page)
    assert fact == (
        "s80 19.68 m (90 % interval 14.72 m to 23.24 m), bound s80/90 21.94 m; "
        "s50 18.1 m (90 % interval beyond 1 m to 21.2 m); p falls from 20.55 m to 18.01 m (10 % to 90 % of its drop)"
    )
    assert "p &gt;= 80 % at the edge with confidence 96.4 % (30 runs)" in page  # holds_at_edge with the runs


def test_pytest_html_row_of_a_noisy_outcome_embeds_the_reliability_plot() -> None:
    html = outcome_html(fog_outcome())
    (data,) = re.findall(r"src='data:image/png;base64,([^']+)'", html)
    image = cv2.imdecode(np.frombuffer(base64.b64decode(data), np.uint8), cv2.IMREAD_COLOR)
    assert image is not None and image.shape == (600, 800, 3)
