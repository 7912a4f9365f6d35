"""``sal report DIR``: one HTML page from a real experiment folder, looked at in headless Chromium.

The folder is made by the real commands (``sal perturb``, ``sal evaluate`` and ``sal boundary``
with the reference VO, ``sal features`` with ORB) on 8 frames of the synthetic urban world.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path
from urllib.parse import unquote

import cv2
import numpy as np
import pytest
import yaml
from browser import find_picture, needs_chromium, screenshot

from pytest_sal.cli.main import build_parser, main
from pytest_sal.experiment.boundary_summary import read_boundary_summary
from pytest_sal.experiment.config import build_sequence, load_config
from pytest_sal.report.experiment_frames import THUMBNAIL_WIDTH
from pytest_sal.report.experiment_page import write_experiment_report
from sal_adapters import SalError
from sal_adapters.images import read_image

FRAMES = 8
#: the commands the page suggests for a part not made yet, as it writes them
SUGGESTED = {"evaluate": "sal evaluate CONFIG --system NAME", "features": "sal features CONFIG --features orb"}
CONFIG = {
    "experiment": {"name": "report_demo", "seed": 3},
    "dataset": {"type": "synthetic", "max_frames": FRAMES, "options": {"scene": "urban", "frames": FRAMES}},
    "perturbations": [
        {"name": "fog", "type": "fog", "parameters": {"visibility_m": 25}},
        {
            "name": "rain_soiled",
            "type": "composite",
            "parameters": {
                "modules": [
                    {"type": "rain", "parameters": {"intensity_mm_h": 20}},
                    {"type": "lens_soiling", "parameters": {"particles": 30}},
                ]
            },
        },
    ],
    "robustness_boundary": {
        "enabled": True,
        "name": "fog_visibility",
        "target_perturbation": "fog",
        "parameter": "visibility_m",
        "lower_bound": 5,
        "upper_bound": 400,
        "tolerance": 20,
        "max_trials": 3,
        "ate_rmse_fail": 1.0,
    },
}
SEQUENCES = ("baseline", "fog", "rain_soiled")


@pytest.fixture(scope="module")
def experiment(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An experiment folder written by all four commands."""
    root = tmp_path_factory.mktemp("experiment")
    config = root / "report_demo.yaml"
    config.write_text(yaml.safe_dump({**CONFIG, "output": {"base_dir": str(root / "results")}}))
    cache = str(root / "cache")
    for argv in (
        ["perturb", str(config), "--cache-dir", cache],
        ["evaluate", str(config), "--slam", "reference_vo", "--cache-dir", cache],
        ["boundary", str(config), "--slam", "reference_vo", "--cache-dir", cache],
        ["features", str(config), "--features", "orb"],
    ):
        assert main(argv) == 0, argv
    return root / "results" / "report_demo"


@pytest.fixture(scope="module")
def report(experiment: Path) -> Path:
    return write_experiment_report(experiment, warn=lambda message: pytest.fail(f"unexpected warning: {message}"))


def page_images(page: Path) -> list[Path]:
    return [page.parent / unquote(src) for src in re.findall(r"<img [^>]*src='([^']+)'", page.read_text())]


