"""EuRoC adapter: the real V1_01_easy excerpt, ground-truth frames, write-back round trips and
the errors bad folders raise."""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

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
from sal_adapters.euroc import EUROC

SEQ = "V1_01_easy_micro"


@pytest.fixture(scope="module")
def euroc_dir(shared_data: Path) -> Path:
    path = shared_data / "euroc" / SEQ
    if not (path / "mav0").is_dir():
        pytest.skip(f"EuRoC excerpt not found at {path}")
    return path


def _T_BS(path: Path) -> np.ndarray:
    """T_BS of a sensor.yaml, parsed independently of the adapter."""
    text = path.read_text().replace("%YAML:1.0", "", 1)
    return np.array(yaml.safe_load(text)["T_BS"]["data"], dtype=float).reshape(4, 4)


def _csv_ns(path: Path) -> list[int]:
    return [int(line.split(",")[0]) for line in path.read_text().splitlines() if line and not line.startswith("#")]


def _open_stereo(path: Path, **options) -> Sequence:
    with pytest.warns(DatasetWarning, match=r"cam1/data\.csv: 4 of 99 rows skipped: 4 name image files that do not exist"):
        return open_dataset("euroc", path, stereo=True, **options)


def _assert_same(a: Sequence, b: Sequence, *, exact_ns: bool = True) -> None:
    """Same frames (pixels), timestamps, camera and ground truth."""
    assert len(a) == len(b) and a.sensor == b.sensor and a.fps == b.fps
    if exact_ns:
        assert [r.timestamp_ns for r in a.records] == [r.timestamp_ns for r in b.records]
        np.testing.assert_array_equal(a.timestamps, b.timestamps)
    else:
        np.testing.assert_allclose(a.timestamps, b.timestamps, rtol=0, atol=1e-9)
    for name in ("fx", "fy", "cx", "cy", "width", "height", "distortion", "depth_scale"):
        assert getattr(a.camera, name) == getattr(b.camera, name), name
    assert (a.camera.right is None) == (b.camera.right is None)
    if a.camera.right is not None:
        assert a.camera.right.to_dict() == b.camera.right.to_dict()
    if a.camera.T_left_right is None:
        assert b.camera.T_left_right is None
    else:
        np.testing.assert_allclose(a.camera.T_lr, b.camera.T_lr, rtol=0, atol=1e-9)
        assert b.camera.baseline_m == pytest.approx(a.camera.baseline_m, abs=1e-12)
    for fa, fb in zip(a, b):
        np.testing.assert_array_equal(fa.image, fb.image)
        if a.sensor == "stereo":
            np.testing.assert_array_equal(fa.right, fb.right)
    if a.groundtruth is None:
        assert b.groundtruth is None
    else:
        assert b.groundtruth is not None and a.groundtruth.allclose(b.groundtruth, atol=1e-9)


# -- the real excerpt ------------------------------------------------------------------------------
def test_real_excerpt_mono(euroc_dir: Path) -> None:
    seq = open_dataset("euroc", euroc_dir)
    assert (seq.kind, seq.name, seq.sensor, len(seq), seq.fps) == ("euroc", f"euroc/{SEQ}", "mono", 95, 20.0)
    cam = seq.camera
    assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height) == (458.654, 457.296, 367.215, 248.375, 752, 480)
    assert cam.distortion == pytest.approx((-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05))
    assert cam.baseline_m is None and cam.right is None and seq.grayscale
    ns = _csv_ns(euroc_dir / "mav0" / "cam0" / "data.csv")
    assert [r.timestamp_ns for r in seq.records] == ns
    assert [r.stem for r in seq.records] == [str(n) for n in ns]
    np.testing.assert_array_equal(seq.timestamps, np.array(ns) * 1e-9)
    dt = np.diff(seq.timestamps)
    assert np.all(dt > 0) and np.allclose(dt, 0.05, atol=1e-4)
    for frame in (seq[0], seq[94]):
        assert frame.image.shape == (480, 752, 3) and frame.image.dtype == np.uint8
        assert np.array_equal(frame.image[..., 0], frame.image[..., 1]) and np.array_equal(frame.image[..., 1], frame.image[..., 2])
        assert frame.right is None
    assert seq.groundtruth is not None and len(seq.groundtruth) == 78
    # ORB-SLAM3 evaluation file: already camera-0 poses, taken as they are
    gt_file = euroc_dir / "groundtruth_cam0_V101_GT_orbslam3_window.csv"
    assert seq.groundtruth.allclose(Trajectory.read_euroc(gt_file))
    assert seq.groundtruth.timestamps[0] == seq.timestamps[21]
    assert json.loads(json.dumps(seq.meta)) == seq.meta
    assert seq.meta["sequence"] == SEQ and np.allclose(seq.meta["T_BS_cam0"], _T_BS(euroc_dir / "mav0/cam0/sensor.yaml").ravel())


