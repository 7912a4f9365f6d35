"""The ``sal`` command: help, dataset info (text and JSON) and one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from pytest_sal.cli.main import main

SAL = Path(sys.executable).with_name("sal")


def run_sal(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(SAL), *args], capture_output=True, text=True, timeout=120)


def test_help_teaches_commands_and_examples():
    result = run_sal("--help")
    assert result.returncode == 0
    for text in ("demo", "dataset", "examples:", "sal dataset info kitti", "SAL_CACHE_DIR"):
        assert text in result.stdout
    info_help = run_sal("dataset", "info", "--help").stdout
    for text in ("--sequence", "--stereo", "--json", "baseline_m", "synthetic"):
        assert text in info_help
    compare_help = run_sal("compare", "--help")  # a help text with '%' (boundary:10%) must not break argparse
    assert compare_help.returncode == 0 and "said only): boundary:10% (the boundary's pass" in " ".join(compare_help.stdout.split())


def test_dataset_info_json_has_exactly_the_documented_keys(shared_data, capsys):
    assert main(["dataset", "info", "kitti", str(shared_data / "kitti"), "--sequence", "07", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert set(info) == {"frames", "sensor", "fps", "camera", "groundtruth_poses"}
    assert set(info["camera"]) == {"fx", "fy", "cx", "cy", "width", "height", "baseline_m"}
    assert info["frames"] == 140 and info["groundtruth_poses"] == 140 and info["sensor"] == "mono"
    assert info["camera"]["fx"] == pytest.approx(707.0912)


def test_dataset_info_text(shared_data, capsys):
    assert main(["dataset", "info", "kitti", str(shared_data / "kitti" / "sequences" / "07"), "--max-frames", "20"]) == 0
    out = capsys.readouterr().out
    assert "frames       20" in out and "fx 707.0912" in out and "groundtruth  20 poses" in out


def test_dataset_list_names_every_builtin_kind(capsys):
    assert main(["dataset", "list"]) == 0
    out = capsys.readouterr().out
    for kind in ("kitti", "tum", "euroc", "folder", "synthetic"):
        assert f"\n{kind}" in "\n" + out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["dataset", "info", "kitti", "/no/such/folder"], "sal: error: /no/such/folder: kitti dataset folder not found"),
        (
            ["dataset", "info", "nosuchkind", "/tmp"],
            "sal: error: unknown dataset kind 'nosuchkind'; known: euroc, folder, kitti, rosbag, synthetic, tum, video (entry-point group 'sal.datasets')",
        ),
        (
            ["dataset", "info", "kitti", "/tmp", "-o", "colour=true"],
            "sal: error: unknown option 'colour' for dataset kind 'kitti'; allowed: start, max_frames, sequence, stereo, color",
        ),
    ],
)
def test_bad_input_is_one_line_without_traceback(args, message):
    result = run_sal(*args)
    assert result.returncode == 2
    assert result.stderr.strip() == message
    assert "Traceback" not in result.stderr


def test_malformed_file_error_names_file_and_line(shared_data, tmp_path):
    seq = tmp_path / "sequences" / "07"
    (seq / "image_0").mkdir(parents=True)
    src = shared_data / "kitti" / "sequences" / "07"
    (seq / "image_0" / "000000.png").write_bytes((src / "image_0" / "000000.png").read_bytes())
    (seq / "calib.txt").write_text((src / "calib.txt").read_text())
    (seq / "times.txt").write_text("zero\n")
    result = run_sal("dataset", "info", "kitti", str(seq))
    assert result.returncode == 2
    assert result.stderr.strip() == f"sal: error: {seq / 'times.txt'}:1: expected numbers, got 'zero'"


def test_usage_errors_come_from_argparse():
    result = run_sal("dataset", "info", "kitti", "/tmp", "--max-frames", "0")
    assert result.returncode == 2 and "expected a number >= 1, got 0" in result.stderr


@pytest.mark.parametrize("value", ["-3", "0", "nan", "soon"])
def test_a_timeout_must_be_seconds_above_zero(value, tmp_path):
    """A negative timeout used to kill every run at once and report a boundary of failures."""
    config = tmp_path / "never_read.yaml"  # argparse rejects the value before the config is read
    result = run_sal("boundary", str(config), "--slam", "reference_vo", "--timeout", value)
    assert result.returncode == 2
    expected = f"expected seconds, got {value!r}" if value == "soon" else f"expected seconds > 0, got {value}"
    assert result.stderr.strip().endswith(f"sal boundary: error: argument --timeout: {expected}")


def test_demo_renders_both_scenes_and_writes_previews(tmp_path, capsys):
    import cv2

    assert main(["demo", "--frames", "3", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "3 stereo frames 1240x376 px at 10 Hz" in out and "baseline 0.54 m" in out
    assert "3 rgbd frames 640x480 px at 30 Hz" in out
    for scene in ("urban", "indoor"):
        sheet = cv2.imread(str(tmp_path / f"{scene}.png"))
        assert sheet is not None and sheet.shape[0] > 300
        assert sheet.std() > 20  # frames and depth, not a blank canvas


def test_dataset_info_synthetic_without_path(capsys):
    assert main(["dataset", "info", "synthetic", "-o", "scene=indoor", "-o", "frames=12", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["frames"] == 12 and info["sensor"] == "rgbd" and info["fps"] == 30
    assert info["camera"]["width"] == 640 and info["groundtruth_poses"] == 12