def test_page_shows_every_part_with_the_numbers_of_the_result_files(experiment: Path, report: Path) -> None:
    text = report.read_text()
    assert report == experiment / "report" / "index.html"
    for heading in ("Example frames", "SLAM results", "Robustness boundary", "Feature tracking"):
        assert f"<h2>{heading}</h2>" in text
    summary = json.loads((experiment / "slam_results" / "reference_vo" / "metrics" / "summary.json").read_text())
    found = re.search(r"<table class='slam'>.*?</table>", text, re.DOTALL)
    assert found is not None
    table = found.group(0)
    assert "<th class='num'>KITTI t_rel [%] median</th><th class='num'>KITTI r_rel [deg/100m] median</th>" in table
    for name in SEQUENCES:
        entry = summary["baseline"] if name == "baseline" else summary["perturbations"][name]
        found = re.search(rf"<tr[^>]*><td>{name}</td>(.*?)</tr>", table)
        assert found is not None, name
        row = found.group(1)
        median = entry["ate_rmse"]["median"]
        ok = entry["runs"] - entry["failures"]
        assert f"<td class='num'>{ok}/{entry['runs']}</td><td class='num'>{'-' if median is None else format(median, '.4f')}</td>" in row
        for failure in entry["failure_reasons"]:  # a failed run's reason is listed under the table
            assert f"<li>{name}, run {failure['run']}: {failure['reason']}</li>" in text
    assert summary["baseline"]["failures"] == 0 and summary["perturbations"]["fog"]["failures"] == 1  # 25 m fog defeats the VO
    search = read_boundary_summary(
        json.loads((experiment / "robustness_boundary" / "reference_vo" / "fog_visibility" / "boundary_summary.json").read_text())
    )
    assert f"fog.visibility_m {search.outcome.boundary.text()}" in text
    assert f"a linear sweep at the tolerance step: {search.experiment['linear_sweep_trials']}" in text
    trials = search.outcome.trials
    assert text.count("<tr class='passed'><td class=num>") + text.count("<tr class='failed'><td class=num>") == len(trials)
    missing = [t for t in trials if t.metrics["failures"]]  # the 5 m fog: nothing tracked
    assert missing and all(f"({t.metrics['failures'][0]})</td>" in text for t in missing)  # why its ATE is missing
    features = json.loads((experiment / "features" / "orb" / "summary.json").read_text())
    for name in SEQUENCES:
        assert f"<td>{name}</td><td class=num>{features['sequences'][name]['detections_per_frame']['mean']:.0f}</td>" in text
    assert "rain(intensity_mm_h=20" in text and "lens_soiling(particles=30" in text  # the composite's steps, in order
    assert "http://" not in text and "https://" not in text  # self-contained: nothing fetched
    images = page_images(report)
    # 3 frames, aggregated + ATE + trajectories + error over time, boundary plot, survival + detections
    assert len(images) == 3 + 4 + 1 + 2
    assert all(p.is_file() and p.resolve().is_relative_to(report.parent.resolve()) for p in images)


def test_example_frames_show_the_same_moment_of_every_sequence(experiment: Path, report: Path) -> None:
    frames = report.parent / "assets" / "frames"
    thumbs = {name: read_image(frames / f"{name}.png").astype(np.float64) for name in SEQUENCES}
    clean = build_sequence(load_config(experiment / "config.yaml"))
    middle = clean[FRAMES // 2].image
    expected = cv2.resize(
        middle, (THUMBNAIL_WIDTH, round(middle.shape[0] * THUMBNAIL_WIDTH / middle.shape[1])), interpolation=cv2.INTER_AREA
    )  # by hand
    assert np.array_equal(thumbs["baseline"], expected)
    # fog at 25 m visibility washes the street out: far less contrast than the clean frame
    assert thumbs["fog"].std() < 0.6 * thumbs["baseline"].std()
    # rain and dirt change the picture, yet it is the same view (not another frame)
    diff = np.abs(thumbs["rain_soiled"] - thumbs["baseline"]).mean()
    other = cv2.resize(clean[0].image, expected.shape[1::-1], interpolation=cv2.INTER_AREA).astype(np.float64)
    assert 1.0 < diff < np.abs(other - thumbs["baseline"]).mean() + 30


def test_report_folder_can_be_moved_and_written_elsewhere(experiment: Path, report: Path, tmp_path: Path) -> None:
    moved = tmp_path / "moved"
    shutil.copytree(report.parent, moved)
    assert all(p.is_file() for p in page_images(moved / "index.html"))
    assert main(["report", str(experiment), "-o", str(tmp_path / "elsewhere")]) == 0
    assert (tmp_path / "elsewhere" / "index.html").read_text() == report.read_text()
    # the config names its results folder: sal report CONFIG is the same page
    assert main(["report", str(experiment.parent.parent / "report_demo.yaml"), "-o", str(tmp_path / "from-config")]) == 0
    assert (tmp_path / "from-config" / "index.html").read_text() == report.read_text()


@needs_chromium
def test_page_renders_in_headless_chromium_with_its_pictures(report: Path, tmp_path: Path) -> None:
    page = screenshot(report, tmp_path)
    # every example frame and the boundary plot is drawn at its natural size: find each in the screenshot
    shown = [*sorted((report.parent / "assets" / "frames").glob("*.png")), *(report.parent / "assets" / "boundary").rglob("*.png")]
    assert len(shown) == 4
    tops = []
    for picture in shown:
        best, top = find_picture(page, picture)
        assert best > 0.95, f"{picture.name} is not visible on the page (best match {best:.2f})"
        tops.append(top)
    assert max(tops[:3]) < tops[3]  # the frames come before the boundary plot
    # the page ends before the window does: nothing was cut off below
    assert (page[-300:] > 250).all()


def test_broken_and_missing_parts_are_named_and_the_rest_is_built(experiment: Path, tmp_path: Path) -> None:
    copy = tmp_path / "experiment"
    shutil.copytree(experiment, copy, ignore=shutil.ignore_patterns("report"))
    (copy / "slam_results" / "reference_vo" / "metrics" / "summary.json").write_text("{broken")
    shutil.rmtree(copy / "features")
    warnings: list[str] = []
    text = write_experiment_report(copy, warn=warnings.append).read_text()
    expected = (
        "warning: slam_results/reference_vo/metrics/summary.json: cannot be read "
        "(Expecting property name enclosed in double quotes: line 1 column 2 (char 1)); its part of the report is left out"
    )
    assert warnings == [expected]
    assert "<h2>Left out</h2>" in text and "unreadable: slam_results/reference_vo/metrics/summary.json" in text
    assert f"no feature tracking: run <code>{SUGGESTED['features']}</code>" in text
    assert text.count(f"<figure style='width: {THUMBNAIL_WIDTH}px'>") == 3 and "fog_visibility" in text  # frames and boundary still there


def test_a_folder_without_results_is_one_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["report", str(tmp_path / "nowhere")]) == 2
    assert f"experiment folder not found: {tmp_path / 'nowhere'}" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    with pytest.raises(
        SalError, match=r"holds no experiment results \(none of images/, slam_results/, robustness_boundary/, features/\); run sal perturb"
    ):
        write_experiment_report(tmp_path / "empty")
    assert not (tmp_path / "empty" / "report").exists()  # nothing written for a refused folder
    (tmp_path / "empty" / "images").mkdir()
    (tmp_path / "file").write_text("")
    with pytest.raises(SalError, match=r"report folder .*file is a file; give a folder for index.html and assets/"):
        write_experiment_report(tmp_path / "empty", tmp_path / "file")


