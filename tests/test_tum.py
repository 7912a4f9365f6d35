"""TUM RGB-D adapter: association, Freiburg intrinsics, depth in metres, write-back, errors."""

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
from sal_adapters.tum import TUM, associate, freiburg_camera

FR1 = (517.3, 516.5, 318.6, 255.3)
FR1_DIST = (0.2624, -0.9531, -0.0054, 0.0026, 1.1633)
FR2 = (520.9, 521.0, 325.1, 249.7)
FR2_DIST = (0.2312, -0.7849, -0.0033, -0.0001, 0.9172)


# -- helpers -----------------------------------------------------------------------------------
def reference_associate(first: dict[float, str], second: dict[float, str], max_difference: float) -> list[tuple[float, float]]:
    """TUM's associate.py, written out independently (quadratic, dictionaries of times)."""
    first_keys, second_keys = list(first), list(second)
    candidates = sorted((abs(a - b), a, b) for a in first_keys for b in second_keys if abs(a - b) < max_difference)
    matches = []
    for _, a, b in candidates:
        if a in first_keys and b in second_keys:
            first_keys.remove(a)
            second_keys.remove(b)
            matches.append((a, b))
    return sorted(matches)


def read_list(path: Path) -> list[list[str]]:
    return [line.split() for line in path.read_text().splitlines() if line.strip() and not line.startswith("#")]


def times_of(path: Path) -> dict[float, str]:
    return {float(t): name for t, name in read_list(path)}


def write_png(path: Path, array: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), array)


def make_tum(
    root: Path,
    name: str = "rgbd_dataset_freiburg3_synth",
    frames: int = 6,
    depth_offsets: list[float] | None = None,
    seed: int = 0,
) -> Path:
    """A small TUM folder: random 32x24 colour frames, uint16 depth (with zeros), ground truth."""
    rng = np.random.default_rng(seed)
    folder = root / name
    rgb_lines, depth_lines, gt_lines = ["# color images"], ["# depth maps"], ["# timestamp tx ty tz qx qy qz qw"]
    for k in range(frames):
        t = 1305031102.175304 + k / 30.0
        td = t + (depth_offsets[k] if depth_offsets else 0.004)
        stem, dstem = f"{t:.6f}", f"{td:.6f}"
        write_png(folder / "rgb" / f"{stem}.png", rng.integers(0, 256, (24, 32, 3), dtype=np.uint8))
        depth = rng.integers(0, 40000, (24, 32), dtype=np.uint16)
        depth[:3, :3] = 0
        write_png(folder / "depth" / f"{dstem}.png", depth)
        rgb_lines.append(f"{stem} rgb/{stem}.png")
        depth_lines.append(f"{dstem} depth/{dstem}.png")
        gt_lines.append(f"{t:.4f} {0.1 * k} 0.2 0.3 0 0 0 1")
    (folder / "rgb.txt").write_text("\n".join(rgb_lines) + "\n")
    (folder / "depth.txt").write_text("\n".join(depth_lines) + "\n")
    (folder / "groundtruth.txt").write_text("\n".join(gt_lines) + "\n")
    return folder


@pytest.fixture
def fr1_lists(shared_data: Path) -> Path:
    return shared_data / "trajectories" / "tum_fr1_xyz_txt"


@pytest.fixture
def fr1_folder(fr1_lists: Path, tmp_path: Path) -> Path:
    """The real fr1_xyz lists with tiny placeholder images for every listed file."""
    folder = tmp_path / "rgbd_dataset_freiburg1_xyz"
    (folder / "rgb").mkdir(parents=True)
    (folder / "depth").mkdir()
    for name in ("rgb.txt", "depth.txt", "groundtruth.txt"):
        shutil.copy(fr1_lists / name, folder / name)
    colour = cv2.imencode(".png", np.zeros((6, 8, 3), np.uint8))[1].tobytes()
    depth = cv2.imencode(".png", np.full((6, 8), 5000, np.uint16))[1].tobytes()
    for list_name, data in (("rgb.txt", colour), ("depth.txt", depth)):
        for _, name in read_list(folder / list_name):
            (folder / name).write_bytes(data)
    return folder