def test_parent_folder_and_sequence_option(euroc_dir: Path) -> None:
    by_name = open_dataset("euroc", euroc_dir.parent, sequence=SEQ)
    from_mav0 = open_dataset("euroc", euroc_dir / "mav0")
    assert by_name.source == from_mav0.source == euroc_dir
    assert len(by_name) == len(from_mav0) == 95


def test_real_excerpt_stereo(euroc_dir: Path) -> None:
    seq = _open_stereo(euroc_dir)
    assert seq.sensor == "stereo" and len(seq) == 95
    assert all(r.right is not None and r.right.is_file() and r.right.name == r.image.name for r in seq.records)
    T0 = _T_BS(euroc_dir / "mav0/cam0/sensor.yaml")
    T1 = _T_BS(euroc_dir / "mav0/cam1/sensor.yaml")
    T_lr = np.linalg.inv(T0) @ T1
    assert abs(np.linalg.norm(T1[:3, 3] - T0[:3, 3]) - 0.110) < 1e-3
    assert seq.camera.baseline_m == pytest.approx(np.linalg.norm(T_lr[:3, 3]), abs=1e-12)
    assert abs(seq.camera.baseline_m - 0.110) < 1e-3
    np.testing.assert_allclose(seq.camera.T_lr, T_lr, rtol=0, atol=1e-12)
    right = seq.camera.right
    assert right is not None and (right.fx, right.fy, right.cx, right.cy) == (457.587, 456.134, 379.999, 255.238)
    assert len(right.distortion) == 4
    frame = seq[10]
    assert frame.right.shape == frame.image.shape and not np.array_equal(frame.right, frame.image)


def test_max_frames_crops_groundtruth_to_the_window(euroc_dir: Path) -> None:
    seq = open_dataset("euroc", euroc_dir, max_frames=30)
    assert len(seq) == 30
    gt = seq.groundtruth
    assert gt is not None and 9 <= len(gt) <= 10
    t = seq.timestamps
    assert gt.timestamps[0] >= t[0] - 0.05 and gt.timestamps[-1] <= t[-1] + 0.05 + 1e-6
    later = open_dataset("euroc", euroc_dir, start=50, max_frames=10)
    assert later.groundtruth is not None and len(later.groundtruth) in (10, 11, 12)


def _euroc_copy(src: Path, dst: Path, cams: tuple[str, ...] = ("cam0", "cam1")) -> Path:
    """A EuRoC folder whose camera folders link to the real excerpt (no image copies)."""
    (dst / "mav0").mkdir(parents=True)
    for cam in cams:
        (dst / "mav0" / cam).mkdir()
        for name in ("data.csv", "sensor.yaml"):
            shutil.copy(src / "mav0" / cam / name, dst / "mav0" / cam / name)
        os.symlink(src / "mav0" / cam / "data", dst / "mav0" / cam / "data")
    return dst