def test_report_on_real_kitti_frames(shared_data: Path, tmp_path: Path) -> None:
    """The example frames of a real dataset: KITTI's grey images, reopened from its own layout."""
    config = tmp_path / "kitti.yaml"
    config.write_text(
        yaml.safe_dump(
            {
                "experiment": {"name": "kitti_soiling", "seed": 1},
                "dataset": {"type": "kitti", "path": str(shared_data / "kitti" / "sequences" / "07"), "max_frames": 5},
                "perturbations": [{"name": "soiling", "type": "lens_soiling", "parameters": {"particles": 200}}],
                "output": {"base_dir": str(tmp_path / "results")},
            }
        )
    )
    assert main(["perturb", str(config), "--cache-dir", str(tmp_path / "cache")]) == 0
    page = write_experiment_report(config, warn=lambda message: pytest.fail(f"unexpected warning: {message}"))
    frames = page.parent / "assets" / "frames"
    clean, soiled = (read_image(frames / f"{name}.png").astype(np.float64) for name in ("baseline", "soiling"))
    middle = build_sequence(load_config(config))[2].image
    assert np.array_equal(clean, cv2.resize(middle, clean.shape[1::-1], interpolation=cv2.INTER_AREA))
    assert (clean[..., 0] == clean[..., 1]).all()  # grey KITTI, expanded to RGB
    assert np.abs(soiled - clean).mean() > 1.0 and f"no SLAM runs: run <code>{SUGGESTED['evaluate']}</code>" in page.read_text()


def test_report_of_a_config_with_timestamped_folders_takes_the_newest(tmp_path: Path) -> None:
    config = tmp_path / "exp.yaml"
    config.write_text(yaml.safe_dump({**CONFIG, "output": {"base_dir": str(tmp_path / "out"), "create_timestamp_dir": True}}))
    with pytest.raises(SalError, match=r"no results folder .*report_demo_<YYYYmmdd_HHMMSS> yet; run sal perturb"):
        write_experiment_report(config)
    for stamp in ("20261201_090000", "20261201_101500", "20261130_235959"):
        (tmp_path / "out" / f"report_demo_{stamp}" / "features").mkdir(parents=True)
    assert write_experiment_report(config, warn=print) == tmp_path / "out" / "report_demo_20261201_101500" / "report" / "index.html"


@pytest.mark.parametrize("command", SUGGESTED.values())
def test_the_commands_the_page_suggests_are_real(command: str) -> None:
    """Each parses with the real ``sal`` parser (CONFIG and NAME filled in): a renamed command or
    option breaks this test, not a reader following the page."""
    args = command.replace("CONFIG", "exp.yaml").replace("NAME", "reference_vo").split()[1:]
    try:
        build_parser().parse_args(args)
    except SystemExit:
        pytest.fail(f"sal cannot parse {command!r}")