# -- association on the real fr1_xyz lists ----------------------------------------------------
def test_associate_matches_reference_on_fr1_xyz(fr1_lists: Path) -> None:
    rgb, depth = times_of(fr1_lists / "rgb.txt"), times_of(fr1_lists / "depth.txt")
    expected = reference_associate(rgb, depth, 0.02)
    pairs = associate(np.array(list(rgb)), np.array(list(depth)), 0.02)
    rgb_t, depth_t = np.array(list(rgb)), np.array(list(depth))
    got = [(rgb_t[i], depth_t[j]) for i, j in pairs]
    assert len(rgb) == len(depth) == 798
    assert len(pairs) == len(expected) == 792
    assert got == expected
    assert np.all(np.abs(rgb_t[pairs[:, 0]] - depth_t[pairs[:, 1]]) < 0.02)
    assert len(set(pairs[:, 0])) == len(set(pairs[:, 1])) == len(pairs)


def test_associate_is_greedy_by_smallest_difference() -> None:
    # depth 1.005 is nearest to both colour times; the closer one (1.006) takes it
    pairs = associate(np.array([1.0, 1.006, 2.0]), np.array([1.005, 1.015, 3.0]), 0.02)
    assert pairs.tolist() == [[0, 1], [1, 0]]
    assert associate(np.array([1.0]), np.array([1.02]), 0.02).shape == (0, 2)  # strict <, as associate.py


def test_open_fr1_xyz(fr1_folder: Path) -> None:
    with pytest.warns(DatasetWarning, match=r"6 of 798 colour frames have no depth map within 0.02 s"):
        seq = open_dataset("tum", fr1_folder)
    rgb, depth = times_of(fr1_folder / "rgb.txt"), times_of(fr1_folder / "depth.txt")
    expected = reference_associate(rgb, depth, 0.02)
    assert len(seq) == len(expected) == 792
    assert seq.sensor == "rgbd" and seq.name == "tum/rgbd_dataset_freiburg1_xyz"
    assert (seq.camera.fx, seq.camera.fy, seq.camera.cx, seq.camera.cy) == FR1
    assert seq.camera.distortion == FR1_DIST
    assert seq.camera.depth_scale == 5000.0
    assert (seq.camera.width, seq.camera.height) == (8, 6)
    assert seq.groundtruth is not None and len(seq.groundtruth) == 3000
    assert 29.0 < seq.fps < 32.0
    rgb_times = list(rgb)
    for record, (t_rgb, t_depth) in zip(seq.records, expected):
        assert record.timestamp == t_rgb
        assert record.index == rgb_times.index(t_rgb)
        assert record.stem == Path(rgb[t_rgb]).stem
        assert record.depth == fr1_folder / depth[t_depth]
    assert seq.records[0].stem == "1305031102.175304"
    assert np.all(seq[0].depth == 1.0)


def test_open_by_short_sequence_name_and_colour_only(fr1_folder: Path) -> None:
    for name in ("fr1_xyz", "freiburg1_xyz", "rgbd_dataset_freiburg1_xyz"):
        with pytest.warns(DatasetWarning):
            seq = TUM.open(fr1_folder.parent, sequence=name)
        assert seq.source == fr1_folder
    mono = TUM.open(fr1_folder, depth=False)
    assert mono.sensor == "mono" and len(mono) == 798 and mono.camera.depth_scale is None
    assert mono.indices.tolist() == list(range(798))
    with pytest.raises(DatasetError, match=r"TUM sequence 'fr2_desk' not found"):
        TUM.open(fr1_folder.parent, sequence="fr2_desk")


# -- the real RGB-D pairs ---------------------------------------------------------------------
def test_real_rgbd_pair_depth_in_metres(ch7_folder: Path, shared_data: Path) -> None:
    seq = open_dataset("tum", ch7_folder)
    assert seq.sensor == "rgbd" and len(seq) == 2
    assert (seq.camera.fx, seq.camera.fy, seq.camera.cx, seq.camera.cy) == FR2
    assert seq.camera.distortion == FR2_DIST and seq.camera.depth_scale == 5000.0
    assert (seq.camera.width, seq.camera.height) == (640, 480)
    src = shared_data / "tum_rgbd_samples" / "slambook2_tum_like"
    for k, frame in enumerate(seq, start=1):
        assert frame.image.shape == (480, 640, 3) and frame.image.dtype == np.uint8
        bgr = cv2.imread(str(src / f"ch7_{k}.png"), cv2.IMREAD_COLOR)
        assert np.array_equal(frame.image, bgr[..., ::-1])
        raw = cv2.imread(str(src / f"ch7_{k}_depth.png"), cv2.IMREAD_UNCHANGED)
        assert raw.dtype == np.uint16
        assert frame.depth.dtype == np.float32
        assert np.array_equal(frame.depth, raw.astype(np.float32) / np.float32(5000.0))
        assert np.any(raw == 0) and np.all(frame.depth[raw == 0] == 0)
        assert frame.depth.max() == pytest.approx(raw.max() / 5000.0)
    assert seq.groundtruth is not None and len(seq.groundtruth) == 3
    assert seq.fps == pytest.approx(1 / (1311868164.399454 - 1311868164.363181))


