"""tools/make_rosbags.py (issue 26): the KITTI 07 and EuRoC V1_01 excerpts written as a ROS 1
bag, a ROS 2 sqlite3 bag, a ROS 2 MCAP bag and a bare MCAP file, read back with rosbags' own reader: every topic
has one message per frame (or per ground-truth pose, per IMU sample), the pixels and stamps are
the folder adapters' to the bit, the calibration and the TF ground truth are theirs."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbag_files import make_bags
from rosbags.highlevel import AnyReader
from scipy.spatial.transform import Rotation

from sal_adapters import Sequence, open_dataset
from sal_adapters.common.errors import DatasetWarning


def read_bag(path: Path) -> dict[str, list[tuple[int, Any]]]:
    """Topic -> [(log time ns, message)] of a bag of any of the three formats."""
    found: dict[str, list[tuple[int, Any]]] = {}
    with AnyReader([path]) as reader:
        for connection, stamp, raw in reader.messages():
            found.setdefault(connection.topic, []).append((stamp, reader.deserialize(raw, connection.msgtype)))
    return found


def ns_of(message: Any) -> int:
    """The header stamp of ``message`` in integer nanoseconds."""
    return int(message.header.stamp.sec) * 10**9 + int(message.header.stamp.nanosec)


def check_images(topic: list[tuple[int, Any]], seq: Sequence, right: bool = False) -> None:
    """One message per frame, stamped with the frame's time, holding its pixels as mono8."""
    assert len(topic) == len(seq)
    for (stamp, message), frame in zip(topic, seq):
        expected_ns = frame.record.timestamp_ns if frame.record.timestamp_ns is not None else round(frame.timestamp * 1e9)
        assert stamp == ns_of(message) == expected_ns
        assert message.encoding == "mono8"
        pixels = np.frombuffer(message.data, np.uint8).reshape(message.height, message.width)
        np.testing.assert_array_equal(pixels, (frame.right if right else frame.image)[..., 0])


def intrinsics(message: Any) -> np.ndarray:
    """K of a CameraInfo (ROS 1 spells it K, ROS 2 k)."""
    return np.asarray(message.K if hasattr(message, "K") else message.k).reshape(3, 3)


def check_groundtruth(topic: list[tuple[int, Any]], seq: Sequence) -> None:
    """/tf holds world -> cam0 at every ground-truth time, equal to the trajectory's pose."""
    truth = seq.groundtruth
    assert truth is not None and len(topic) == len(truth)
    for (stamp, message), t, pose in zip(topic, truth.timestamps, truth.matrices):
        (transform,) = message.transforms
        assert (transform.header.frame_id, transform.child_frame_id) == ("world", "cam0") and stamp == round(t * 1e9)
        q, p = transform.transform.rotation, transform.transform.translation
        np.testing.assert_allclose(Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(), pose[:3, :3], atol=1e-12)
        np.testing.assert_array_equal([p.x, p.y, p.z], pose[:3, 3])


def test_kitti07_bags_hold_its_frames_stamps_calibration_and_ground_truth(shared_data: Path, tmp_path: Path) -> None:
    folder = shared_data / "kitti"
    seq = open_dataset("kitti", folder, sequence="07", max_frames=8)
    for path in make_bags("kitti", folder, tmp_path, "sequence=07", "max_frames=8"):
        topics = read_bag(path)
        assert sorted(topics) == ["/cam0/camera_info", "/cam0/image_raw", "/tf"], path
        check_images(topics["/cam0/image_raw"], seq)
        info = topics["/cam0/camera_info"][0][1]
        assert intrinsics(info)[0, 0] == 707.0912 and (info.width, info.height) == (seq.camera.width, seq.camera.height)
        check_groundtruth(topics["/tf"], seq)


def test_euroc_bags_hold_both_cameras_and_every_imu_sample_between_the_frames(shared_data: Path, tmp_path: Path) -> None:
    folder = shared_data / "euroc" / "V1_01_easy_micro"
    with pytest.warns(DatasetWarning, match="rows skipped"):  # the excerpt lacks 4 cam1 images
        seq = open_dataset("euroc", folder, stereo=True, max_frames=30)  # ground truth from frame 20 on
    csv = folder / "mav0" / "imu0" / "data.csv"
    imu = np.loadtxt(csv, delimiter=",", comments="#", dtype=np.float64)
    stamps = np.loadtxt(csv, delimiter=",", comments="#", dtype=np.int64, usecols=0)  # ns, beyond float64
    first, last = seq.records[0].timestamp_ns, seq.records[-1].timestamp_ns
    assert first is not None and last is not None
    inside = (stamps >= first) & (stamps <= last)
    for path in make_bags("euroc", folder, tmp_path, "stereo=true", "max_frames=30"):
        topics = read_bag(path)
        check_images(topics["/cam0/image_raw"], seq)
        check_images(topics["/cam1/image_raw"], seq, right=True)
        samples = topics["/imu0"]
        assert [stamp for stamp, _ in samples] == stamps[inside].tolist()
        gyro = samples[0][1].angular_velocity
        np.testing.assert_array_equal([gyro.x, gyro.y, gyro.z], imu[inside][0, 1:4])
        check_groundtruth(topics["/tf"], seq)
