"""The dataset readers' YAML goes through the bounded loader of experiment configs: an alias
bomb, a 200 MB file or a 1e8x1e8 resolution in EuRoC ``sensor.yaml`` or a folder's
``camera.yaml`` is one short ``DatasetError`` naming the file (issue 23, item 8)."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import pytest
from euroc_excerpt import SEQ, _euroc_copy
from experiment_fuzz_configs import alias_bomb

from sal_adapters import DatasetError, open_dataset

LINE = 300  # characters of an error message


@pytest.fixture
def sensor_yaml(shared_data: Path, tmp_path: Path) -> Path:
    """cam0's ``sensor.yaml`` of a copy of the real EuRoC excerpt (images linked)."""
    return _euroc_copy(shared_data / "euroc" / SEQ, tmp_path / SEQ, cams=("cam0",)) / "mav0" / "cam0" / "sensor.yaml"


@pytest.fixture
def camera_yaml(shared_data: Path, tmp_path: Path) -> Path:
    """``camera.yaml`` of a folder of two real TUM frames."""
    folder = tmp_path / "frames"
    folder.mkdir()
    for name in sorted((shared_data / "tum_rgbd_samples").rglob("*.png"))[:2]:
        image = cv2.imread(str(name), cv2.IMREAD_COLOR)
        cv2.imwrite(str(folder / f"{len(list(folder.iterdir())):03d}.png"), cv2.resize(image, (640, 480)))
    path = folder / "camera.yaml"
    path.write_text("fx: 520.9\nfy: 521.0\ncx: 325.1\ncy: 249.7\nwidth: 640\nheight: 480\n")
    return path


def open_error(path: Path) -> str:
    """The one-line error of opening the dataset ``path`` (a sensor or camera file) belongs to."""
    kind, root = ("euroc", path.parents[2]) if path.name == "sensor.yaml" else ("folder", path.parent)
    with pytest.raises(DatasetError) as info:
        open_dataset(kind, root)
    message = str(info.value)
    assert message.startswith(f"{path}:") and message.isprintable() and len(message) <= LINE + len(str(path)), message[:2000]
    return message


def test_the_real_files_open(sensor_yaml: Path, camera_yaml: Path) -> None:
    assert open_dataset("euroc", sensor_yaml.parents[2]).camera.width == 752
    assert open_dataset("folder", camera_yaml.parent).camera.fx == 520.9


@pytest.mark.parametrize("key", ["intrinsics", "fx"])
def test_an_alias_bomb_is_one_short_line(sensor_yaml: Path, camera_yaml: Path, key: str) -> None:
    """Six levels of nine aliases (531 441 strings): the old readers built the value and put its
    repr() in the message (at nine levels they hung with growing memory)."""
    path = sensor_yaml if key == "intrinsics" else camera_yaml
    text = path.read_text().replace("%YAML:1.0\n", "")
    path.write_text(alias_bomb(6) + re.sub(rf"(?m)^{key}: .*$", f"{key}: *l5", text))
    assert open_error(path).endswith(
        "holds more than 10000 values once its YAML aliases are expanded; a dataset YAML file needs a few hundred"
    )


@pytest.mark.parametrize("which", ["sensor.yaml", "camera.yaml"])
def test_a_200_mb_file_is_refused_before_it_is_read(sensor_yaml: Path, camera_yaml: Path, which: str) -> None:
    path = sensor_yaml if which == "sensor.yaml" else camera_yaml
    with path.open("r+b") as handle:
        handle.truncate(200 * 2**20)  # sparse: nothing written
    assert open_error(path) == f"{path}: the file is 209715200 bytes; the limit is 100000 bytes"


def test_a_1e8_by_1e8_resolution_is_one_error_naming_the_key(sensor_yaml: Path) -> None:
    sensor_yaml.write_text(re.sub(r"(?m)^resolution: .*$", "resolution: [1e8, 1e8]", sensor_yaml.read_text()))
    assert open_error(sensor_yaml) == (
        f"{sensor_yaml}: key 'resolution' must be [width, height] (px): "
        "each side must be a whole number of pixels from 1 to 32768, got 100000000.0x100000000.0 px"
    )


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("intrinsics", "[1e300, 458.654, 367.215, 248.375]", "key 'intrinsics': camera fx must be > 0 px and at most 1e+06 px"),
        ("rate_hz", ".inf", "key 'rate_hz' must be a positive number of Hz up to 1e+06, got inf"),
        ("rate_hz", "1" + "0" * 400, "key 'rate_hz' must be a positive number of Hz up to 1e+06, got <an integer of about 401 digits>"),
        ("T_BS", "[1" + "0" * 400 + "]", "key 'T_BS' must hold 16 numbers (4x4 row-major), got [<an integer of about 401 digits>]"),
    ],
    ids=["huge focal length", "infinite rate", "400-digit rate", "400-digit T_BS"],
)
def test_sensor_values_out_of_range_are_one_line(sensor_yaml: Path, key: str, value: str, message: str) -> None:
    text = sensor_yaml.read_text()
    if key == "T_BS":
        text = re.sub(r"(?ms)^T_BS:.*?\]\n", "T_BS: " + value + "\n", text)
    else:
        text = re.sub(rf"(?m)^{key}: .*$", f"{key}: {value}", text)
    sensor_yaml.write_text(text)
    assert open_error(sensor_yaml).startswith(f"{sensor_yaml}: {message}")


def test_camera_yaml_values_out_of_range_are_one_line(camera_yaml: Path) -> None:
    text = camera_yaml.read_text()
    camera_yaml.write_text(text.replace("width: 640", "width: 1e8"))
    assert open_error(camera_yaml) == f"{camera_yaml}:5: width is 1e+08 px but the images are 640x480 px"
    camera_yaml.write_text(text.replace("fx: 520.9", "fx: 1e300"))
    assert open_error(camera_yaml) == f"{camera_yaml}: camera fx must be > 0 px and at most 1e+06 px, got 1e+300"
    camera_yaml.write_text(text.replace("fx: 520.9", f"fx: {'9' * 400}"))
    assert open_error(camera_yaml).startswith(f"{camera_yaml}:1: fx: expected a number, got <an integer of about 401 digits>")