def test_freiburg_camera_from_name() -> None:
    assert freiburg_camera("rgbd_dataset_freiburg1_xyz") == 1
    assert freiburg_camera("fr2_desk") == 2
    assert freiburg_camera("TUM-FR3-office") == 3
    assert freiburg_camera("frame_12") is None
    assert freiburg_camera("fr12") is None


def test_unknown_camera_warns_and_intrinsics_override(tmp_path: Path) -> None:
    folder = make_tum(tmp_path, name="my_sequence")
    with pytest.warns(DatasetWarning, match=r"ROS default intrinsics fx=525.0.*intrinsics=\(fx, fy, cx, cy\)"):
        seq = TUM.open(folder)
    assert (seq.camera.fx, seq.camera.cx, seq.camera.distortion) == (525.0, 319.5, ())
    seq = TUM.open(folder, intrinsics=(100.0, 101.0, 15.5, 11.5))
    assert (seq.camera.fx, seq.camera.fy, seq.camera.cx, seq.camera.cy, seq.camera.distortion) == (100.0, 101.0, 15.5, 11.5, ())
    seq = TUM.open(folder, intrinsics="100 101 15.5 11.5", distortion="0.1, -0.2, 0, 0")
    assert seq.camera.distortion == (0.1, -0.2, 0.0, 0.0)
    fr1 = TUM.open(make_tum(tmp_path, name="rgbd_dataset_freiburg1_desk"), distortion=[0, 0, 0, 0, 0])
    assert fr1.camera.fx == 517.3 and fr1.camera.distortion == (0.0,) * 5


def test_associations_file_is_used(tmp_path: Path) -> None:
    folder = make_tum(tmp_path)
    rgb, depth = read_list(folder / "rgb.txt"), read_list(folder / "depth.txt")
    # pair frames 1 and 4 with each other's depth (a file may pair anything)
    lines = [f"{rgb[1][0]} {rgb[1][1]} {depth[4][0]} {depth[4][1]}", f"{rgb[4][0]} {rgb[4][1]} {depth[1][0]} {depth[1][1]}"]
    (folder / "associations.txt").write_text("\n".join(lines) + "\n")
    seq = TUM.open(folder)
    assert seq.indices.tolist() == [1, 4]
    assert [r.depth for r in seq.records] == [folder / depth[4][1], folder / depth[1][1]]


# -- write-back -------------------------------------------------------------------------------
def test_round_trip_real_pair(ch7_folder: Path, tmp_path: Path) -> None:
    seq = open_dataset("tum", ch7_folder)
    path = write_sequence(seq, tmp_path / "copy")
    assert "freiburg" not in str(path)
    back = open_dataset("tum", path)
    assert back.sensor == "rgbd" and back.camera == seq.camera and back.grayscale == seq.grayscale
    assert_same_frames(seq, back)
    assert back.groundtruth is not None and back.groundtruth.allclose(seq.groundtruth, atol=0)
    assert np.array_equal(back.groundtruth.timestamps, seq.groundtruth.timestamps)
    assert back.fps == seq.fps


def test_round_trip_with_dropped_frames_keeps_lists_consistent(tmp_path: Path) -> None:
    # frame 3's depth is 25 ms away: it has no partner and is left out at open
    folder = make_tum(tmp_path, frames=7, depth_offsets=[0.004, -0.003, 0.01, 0.025, 0.0, 0.002, -0.001])
    with pytest.warns(DatasetWarning, match="1 of 7"):
        seq = TUM.open(folder)
    assert seq.indices.tolist() == [0, 1, 2, 4, 5, 6]
    kept = seq.select([0, 2, 3, 5])
    path = write_sequence(kept, tmp_path / "out")
    stems = [r.stem for r in kept.records]
    rgb, depth, assoc = (read_list(path / n) for n in ("rgb.txt", "depth.txt", "associations.txt"))
    assert [row[1] for row in rgb] == [f"rgb/{s}.png" for s in stems]
    assert [row[1] for row in depth] == [f"depth/{s}.png" for s in stems]
    assert [row[1] for row in assoc] == [row[1] for row in rgb] and [row[3] for row in assoc] == [row[1] for row in depth]
    assert [float(row[0]) for row in rgb] == kept.timestamps.tolist() == [float(row[2]) for row in assoc]
    assert sorted(p.stem for p in (path / "rgb").iterdir()) == sorted(stems)
    assert sorted(p.stem for p in (path / "depth").iterdir()) == sorted(stems)
    back = TUM.open(path)
    assert back.camera == kept.camera
    assert_same_frames(kept, back)
    assert back.groundtruth.allclose(seq.groundtruth, atol=0)


