"""EuRoC adapter write-back: round trips of real mono and stereo (dropped frames, changed
extrinsics) and non-EuRoC sequences, and what writing refuses or warns about."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from euroc_excerpt import _T_BS, SEQ, _csv_ns, _memory_sequence, _open_stereo

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

#: the shared fixtures (euroc_dir)
pytest_plugins = ["euroc_excerpt"]


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
