"""Folder-of-images adapter and the shared camera.yaml: timestamps, intrinsics, write-back, errors."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from sequence_asserts import assert_same_frames

from sal_adapters import (
    Camera,
    DatasetError,
    DatasetWarning,
    FrameRecord,
    Sequence,
    Trajectory,
    open_dataset,
    write_sequence,
)
from sal_adapters.folder import FOLDER
from sal_adapters.layout_io import natural_key, read_camera_yaml, write_camera_yaml

FR3 = (535.4, 539.2, 320.1, 247.6)
FR3_STAMPS = ["1341847980.722988", "1341847984.106759", "1341847987.458620", "1341847990.710795"]


def write_png(path: Path, array: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), array)


def make_folder(root: Path, names: list[str], shape: tuple[int, ...] = (6, 8, 3), seed: int = 0) -> Path:
    rng = np.random.default_rng(seed)
    root.mkdir(parents=True, exist_ok=True)
    for name in names:
        write_png(root / name, rng.integers(0, 256, shape, dtype=np.uint8))
    (root / "camera.yaml").write_text("fx: 8\nfy: 8\ncx: 3.5\ncy: 2.5\n")
    return root


@pytest.fixture
def fr3_folder(shared_data: Path) -> Path:
    return shared_data / "tum_rgbd_samples" / "fr3_long_office_household_4frames_pyslam"


# -- the real fr3 frames ----------------------------------------------------------------------
def test_fr3_frames_timestamps_from_names(fr3_folder: Path) -> None:
    seq = open_dataset("folder", fr3_folder, intrinsics=FR3)
    assert len(seq) == 4 and seq.sensor == "mono" and not seq.grayscale
    assert seq.timestamps.tolist() == [float(t) for t in FR3_STAMPS]
    assert seq.timestamps[0] == 1341847980.722988
    assert [r.stem for r in seq.records] == FR3_STAMPS
    assert (seq.camera.fx, seq.camera.fy, seq.camera.cx, seq.camera.cy) == FR3
    assert (seq.camera.width, seq.camera.height, seq.camera.distortion) == (640, 480, ())
    assert seq.fps == pytest.approx(1.0 / np.median(np.diff(seq.timestamps)))
    assert seq[3].image.shape == (480, 640, 3)
    assert seq.groundtruth is None


def test_assumed_intrinsics_warn(fr3_folder: Path) -> None:
    with pytest.warns(DatasetWarning, match=r"assuming fx=fy=640 px.*cx=319.5 cy=239.5.*intrinsics=\(fx, fy, cx, cy\)"):
        seq = FOLDER.open(fr3_folder)
    assert (seq.camera.fx, seq.camera.fy, seq.camera.cx, seq.camera.cy) == (640.0, 640.0, 319.5, 239.5)


def test_round_trip_real_frames_with_groundtruth_and_drops(fr3_folder: Path, tmp_path: Path) -> None:
    seq = FOLDER.open(fr3_folder, intrinsics=FR3, distortion=(0.01, -0.02, 0.001, 0.0, 0.003))
    gt = Trajectory(seq.timestamps, [[0, 0, 0], [0.1, 0, 0], [0.2, 0.1, 0], [0.3, 0.1, 0.05]], [[0, 0, 0, 1]] * 4)
    seq = seq.replace(groundtruth=gt)
    path = write_sequence(seq, tmp_path / "all")
    back = open_dataset("folder", path)
    assert back.camera == seq.camera and back.fps == seq.fps and not back.grayscale
    assert_same_frames(seq, back)
    assert back.groundtruth.allclose(gt, atol=0) and np.array_equal(back.groundtruth.timestamps, gt.timestamps)

    kept = seq.select([0, 2, 3])
    path = write_sequence(kept, tmp_path / "kept")
    lines = [line.split() for line in (path / "timestamps.txt").read_text().splitlines() if not line.startswith("#")]
    assert [name for _, name in lines] == [f"{FR3_STAMPS[i]}.png" for i in (0, 2, 3)]
    assert [float(t) for t, _ in lines] == kept.timestamps.tolist()
    assert sorted(p.name for p in path.glob("*.png")) == [f"{FR3_STAMPS[i]}.png" for i in (0, 2, 3)]
    back = FOLDER.open(path)
    assert_same_frames(kept, back)
    assert back.camera == seq.camera
    assert back.groundtruth.allclose(kept.groundtruth, atol=0)


# -- timestamps -------------------------------------------------------------------------------
def test_natural_order_and_default_rate(tmp_path: Path) -> None:
    folder = make_folder(tmp_path / "imgs", ["img10.png", "img2.png", "img1.png", ".hidden.png"])
    (folder / "notes.txt").write_text("not an image")
    seq = FOLDER.open(folder)
    assert [r.stem for r in seq.records] == ["img1", "img2", "img10"]
    assert seq.timestamps.tolist() == [0.0, 1 / 30, 2 / 30] and seq.fps == pytest.approx(30.0)
    seq = FOLDER.open(folder, fps=10)
    assert seq.timestamps.tolist() == [0.0, 0.1, 0.2] and seq.fps == 10.0
    assert sorted(["a10", "a9", "b1", "a09x"], key=natural_key) == ["a9", "a09x", "a10", "b1"]


def test_frame_number_stems_are_not_times(tmp_path: Path) -> None:
    seq = FOLDER.open(make_folder(tmp_path / "k", ["000000.png", "000001.png", "000002.png"]), fps=10)
    assert seq.timestamps.tolist() == [0.0, 0.1, 0.2]


def test_nanosecond_stems(tmp_path: Path) -> None:
    seq = FOLDER.open(make_folder(tmp_path / "e", ["1403715273312143104.png", "1403715273262142976.png"]))
    assert [r.timestamp_ns for r in seq.records] == [1403715273262142976, 1403715273312143104]
    assert seq.timestamps[0] == 1403715273262142976 * 1e-9


def test_one_time_per_line_files(tmp_path: Path) -> None:
    folder = make_folder(tmp_path / "t", ["a1.png", "a2.png", "a3.png"])
    (folder / "times.txt").write_text("0.0\n0.05\n0.1\n")
    assert FOLDER.open(folder).timestamps.tolist() == [0.0, 0.05, 0.1]
    (folder / "timestamps.txt").write_text("# time\n1.0\n1.5\n2.0\n")  # preferred over times.txt
    seq = FOLDER.open(folder)
    assert seq.timestamps.tolist() == [1.0, 1.5, 2.0] and seq.fps == 2.0
    (tmp_path / "mine.txt").write_text("5\n6\n7\n")
    assert FOLDER.open(folder, timestamps=tmp_path / "mine.txt").timestamps.tolist() == [5.0, 6.0, 7.0]
    (folder / "other.txt").write_text("8\n9\n10\n")
    assert FOLDER.open(folder, timestamps="other.txt").timestamps.tolist() == [8.0, 9.0, 10.0]


def test_tum_style_list_defines_frames(tmp_path: Path) -> None:
    folder = make_folder(tmp_path / "l", ["x.png", "y.png", "z.png"])
    (folder / "timestamps.txt").write_text("# timestamp filename\n10.5 z.png\n11.25 x.png\n")
    seq = FOLDER.open(folder)
    assert [r.stem for r in seq.records] == ["z", "x"] and seq.timestamps.tolist() == [10.5, 11.25]


def test_grey_images(tmp_path: Path) -> None:
    folder = make_folder(tmp_path / "g", ["0.png", "1.png"], shape=(6, 8))
    seq = FOLDER.open(folder)
    assert seq.grayscale and seq[0].image.shape == (6, 8, 3)
    path = write_sequence(seq, tmp_path / "g_copy")
    assert cv2.imread(str(path / "0.png"), cv2.IMREAD_UNCHANGED).ndim == 2
    back = FOLDER.open(path)
    assert back.grayscale
    assert_same_frames(seq, back)


def test_write_rgbd_sequence_keeps_colour_only(tmp_path: Path) -> None:
    image = np.full((4, 6, 3), 7, np.uint8)
    records = [
        FrameRecord(index=k, timestamp=0.5 * k, stem=f"f/{k}", image=lambda: image, depth=lambda: np.ones((4, 6), np.float32))
        for k in range(2)
    ]
    camera = Camera(fx=5.0, fy=5.0, cx=2.5, cy=1.5, width=6, height=4, depth_scale=5000.0)
    seq = Sequence(kind="synthetic", name="synthetic/x", camera=camera, sensor="rgbd", fps=2.0, records=records)
    with pytest.warns(DatasetWarning, match="depth maps are not written"):
        path = write_sequence(seq, tmp_path / "out", layout="folder")
    back = FOLDER.open(path)
    assert [r.stem for r in back.records] == ["000000", "000001"]  # unusable stems are replaced
    assert back.camera == Camera(fx=5.0, fy=5.0, cx=2.5, cy=1.5, width=6, height=4)
    assert back.timestamps.tolist() == [0.0, 0.5]


# -- camera.yaml (shared with tum) ------------------------------------------------------------
def test_camera_yaml_round_trip(tmp_path: Path) -> None:
    camera = Camera(fx=517.3, fy=516.5, cx=318.6, cy=255.3, width=640, height=480, distortion=(0.2624, -0.9531, -0.0054, 1e-05, 1.1633))
    write_camera_yaml(tmp_path / "camera.yaml", camera, depth_scale=5000.0)
    back = read_camera_yaml(tmp_path / "camera.yaml", 640, 480)
    assert back.distortion == camera.distortion and back.depth_scale == 5000.0
    assert back == Camera(**{**camera.to_dict(), "depth_scale": 5000.0, "distortion": camera.distortion})


@pytest.mark.parametrize(
    ("text", "line", "message"),
    [
        ("fx: 8\nfy: 8\ncx: 3.5\ncy: 2.5\nfocal: 3\n", 5, "unknown key 'focal'"),
        ("fx: 8\nfy: [1\ncx: 3.5\n", 3, "YAML syntax error"),
        ("fx: 8\nfy: eight\ncx: 3.5\ncy: 2.5\n", 2, "fy: expected a number, got 'eight'"),
        ("fx: 8\nfy: 8\ncx: 3.5\ncy: 2.5\nwidth: 640\n", 5, "width is 640 px but the images are 8x6 px"),
        ("fx: 8\nfy: 8\ncx: 3.5\ncy: 2.5\ndistortion: [1, 2]\n", 5, "distortion must be a list of 4, 5, 8, 12, 14 numbers"),
        ("fx: -8\nfy: 8\ncx: 3.5\ncy: 2.5\n", None, "camera fx must be > 0 px"),
        ("fx: 8\nfy: 8\ncx: 3.5\n", None, "missing cy (px)"),
    ],
)
def test_bad_camera_yaml_names_file_and_line(tmp_path: Path, text: str, line: int | None, message: str) -> None:
    folder = make_folder(tmp_path / "c", ["a.png"])
    (folder / "camera.yaml").write_text(text)
    with pytest.raises(DatasetError) as info:
        FOLDER.open(folder)
    where = f"{folder / 'camera.yaml'}:{line}: " if line else f"{folder / 'camera.yaml'}: "
    assert str(info.value).startswith(where)
    assert message in str(info.value)


# -- errors -----------------------------------------------------------------------------------
def test_errors(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="image folder not found"):
        FOLDER.open(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DatasetError, match=r"empty: no images found"):
        FOLDER.open(tmp_path / "empty")
    folder = make_folder(tmp_path / "f", ["a.png", "b.png"])
    with pytest.raises(DatasetError, match="monocular"):
        FOLDER.open(folder, stereo=True)
    with pytest.raises(DatasetError, match="fps must be > 0"):
        FOLDER.open(folder, fps=0)
    with pytest.raises(DatasetError, match="timestamps file not found"):
        FOLDER.open(folder, timestamps="missing.txt")


@pytest.mark.parametrize(
    ("text", "line", "message"),
    [
        ("0.0\n0.1\n0.2\n", None, "3 timestamps for 2 images"),
        ("0.0\nzero\n", 2, "expected a timestamp in seconds, got 'zero'"),
        ("0.0\n0.0\n", 2, "time 0.0 s is not after line 1's 0.0 s (frame times must increase)"),
        ("0.0 a.png\n0.1\n", 2, "expected 2 fields 'timestamp filename', got 1"),
        ("# t name\n0.0 a.png\n0.1 c.png\n", 3, "listed image c.png not found"),
        ("0.0 a.png extra\n", 1, "expected 'timestamp' or 'timestamp filename' per line, got 3 fields"),
    ],
)
def test_bad_timestamps_file_names_file_and_line(tmp_path: Path, text: str, line: int | None, message: str) -> None:
    folder = make_folder(tmp_path / "f", ["a.png", "b.png"])
    (folder / "timestamps.txt").write_text(text)
    with pytest.raises(DatasetError) as info:
        FOLDER.open(folder)
    where = f"{folder / 'timestamps.txt'}:{line}: " if line else f"{folder / 'timestamps.txt'}: "
    assert str(info.value).startswith(where)
    assert message in str(info.value)


def test_unreadable_first_image_is_named(tmp_path: Path, fr3_folder: Path) -> None:
    folder = tmp_path / "broken"
    folder.mkdir()
    shutil.copy(fr3_folder / f"{FR3_STAMPS[1]}.png", folder / f"{FR3_STAMPS[1]}.png")
    (folder / f"{FR3_STAMPS[0]}.png").write_bytes(b"\x89PNG broken")
    with pytest.raises(DatasetError, match="^" + re.escape(f"{folder / FR3_STAMPS[0]}.png: cannot decode image")):
        FOLDER.open(folder, intrinsics=FR3)


def test_bad_groundtruth_names_line(tmp_path: Path) -> None:
    folder = make_folder(tmp_path / "f", ["a.png", "b.png"])
    (folder / "groundtruth.txt").write_text("# t tx ty tz qx qy qz qw\n0 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 1\n")
    with pytest.raises(DatasetError, match="^" + re.escape(f"{folder / 'groundtruth.txt'}:3: expected 8 values")):
        FOLDER.open(folder)