def test_write_any_sequence_and_reopen(tmp_path: Path) -> None:
    """A hand-made RGB-D sequence (no files, no Freiburg name) survives tum write + reopen."""
    rng = np.random.default_rng(3)
    images = rng.integers(0, 256, (4, 12, 16, 3), dtype=np.uint8)
    raw = rng.integers(0, 60000, (4, 12, 16)).astype(np.uint16)
    depths = raw.astype(np.float32) / np.float32(5000.0)  # representable exactly in the TUM format
    times = 100.0 + np.array([0.0, 0.0999999, 0.2000001, 0.3333333333])
    records = [
        FrameRecord(index=k, timestamp=float(times[k]), stem=f"{k:06d}", image=lambda k=k: images[k], depth=lambda k=k: depths[k])
        for k in range(4)
    ]
    camera = Camera(fx=20.5, fy=21.25, cx=7.5, cy=5.5, width=16, height=12, distortion=(0.01, -0.002, 0.0, 0.0), depth_scale=5000.0)
    gt = Trajectory(times, rng.normal(size=(4, 3)), rng.normal(size=(4, 4)))
    seq = Sequence(kind="synthetic", name="synthetic/test", camera=camera, sensor="rgbd", fps=10.0, records=records, groundtruth=gt)
    path = write_sequence(seq.select([0, 1, 3]), tmp_path / "tum_copy", layout="tum")
    back = TUM.open(path)  # camera.yaml: no warning, same camera
    assert back.camera == camera
    assert_same_frames(seq.select([0, 1, 3]), back)
    assert back.groundtruth.allclose(seq.select([0, 1, 3]).groundtruth)
    mono = write_sequence(seq.replace(sensor="mono", grayscale=False), tmp_path / "mono_copy", layout="tum")
    assert not (mono / "depth.txt").exists() and not (mono / "depth").exists()
    back = TUM.open(mono)
    assert back.sensor == "mono" and back.camera.depth_scale is None and len(back) == 4


def test_grey_sequence_round_trip(tmp_path: Path) -> None:
    grey = np.random.default_rng(5).integers(0, 256, (3, 10, 14), dtype=np.uint8)
    records = [
        FrameRecord(index=k, timestamp=0.1 * k, stem=f"{k:06d}", image=lambda k=k: np.repeat(grey[k][..., None], 3, axis=2))
        for k in range(3)
    ]
    camera = Camera(fx=14.0, fy=14.0, cx=6.5, cy=4.5, width=14, height=10)
    seq = Sequence(kind="kitti", name="kitti/xx", camera=camera, sensor="mono", fps=10.0, records=records, grayscale=True)
    path = write_sequence(seq, tmp_path / "grey", layout="tum")
    assert cv2.imread(str(path / "rgb" / "000001.png"), cv2.IMREAD_UNCHANGED).ndim == 2
    back = TUM.open(path)
    assert back.grayscale and back.camera == camera
    assert_same_frames(seq, back)


# -- errors -----------------------------------------------------------------------------------
def test_missing_folder_and_rgb_txt(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match=r"TUM dataset folder not found"):
        TUM.open(tmp_path / "nope")
    with pytest.raises(DatasetError, match=r"tum dataset folder not found"):
        open_dataset("tum", tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DatasetError) as info:
        open_dataset("tum", tmp_path / "empty")
    assert str(info.value).startswith(f"{tmp_path / 'empty' / 'rgb.txt'}: file not found")
    with pytest.raises(DatasetError, match="needs a path"):
        TUM.open(None)


