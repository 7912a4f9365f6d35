"""EuRoC adapter errors bad folders raise: missing folders and frame lists, several sequences,
malformed CSV lines, decreasing timestamps, missing images, sensor.yaml and ground-truth problems."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
from euroc_excerpt import _euroc_copy, _memory_sequence

from sal_adapters import (
    DatasetError,
    DatasetWarning,
    open_dataset,
)
from sal_adapters.euroc import EUROC

#: the shared fixtures (euroc_dir)
pytest_plugins = ["euroc_excerpt"]


# -- bad input -------------------------------------------------------------------------------------
@pytest.fixture()
def tiny(tmp_path: Path) -> Path:
    """A 3-frame stereo EuRoC folder written from memory."""
    seq = _memory_sequence(stereo=True, colour=False, n=3)
    return EUROC.write(seq, tmp_path / "written", iter(seq))


def test_missing_folder_and_frame_list(tmp_path: Path, tiny: Path) -> None:
    with pytest.raises(DatasetError, match=r"nowhere: EuRoC folder not found"):
        EUROC.open(tmp_path / "nowhere")
    with pytest.raises(DatasetError, match=r"not a EuRoC sequence folder \(no mav0/"):
        EUROC.open(tmp_path / "written" / "memory_test" / "mav0" / "cam0")
    with pytest.raises(DatasetError, match=r"sequence 'V9' not found"):
        EUROC.open(tiny.parent, sequence="V9")
    (tiny / "mav0/cam0/data.csv").unlink()
    with pytest.raises(DatasetError, match=r"mav0/cam0/data\.csv: file not found"):
        EUROC.open(tiny)


def test_several_sequences_need_the_option(tmp_path: Path, tiny: Path) -> None:
    shutil.copytree(tiny, tiny.parent / "second")
    with pytest.raises(DatasetError, match=r"several EuRoC sequences found \(memory_test, second\); pass sequence="):
        EUROC.open(tiny.parent)
    assert len(EUROC.open(tiny.parent, sequence="second")) == 3


def test_malformed_frame_csv_line(tiny: Path) -> None:
    csv = tiny / "mav0/cam0/data.csv"
    lines = csv.read_text().splitlines()
    lines[2] = "12345abc,12345abc.png"
    csv.write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError, match=rf"^{re.escape(str(csv))}:3: expected an integer timestamp in ns, got '12345abc'$"):
        EUROC.open(tiny)
    lines[2] = "99"
    csv.write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError, match=rf"^{re.escape(str(csv))}:3: expected 2 comma-separated values"):
        EUROC.open(tiny)


def test_decreasing_timestamps(tiny: Path) -> None:
    csv = tiny / "mav0/cam0/data.csv"
    lines = csv.read_text().splitlines()
    lines[2], lines[3] = lines[3], lines[2]
    csv.write_text("\n".join(lines) + "\n")
    with pytest.raises(
        DatasetError, match=rf"^{re.escape(str(csv))}:4: time \d+ ns is not after line 3's \d+ ns \(frame times must increase\)$"
    ):
        EUROC.open(tiny)


def test_missing_images_warn_once(tiny: Path) -> None:
    files = sorted((tiny / "mav0/cam0/data").iterdir())
    files[1].unlink()
    with pytest.warns(DatasetWarning, match=r"cam0/data\.csv: 1 of 3 rows skipped: 1 name image files that do not exist") as record:
        seq = EUROC.open(tiny)
    assert len(record) == 1 and len(seq) == 2 and [r.index for r in seq.records] == [0, 2]
    with pytest.warns(DatasetWarning) as record:
        stereo = EUROC.open(tiny, stereo=True)
    messages = sorted(str(w.message) for w in record)
    assert len(stereo) == 2 and len(messages) == 2
    assert "cam0/data.csv: 1 of 3 rows skipped: 1 name image files" in messages[0]
    assert "cam1/data.csv: 1 of 3 rows skipped: 1 have no cam0 image at the same ns timestamp" in messages[1]
    for f in files:
        f.unlink(missing_ok=True)
    with pytest.warns(DatasetWarning), pytest.raises(DatasetError, match="no frame has its image file"):
        EUROC.open(tiny)


@pytest.mark.parametrize("key", ["T_BS", "rate_hz", "resolution", "intrinsics", "distortion_coefficients"])
def test_sensor_yaml_missing_key(tiny: Path, key: str) -> None:
    path = tiny / "mav0/cam0/sensor.yaml"
    text = path.read_text()
    start = text.index(f"\n{key}:") + 1
    end = text.index("\n", start)
    while key == "T_BS" and text[end + 1 : end + 3] == "  ":
        end = text.index("\n", end + 1)
    path.write_text(text[:start] + text[end + 1 :])
    with pytest.raises(DatasetError, match=rf"^{re.escape(str(path))}: missing key '{key}'"):
        EUROC.open(tiny)


def test_sensor_yaml_bad_values(tiny: Path) -> None:
    path = tiny / "mav0/cam1/sensor.yaml"
    text = path.read_text()
    path.write_text(text.replace("intrinsics: [", "intrinsics: [1.0, "))
    assert EUROC.open(tiny).camera.right is None  # mono never reads cam1
    with pytest.raises(DatasetError, match=rf"^{re.escape(str(path))}: key 'intrinsics' must be a list of 4 numbers"):
        EUROC.open(tiny, stereo=True)
    path.write_text(text.replace("distortion_model: radial-tangential", "distortion_model: equidistant"))
    with pytest.raises(DatasetError, match=r"distortion_model 'equidistant' is not supported"):
        EUROC.open(tiny, stereo=True)
    path.write_text(text.replace("T_BS:", "T_BS: [1, 2]\nunused:"))
    with pytest.raises(DatasetError, match=r"key 'T_BS' must hold 16 numbers"):
        EUROC.open(tiny, stereo=True)


def test_sensor_yaml_syntax_error(tiny: Path) -> None:
    path = tiny / "mav0/cam0/sensor.yaml"
    lines = path.read_text().splitlines()
    assert lines[0] == "%YAML:1.0" and lines[16].startswith("resolution:")
    lines[16] = "resolution: [752, 480"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError, match=rf"^{re.escape(str(path))}:18: YAML syntax error"):
        EUROC.open(tiny)


def test_groundtruth_csv_wrong_column_count(tiny: Path) -> None:
    path = tiny / "mav0/state_groundtruth_estimate0/data.csv"
    lines = path.read_text().splitlines()
    lines[2] = ",".join(lines[2].split(",")[:5])
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError, match=rf"^{re.escape(str(path))}:3: expected 8 comma-separated values"):
        EUROC.open(tiny)


def test_explicit_groundtruth_errors(tiny: Path, tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match=r"gt\.csv: ground-truth file not found"):
        EUROC.open(tiny, groundtruth=tmp_path / "gt.csv")
    bad = tmp_path / "short.csv"
    bad.write_text("#t,x\n1,2,3\n")
    with pytest.raises(DatasetError, match=rf"^{re.escape(str(bad))}:2: expected at least 8 comma-separated values"):
        EUROC.open(tiny, groundtruth=bad)


def test_stereo_without_cam1(euroc_dir: Path, tmp_path: Path) -> None:
    mono = _euroc_copy(euroc_dir, tmp_path / "mono", ("cam0",))
    with pytest.raises(DatasetError, match=r"mav0/cam1/data\.csv: stereo=True needs the right camera"):
        open_dataset("euroc", mono, stereo=True)
    assert len(open_dataset("euroc", mono)) == 95
