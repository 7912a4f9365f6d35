"""EuRoC adapter reading the real V1_01_easy excerpt: mono and stereo, the parent folder and
sequence option, cropping, and the ground-truth body frame, its override and absence."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from euroc_excerpt import _T_BS, SEQ, _csv_ns, _euroc_copy, _open_stereo

from sal_adapters import (
    DatasetError,
    Trajectory,
    open_dataset,
)

#: the shared fixtures (euroc_dir)
pytest_plugins = ["euroc_excerpt"]


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