def test_stereo_is_refused(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="no stereo"):
        TUM.open(make_tum(tmp_path), stereo=True)


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("1305031102.3", "expected 2 fields 'timestamp filename', got 1"),
        ("abc rgb/x.png", "expected a timestamp in seconds, got 'abc'"),
        ("1305031102.1 rgb/x.png", "time 1305031102.1 s is not after line 3's"),
    ],
)
def test_malformed_rgb_txt_names_file_and_line(tmp_path: Path, line: str, message: str) -> None:
    folder = make_tum(tmp_path)
    lines = (folder / "rgb.txt").read_text().splitlines()
    lines.insert(3, line)  # becomes line 4
    (folder / "rgb.txt").write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError) as info:
        TUM.open(folder)
    assert str(info.value).startswith(f"{folder / 'rgb.txt'}:4: ")
    assert message in str(info.value)


def test_groundtruth_with_wrong_columns_names_file_and_line(tmp_path: Path) -> None:
    folder = make_tum(tmp_path)
    lines = (folder / "groundtruth.txt").read_text().splitlines()
    lines[2] = "1305031102.2 1 2 3 0 0 1"
    (folder / "groundtruth.txt").write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError) as info:
        TUM.open(folder)
    assert str(info.value).startswith(f"{folder / 'groundtruth.txt'}:3: expected 8 values")


def test_unreadable_images_are_named(tmp_path: Path) -> None:
    folder = make_tum(tmp_path)
    rgb = read_list(folder / "rgb.txt")
    (folder / rgb[0][1]).write_bytes(b"not a png")
    with pytest.raises(DatasetError) as info:
        TUM.open(folder)
    assert str(info.value).startswith(f"{folder / rgb[0][1]}: cannot decode image")

    folder = make_tum(tmp_path, name="rgbd_dataset_freiburg3_b")
    rgb = read_list(folder / "rgb.txt")
    (folder / rgb[2][1]).write_bytes(b"")
    (folder / rgb[3][1]).unlink()
    seq = TUM.open(folder)  # only the first image is decoded at open
    with pytest.raises(DatasetError, match="^" + re.escape(f"{folder / rgb[2][1]}: cannot decode image")):
        seq[2].image
    with pytest.raises(DatasetError, match="^" + re.escape(f"{folder / rgb[3][1]}: image file not found")):
        seq[3].image


def test_missing_depth_is_named(tmp_path: Path) -> None:
    folder = make_tum(tmp_path)
    (folder / "depth.txt").unlink()
    with pytest.raises(DatasetError, match=r"depth.txt: file not found \(open with depth=False"):
        TUM.open(folder, depth=True)
    assert TUM.open(folder).sensor == "mono"  # default: RGB-D only where depth.txt exists
    folder = make_tum(tmp_path, name="rgbd_dataset_freiburg3_c")
    first_depth = folder / read_list(folder / "depth.txt")[0][1]
    first_depth.unlink()
    with pytest.raises(DatasetError, match="^" + re.escape(f"{first_depth}: depth image not found")):
        TUM.open(folder)


def test_bad_associations_line(tmp_path: Path) -> None:
    folder = make_tum(tmp_path)
    (folder / "associations.txt").write_text("# t rgb t depth\n1.0 rgb/other.png 1.0 depth/x.png\n")
    with pytest.raises(DatasetError) as info:
        TUM.open(folder)
    assert str(info.value).startswith(f"{folder / 'associations.txt'}:2: colour image rgb/other.png is not listed in rgb.txt")


def test_bad_options(tmp_path: Path) -> None:
    folder = make_tum(tmp_path)
    with pytest.raises(DatasetError, match="max_time_diff must be > 0"):
        TUM.open(folder, max_time_diff=0)
    with pytest.raises(DatasetError, match=r"option intrinsics .* needs 4 finite numbers"):
        TUM.open(folder, intrinsics=(1.0, 2.0))
    with pytest.raises(DatasetError, match="no colour frame of rgb.txt has a depth map"):
        TUM.open(folder, max_time_diff=0.001)


def test_kitti_frames_written_as_tum(shared_data: Path, tmp_path: Path) -> None:
    """A real KITTI (grey, mono) excerpt with dropped frames reopens from the TUM layout."""
    kitti = open_dataset("kitti", shared_data / "kitti" / "sequences" / "07", max_frames=6).select([0, 1, 4])
    path = write_sequence(kitti, tmp_path / "kitti_as_tum", layout="tum")
    assert [row[1] for row in read_list(path / "rgb.txt")] == ["rgb/000000.png", "rgb/000001.png", "rgb/000004.png"]
    back = TUM.open(path)
    assert back.sensor == "mono" and back.grayscale and back.camera == kitti.camera
    assert_same_frames(kitti, back)
    assert back.groundtruth.allclose(kitti.groundtruth)