def test_standard_body_frame_groundtruth(euroc_dir: Path, shared_data: Path, tmp_path: Path) -> None:
    v102 = shared_data / "trajectories" / "evo_test_data" / "V102_groundtruth.csv"
    if not v102.is_file():
        pytest.skip(f"{v102} not found")
    seq_dir = _euroc_copy(euroc_dir, tmp_path / SEQ, ("cam0",))
    gt_dir = seq_dir / "mav0" / "state_groundtruth_estimate0"
    gt_dir.mkdir()
    shutil.copy(v102, gt_dir / "data.csv")
    shutil.copy(euroc_dir / "mav0/state_groundtruth_estimate0/sensor.yaml", gt_dir / "sensor.yaml")
    seq = open_dataset("euroc", seq_dir)
    rows = np.loadtxt(v102, delimiter=",", comments="#")
    assert seq.groundtruth is not None and len(seq.groundtruth) == len(rows) == 16702
    T_BS = _T_BS(euroc_dir / "mav0/cam0/sensor.yaml")
    from scipy.spatial.transform import Rotation

    picks = [0, 5000, 16701]
    T_WB = np.tile(np.eye(4), (len(picks), 1, 1))
    T_WB[:, :3, :3] = Rotation.from_quat(rows[picks][:, [5, 6, 7, 4]]).as_matrix()
    T_WB[:, :3, 3] = rows[picks, 1:4]
    expected = T_WB @ T_BS
    np.testing.assert_allclose(seq.groundtruth.matrices[picks], expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(seq.groundtruth.timestamps[picks], rows[picks, 0] * 1e-9, rtol=0, atol=1e-6)
    # the same file given explicitly, as body or as camera poses
    explicit = open_dataset("euroc", euroc_dir, groundtruth=v102)
    assert explicit.groundtruth.allclose(seq.groundtruth)
    raw = open_dataset("euroc", euroc_dir, groundtruth=v102, groundtruth_frame="camera")
    np.testing.assert_allclose(raw.groundtruth.matrices[picks], T_WB, rtol=0, atol=1e-9)


def test_groundtruth_frame_override_and_absence(euroc_dir: Path, tmp_path: Path) -> None:
    as_body = open_dataset("euroc", euroc_dir, groundtruth_frame="body")
    T_BS = _T_BS(euroc_dir / "mav0/cam0/sensor.yaml")
    raw = Trajectory.read_euroc(euroc_dir / "groundtruth_cam0_V101_GT_orbslam3_window.csv")
    np.testing.assert_allclose(as_body.groundtruth.matrices, raw.matrices @ T_BS, rtol=0, atol=1e-9)
    bare = _euroc_copy(euroc_dir, tmp_path / "bare", ("cam0",))
    assert open_dataset("euroc", bare).groundtruth is None
    with pytest.raises(DatasetError, match="groundtruth_frame must be 'body' or 'camera'"):
        open_dataset("euroc", euroc_dir, groundtruth_frame="imu")


# -- writing back ----------------------------------------------------------------------------------
def test_round_trip_real_mono(euroc_dir: Path, tmp_path: Path) -> None:
    seq = open_dataset("euroc", euroc_dir)
    path = write_sequence(seq, tmp_path / "out")
    assert path == tmp_path / "out" / SEQ and (path / "mav0" / "cam0" / "data.csv").is_file()
    assert not (path / "mav0" / "cam1").exists()
    assert (path / "mav0" / "imu0" / "data.csv").read_bytes() == (euroc_dir / "mav0/imu0/data.csv").read_bytes()
    assert (path / "mav0" / "body.yaml").is_file()
    assert _csv_ns(path / "mav0/cam0/data.csv") == _csv_ns(euroc_dir / "mav0/cam0/data.csv")
    np.testing.assert_array_equal(_T_BS(path / "mav0/cam0/sensor.yaml"), _T_BS(euroc_dir / "mav0/cam0/sensor.yaml"))
    back = open_dataset("euroc", path)
    _assert_same(seq, back)
    assert back.grayscale and back.meta["T_BS_cam0"] == seq.meta["T_BS_cam0"]
    # ground truth was stored as body poses in the standard file
    body = Trajectory.read_euroc(path / "mav0/state_groundtruth_estimate0/data.csv")
    T_BS = _T_BS(euroc_dir / "mav0/cam0/sensor.yaml")
    np.testing.assert_allclose(body.matrices @ T_BS, seq.groundtruth.matrices, rtol=0, atol=1e-9)


def test_round_trip_real_stereo_with_dropped_frames(euroc_dir: Path, tmp_path: Path) -> None:
    seq = _open_stereo(euroc_dir)
    kept = [p for p in range(len(seq)) if p % 3 != 1][:40]
    cut = seq.select(kept)
    path = EUROC.write(cut, tmp_path, iter(cut))
    assert _csv_ns(path / "mav0/cam0/data.csv") == _csv_ns(path / "mav0/cam1/data.csv") == [r.timestamp_ns for r in cut.records]
    assert sorted(p.name for p in (path / "mav0/cam1/data").iterdir()) == sorted(f"{r.timestamp_ns}.png" for r in cut.records)
    np.testing.assert_array_equal(_T_BS(path / "mav0/cam1/sensor.yaml"), _T_BS(euroc_dir / "mav0/cam1/sensor.yaml"))
    back = open_dataset("euroc", path, stereo=True)  # no warning: every row has its files
    _assert_same(cut, back)
    assert back.camera.T_left_right == cut.camera.T_left_right  # source extrinsics kept bit for bit


def test_round_trip_changed_extrinsics(euroc_dir: Path, tmp_path: Path) -> None:
    seq = _open_stereo(euroc_dir, start=40, max_frames=3)
    assert seq.groundtruth is not None and len(seq.groundtruth) >= 3
    T = seq.camera.T_lr.copy()
    T[:3, 3] *= 1.5
    moved = seq.replace(camera=seq.camera.with_stereo(T, right=seq.camera.right))
    back = open_dataset("euroc", write_sequence(moved, tmp_path / "out"), stereo=True)
    _assert_same(moved, back)
    assert back.camera.baseline_m == pytest.approx(1.5 * seq.camera.baseline_m)


def _memory_sequence(*, stereo: bool, colour: bool, n: int = 5) -> Sequence:
    """A non-EuRoC sequence built from in-memory arrays, with per-frame ground truth."""
    rng = np.random.default_rng(3)
    h, w = 24, 32
    shape = (h, w, 3)

    def image(seed: int):
        def make() -> np.ndarray:
            pixels = np.random.default_rng(seed).integers(0, 256, size=shape, dtype=np.uint8)
            return pixels if colour else np.repeat(pixels[..., :1], 3, axis=2)

        return make

    times = 0.1 + np.arange(n) / 30.0 + rng.uniform(0, 1e-4, n)
    records = [
        FrameRecord(index=i, timestamp=float(t), stem=f"{i:06d}", image=image(i), right=image(100 + i) if stereo else None)
        for i, t in enumerate(times)
    ]
    camera = Camera(fx=30.5, fy=31.25, cx=15.5, cy=11.75, width=w, height=h, distortion=(0.1, -0.01, 1e-5, 0.0))
    if stereo:
        T = np.eye(4)
        T[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
        T[:3, 3] = (0.12, 0.003, -0.001)
        camera = camera.with_stereo(T, right=Camera(fx=29.0, fy=29.5, cx=16.0, cy=12.0, width=w, height=h))
    positions = rng.normal(size=(n, 3))
    quats = rng.normal(size=(n, 4))
    return Sequence(
        kind="synthetic",
        name="synthetic/memory test",
        camera=camera,
        sensor="stereo" if stereo else "mono",
        fps=30.0,
        records=records,
        groundtruth=Trajectory(times, positions, quats),
        grayscale=not colour,
        content_key="memory",
    )


@pytest.mark.parametrize(("stereo", "colour"), [(False, True), (True, False), (True, True)])
def test_round_trip_non_euroc_source(tmp_path: Path, stereo: bool, colour: bool) -> None:
    seq = _memory_sequence(stereo=stereo, colour=colour)
    path = write_sequence(seq, tmp_path / "out", layout="euroc")
    assert path == tmp_path / "out" / "memory_test"
    assert not (path / "mav0" / "imu0").exists()
    np.testing.assert_array_equal(_T_BS(path / "mav0/cam0/sensor.yaml"), np.eye(4))
    back = open_dataset("euroc", path, stereo=stereo)
    assert back.grayscale is (not colour) and back.kind == "euroc"
    assert back.groundtruth_is_per_frame
    assert [r.timestamp_ns for r in back.records] == [round(t * 1e9) for t in seq.timestamps]
    _assert_same(seq, back, exact_ns=False)
    # a second trip from the EuRoC copy is exact
    again = open_dataset("euroc", write_sequence(back, tmp_path / "again"), stereo=stereo)
    _assert_same(back, again)


def test_write_rectified_stereo_without_right_camera(tmp_path: Path) -> None:
    seq = _memory_sequence(stereo=True, colour=False, n=2)
    T = np.eye(4)
    T[0, 3] = 0.54
    seq = seq.replace(camera=Camera(fx=30.0, fy=30.0, cx=16.0, cy=12.0, width=32, height=24).with_stereo(T))
    back = open_dataset("euroc", write_sequence(seq, tmp_path / "out", layout="euroc"), stereo=True)
    assert back.camera.right is None and back.camera.baseline_m == 0.54
    _assert_same(seq, back, exact_ns=False)


def test_write_rgbd_keeps_images_and_warns(tmp_path: Path) -> None:
    seq = _memory_sequence(stereo=False, colour=True, n=2)
    records = [FrameRecord(r.index, r.timestamp, r.stem, r.image, depth=lambda: np.ones((24, 32), np.float32)) for r in seq.records]
    rgbd = seq.replace(sensor="rgbd", records=records)
    with pytest.warns(DatasetWarning, match="no depth maps"):
        path = write_sequence(rgbd, tmp_path / "out", layout="euroc")
    assert open_dataset("euroc", path).sensor == "mono"


def test_write_refuses_repeated_timestamps(tmp_path: Path) -> None:
    seq = _memory_sequence(stereo=False, colour=True, n=3)
    twice = seq.select([0, 1, 1])
    with pytest.raises(DatasetError, match="must increase"):
        EUROC.write(twice, tmp_path, iter(twice))


def test_write_refuses_images_of_another_size(tmp_path: Path) -> None:
    seq = _memory_sequence(stereo=True, colour=True, n=2)
    wrong = seq.replace(camera=seq.camera.with_stereo(seq.camera.T_lr, right=Camera(fx=1, fy=1, cx=0, cy=0, width=64, height=24)))
    with pytest.raises(DatasetError, match=r"frame 0 is 32x24 px but the camera is 64x24 px"):
        EUROC.write(wrong, tmp_path, iter(wrong))


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
    with pytest.raises(DatasetError, match=rf"^{re.escape(str(path))}:18: cannot parse YAML"):
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
