"""Reports over outcomes: the terminal table, the Markdown summary and the HTML page."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from browser import find_picture, needs_chromium, screenshot
from report_outcomes import FOG_REQ, XSS_ID, flaky, fog, m, never_passed, rain, regressed, sweep_point

from pytest_sal.engine.outcomes.outcome import Boundary, Outcome, Trial
from pytest_sal.report.formatting import short_id
from pytest_sal.report.html_page import esc
from pytest_sal.report.metric_plot import metric_figure, metric_plot
from pytest_sal.report.outcome_page import write_html_report
from pytest_sal.report.outcome_report import headline, markdown_report, summary_rows, terminal_table, write_markdown


@pytest.fixture
def outcomes(tmp_path: Path) -> list[Outcome]:
    art = tmp_path / "artifacts"
    art.mkdir()
    return [fog(art), rain(), flaky(), regressed(), never_passed()]


def test_summary_rows_hold_every_column(outcomes: list[Outcome]) -> None:
    rows = {r["test_id"]: r for r in summary_rows(outcomes)}
    f = rows[outcomes[0].test_id]
    assert f["test"] == "test_weather.py::test_fog[orbslam3-euroc_mh01]"
    assert (f["system"], f["parameter"], f["requirement"]) == ("orbslam3", "fog.visibility_m", ">= 25 m")
    assert (f["boundary"], f["trials"], f["margin"], f["verdict"]) == ("13.67-15.12 m", "6 (6 cached)", "+9.88 m", "passed")
    assert f["change"] == "+1.61 m"  # midpoint 16 -> 14.395 m: towards the severe side (lower visibility)
    r = rows[XSS_ID]
    assert (r["requirement"], r["boundary"], r["trials"], r["margin"], r["change"], r["verdict"]) == (
        "<= 20 mm/h",
        "12.5-15 mm/h",
        "5",
        "-7.5 mm/h",
        "-",
        "FAILED",
    )
    assert rows["tests/test_motion.py::test_blur"]["verdict"] == "FLAKY"
    assert rows["tests/test_motion.py::test_blur"]["margin"] == "±0 km/h"
    d = rows["tests/test_transport.py::test_drop"]
    assert (d["change"], d["verdict"], d["status"]) == ("REGRESSED", "FAILED", "regressed")
    n = rows["tests/test_weather.py::test_fog_night"]
    assert (n["boundary"], n["margin"], n["requirement"]) == ("> 1e+05 m (never passed)", "-", ">= 25 m")


def test_terminal_table_fits_and_truncates_ids_from_the_left(outcomes: list[Outcome]) -> None:
    long = flaky()
    long.test_id = "tests/deep/folder/test_motion.py::test_blur_with_a_really_long_name[orbslam3-tum_fr1_desk-stereo-inertial-night]"
    lines = terminal_table([*outcomes, long])
    assert all(len(line) <= 120 for line in lines)
    header = lines[0].split()
    full = ["test", "system", "parameter", "requirement", "boundary", "trials", "votes", "margin", "change", "verdict"]
    assert len(header) == len(full) and all(f.startswith(h.rstrip("…")) for h, f in zip(header, full))  # squeezed, not dropped
    assert set(lines[1]) <= {"-", " "} and len(lines) == 2 + 6
    fog_line = lines[-1]  # the one that passed: after the failures
    assert "6 (6 cached)" in fog_line and "13.67-15.12 m" in fog_line and ">= 25 m" in fog_line and "+1.61 m" in fog_line
    assert sum("REGRESSED" in line for line in lines) == 1 and sum("FLAKY" in line for line in lines[2:-1]) == 2
    last = next(line for line in lines if "night]" in line)
    assert "…" in last and "tests/deep" not in last
    # columns line up: the verdict column starts at the same place on every line
    start = lines[0].index("verdict")
    assert all(line[start:].split()[0] in {"verdict", "passed", "FAILED", "FLAKY"} for line in lines[2:])
    narrow = terminal_table(outcomes, width=100)
    assert all(len(line) <= 100 for line in narrow) and all("…" in line for line in narrow[2:3])


def test_markdown_has_counts_table_and_details_only_where_needed(outcomes: list[Outcome], tmp_path: Path) -> None:
    text = markdown_report(outcomes)
    assert headline(outcomes) == "5 robustness requirements: 1 passed, 3 failed (1 regressed), 1 flaky"
    assert "**5 robustness requirements: 1 passed, 3 failed (1 regressed), 1 flaky**" in text
    assert "| test | system | parameter | requirement | boundary | trials | votes | margin | change | verdict |" in text
    assert text.count("\n| `test_") == 5
    sections = re.findall(r"^### .*$", text, flags=re.MULTILINE)
    assert len(sections) == 4
    assert not any("test_fog[" in s for s in sections)  # passed: no details
    details = text.split("### ")
    drop = next(d for d in details if "test_drop" in d.splitlines()[0])
    assert drop.startswith("REGRESSED: `tests/test_transport.py::test_drop`") and "previous boundary" in drop and "0.3-0.35" in drop
    assert "**last pass** at 0.19:" in drop and "**first fail** at 0.2:" in drop and "tracking\\_rate 0.7" in drop
    rain_part = next(d for d in details if "test_rain" in d.splitlines()[0])
    assert f"`{rain().reproduction}`" in rain_part
    assert "17.5 mm/h passed but 15 mm/h (milder) failed" in rain_part
    assert "| 1 | 20 | fail | - | 0 | " in rain_part  # tracking lost: no ATE
    assert "<script>" not in text.replace("`test_weather.py::test_rain[<script>alert(1)</script>]`", "").replace(
        f"`{XSS_ID}`", ""
    )  # raw only inside code spans
    assert all(line.count("|") - line.count("\\|") in (0, 11) for line in text.splitlines() if line.startswith("| ") and "test |" in line)
    path = write_markdown(outcomes, tmp_path / "out" / "summary.md")
    assert path.read_text(encoding="utf-8") == text
    assert [p.name for p in path.parent.iterdir()] == ["summary.md"]


def test_html_report_is_self_contained_and_escaped(outcomes: list[Outcome], tmp_path: Path) -> None:
    out = tmp_path / "report"
    index = write_html_report(outcomes, out)
    assert index == out / "index.html"
    page = index.read_text(encoding="utf-8")
    for o in outcomes:
        if o.test_id != XSS_ID:
            assert o.test_id in page
    assert "<script" not in page and "&lt;script&gt;alert(1)&lt;/script&gt;" in page
    assert "http://" not in page and "https://" not in page and "<link" not in page
    assert page.count("<section ") == 5 and page.count("class='badge") >= 10
    sources = re.findall(r"<img[^>]* src='([^']+)'", page)
    assert len(sources) == 5 + 6 + 1  # a plot per test, the fog frames, one trajectory
    for src in sources:
        assert not src.startswith("/") and ":" not in src
        assert (out / src).is_file()
    assert len(list(out.glob("assets/*/frame-*.png"))) == 6 and len(list(out.glob("assets/*/trajectory-*.png"))) == 1
    assert "15.12 m: pass" in page and "5 m: fail" in page
    # frames mild to severe: 25 m first, 5 m last
    fog_section = page[page.index("<span class='id'>tests/robustness/test_weather.py::test_fog[orbslam3") :]
    captions = re.findall(r"<figcaption>([^<]+)</figcaption>", fog_section.split("</section>")[0])
    assert captions[:6] == ["25 m: pass", "16.72 m: pass", "15.12 m: pass", "13.67 m: fail", "11.18 m: fail", "5 m: fail"]
    assert write_html_report(outcomes, out) == index  # rewriting over an existing report works


def test_failed_flaky_and_regressed_tests_come_first_in_every_report(tmp_path: Path) -> None:
    calm = fog()
    calm.test_id = "tests/robustness/test_weather.py::test_calm"
    given = [fog(), rain(), calm, regressed(), flaky()]
    # failed, flaky and regressed first, then the passed ones; each group sorted by test id, so a
    # report reads the same whatever order the xdist workers finished the tests in
    first = [XSS_ID, "tests/test_motion.py::test_blur", "tests/test_transport.py::test_drop", calm.test_id, fog().test_id]
    assert first[:3] == sorted(first[:3]) and first[3:] == sorted(first[3:])

    table = terminal_table(given, width=200)[2:]
    assert [next(i for i, line in enumerate(table) if short_id(test_id) in line) for test_id in first] == [0, 1, 2, 3, 4]

    text = markdown_report(given)
    rows = [line for line in text.splitlines() if line.startswith("| `")]
    assert [next(i for i, row in enumerate(rows) if short_id(test_id) in row) for test_id in first] == [0, 1, 2, 3, 4]
    assert [line.split("`")[1] for line in text.splitlines() if line.startswith("### ")] == first[:3]

    page = write_html_report(given, tmp_path / "report").read_text(encoding="utf-8")
    assert re.findall(r"<a href='#[^']*' title='([^']*)'>", page) == [esc(test_id) for test_id in first]  # the table
    assert re.findall(r"<span class='id'>([^<]*)</span>", page) == [esc(test_id) for test_id in first]  # the sections


def test_metric_plot_is_a_non_blank_png_with_markers_band_and_edge(tmp_path: Path) -> None:
    path = metric_plot(rain(), tmp_path / "plot" / "rain.png")
    image = cv2.imread(str(path))
    assert image is not None and image.shape == (600, 800, 3)
    assert np.mean(image == 255) < 0.95 and len(np.unique(image.reshape(-1, 3) // 16, axis=0)) >= 10

    def share(bgr: tuple[int, int, int], tol: int = 30) -> float:
        return float(np.mean(np.all(np.abs(image.astype(int) - bgr) <= tol, axis=2)))

    assert share((40, 39, 214)) > 1e-4 and share((44, 160, 44)) > 1e-4  # red fail, green pass markers
    b, g, r = (image[..., i].astype(int) for i in range(3))
    assert np.mean((r > 230) & (r - b > 40) & (g > b + 10) & (r > g + 10)) > 0.02  # the orange boundary band
    assert [p.name for p in path.parent.iterdir()] == ["rain.png"]
    fig = metric_figure(never_passed())  # 25 .. 100000 m: two decades or more
    assert fig.axes[0].get_xscale() == "log"
    assert [ax.get_xscale() for ax in metric_figure(fog()).axes] == ["linear", "linear"]
    assert [ax.get_ylabel() for ax in metric_figure(fog()).axes] == ["ate_rmse [m]", "tracking_rate"]


def test_a_sweep_point_without_envelope_trials_or_metrics_still_reports(tmp_path: Path) -> None:
    point = sweep_point()
    (row,) = summary_rows([point])
    assert (row["requirement"], row["boundary"], row["trials"], row["margin"], row["change"]) == ("-", "unknown", "0", "-", "-")
    assert "### FAILED: `test_sweep.py::test_levels[3]`" in markdown_report([point])
    page = write_html_report([point], tmp_path / "r").read_text(encoding="utf-8")
    assert "test_levels[3]" in page and "<img" not in page
    image = cv2.imread(str(metric_plot(point, tmp_path / "empty.png")))
    assert image is not None and image.shape == (600, 800, 3)
    point.trials, point.boundary = [Trial(3200.0, False, m(0.9, 1.0), failed=["ate_rmse < 0.5 m"])], Boundary(None, 3200.0, "ISO")
    assert summary_rows([point])[0]["boundary"] == "failed at 3200 ISO"


@needs_chromium
def test_html_report_renders_in_headless_chromium(outcomes: list[Outcome], tmp_path: Path) -> None:
    index = write_html_report(outcomes, tmp_path / "report")
    screen = screenshot(index, tmp_path, size=(1280, 9000))
    plots = re.findall(r"<img class='plot' src='([^']+)'", index.read_text(encoding="utf-8"))
    assert len(plots) == len(outcomes)
    tops = []
    for src in plots:  # each metric plot is drawn at its natural 800 x 600 px, in the page's order
        best, top = find_picture(screen, index.parent / src)
        assert best > 0.95, f"{src} is not visible on the page (best match {best:.2f})"
        tops.append(top)
    assert tops == sorted(tops) and tops[0] > 200  # below the summary table
    assert (screen[-200:] > 250).all()  # the whole page fitted in the window


def test_trial_at_takes_the_last_trial_at_a_value_within_float_rounding() -> None:
    first, repeat = Trial(14.0, True, m(0.5, 0.95)), Trial(14.0, False, m(1.9, 0.7), runs=[{"passed": False}] * 3)
    rounded = Trial(0.1 + 0.2, False, m(2.5, 0.5))  # 0.30000000000000004: what a unit conversion leaves
    edge = Trial(25.0, True, m(0.2, 0.99))
    o = Outcome(
        test_id="test_fog.py::test_fog",
        system="reference_vo",
        dataset="synthetic",
        parameter="fog.visibility_m",
        worse="lower",
        edge=25.0,
        requirement=FOG_REQ,
        verdict="passed",
        boundary=Boundary(14.0, 0.3, "m"),
        termination="tolerance",
        trials=[edge, first, rounded, repeat],
    )
    assert o.trial_at(14.0) is repeat  # repeated trials at one value: the last, the latest evidence
    assert o.trial_at(0.3) is rounded and o.trial_at(0.1 + 0.2) is rounded  # equal within float rounding
    assert o.trial_at(0.30001) is None and o.trial_at(None) is None
    assert o.end_trials() == (repeat, rounded)
    assert o.trial_at(o.edge) is edge


def test_boundary_texts_long_and_short() -> None:
    assert Boundary(14.0, 16.0, "m").text() == "14-16 m" == Boundary(16.0, 14.0, "m").short_text("lower")
    assert Boundary(-1.25, -3.5, "").text() == "-3.5 to -1.25"
    assert Boundary(1.0, None, "m").text() == "beyond 1 m (passed everywhere searched)"
    assert Boundary(None, 1e5, "m").text() == "beyond 1e+05 m (failed everywhere searched)"
    assert Boundary(None, None, "m").text() == "unknown" == Boundary(None, None, "m").short_text("higher")
    assert Boundary(1.0, None, "m").short_text("lower") == "< 1 m (never failed)"
    assert Boundary(1.0, None, "m").short_text("higher") == "> 1 m (never failed)"
    assert Boundary(None, 12.3456, "px").short_text("lower") == "> 12.35 px (never passed)"
    assert Boundary(3.0, None, "px").short_text("higher", single=True) == "passed at 3 px"
    assert Boundary(None, 3.0, "").short_text("higher", single=True) == "failed at 3"
