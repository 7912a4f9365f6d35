"""Bags for the rosbag tests: the real excerpts written by tools/make_rosbags.py, and small
hand-made ROS 2 bags whose topics a test chooses (compressed images, depth, a TF chain,
Odometry, broken stamps) built with rosbags' own writer."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from scipy.spatial.transform import Rotation

from sal_adapters.camera import Camera
from sal_adapters.rosbag.messages import camera_info_message, header, tf_message, typestore

TOOL = Path(__file__).resolve().parents[1] / "tools" / "make_rosbags.py"
#: the four bags the tool writes for a folder NAME
BAGS = ("{}.bag", "{}_sqlite3", "{}_mcap", "{}.mcap")
STORE = typestore(ros1=False)
TYPES = STORE.types
CAMERA = Camera(100.0, 100.0, 32.0, 24.0, 64, 48)


def make_bags(kind: str, folder: Path, out: Path, *options: str) -> list[Path]:
    """Run the tool as a user would; the paths of the four bags."""
    arguments = [arg for option in options for arg in ("-O", option)]
    subprocess.run([sys.executable, str(TOOL), kind, str(folder), "-o", str(out), *arguments], check=True, capture_output=True)
    return [out / pattern.format(folder.name) for pattern in BAGS]


def write_ros2_bag(path: Path, messages: Iterable[tuple[str, str, int, Any]]) -> Path:
    """A ROS 2 MCAP bag folder of ``(topic, msgtype, log ns, message)`` (in log order)."""
    connections: dict[str, Any] = {}
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        for topic, msgtype, ns, message in messages:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=STORE)
            writer.write(connections[topic], ns, STORE.serialize_cdr(message, msgtype))
    return path


def frame_pixels(number: int) -> np.ndarray:
    """A 48x64 RGB test frame that differs per ``number`` (smooth, so JPEG keeps it close)."""
    y, x = np.mgrid[0:48, 0:64]
    return np.stack([(x * 4 + number) % 256, (y * 5) % 256, (x + y + 10 * number) % 256], axis=2).astype(np.uint8)


def image(ns: int, pixels: np.ndarray, encoding: str = "rgb8", frame: str = "cam") -> Any:
    """A raw ``sensor_msgs/Image`` of ``pixels`` (HxW or HxWxC) stamped ``ns``."""
    data = np.ascontiguousarray(pixels)
    return TYPES["sensor_msgs/msg/Image"](
        header=header(TYPES, ns, frame, False),
        height=data.shape[0],
        width=data.shape[1],
        encoding=encoding,
        is_bigendian=0,
        step=data.shape[1] * data.itemsize * (data.shape[2] if data.ndim == 3 else 1),
        data=data.reshape(-1).view(np.uint8),
    )


def jpeg(ns: int, pixels: np.ndarray, frame: str = "cam") -> Any:
    """A ``sensor_msgs/CompressedImage`` holding ``pixels`` (RGB) as JPEG, quality 98."""
    ok, data = cv2.imencode(".jpg", pixels[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 98])
    assert ok
    return TYPES["sensor_msgs/msg/CompressedImage"](header=header(TYPES, ns, frame, False), format="jpeg", data=data.reshape(-1))


def info(ns: int, frame: str = "cam", camera: Camera = CAMERA) -> Any:
    return camera_info_message(TYPES, camera, header(TYPES, ns, frame, False))


def tf(ns: int, pose: np.ndarray, parent: str, child: str) -> Any:
    return tf_message(TYPES, pose, header(TYPES, ns, parent, False), child)


def pose_at(seconds: float) -> np.ndarray:
    """A moving pose: 1 m/s along x, turning 0.2 rad/s about z."""
    c, s = np.cos(0.2 * seconds), np.sin(0.2 * seconds)
    pose = np.eye(4)
    pose[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    pose[:3, 3] = [seconds, 0.5 * seconds, 0.0]
    return pose


def pose_message(pose: np.ndarray) -> Any:
    """A ``geometry_msgs/Pose`` of a 4x4 pose."""
    x, y, z, w = Rotation.from_matrix(pose[:3, :3]).as_quat()
    return TYPES["geometry_msgs/msg/Pose"](
        position=TYPES["geometry_msgs/msg/Point"](x=pose[0, 3], y=pose[1, 3], z=pose[2, 3]),
        orientation=TYPES["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
    )


def camera_bag(
    path: Path, frames: int = 10, make: Callable[[int, int], Any] | None = None, extra: Iterable[tuple[str, str, int, Any]] = ()
) -> Path:
    """A bag with ``/cam/image_raw`` (``make(number, ns)``, default raw rgb8) and
    ``/cam/camera_info`` at 10 Hz from t = 1 s, plus the ``extra`` messages, in log order."""
    build = make or (lambda number, ns: image(ns, frame_pixels(number)))
    items = list(extra)
    for number in range(frames):
        ns = 1_000_000_000 + number * 100_000_000
        message = build(number, ns)
        kind = "sensor_msgs/msg/CompressedImage" if hasattr(message, "format") else "sensor_msgs/msg/Image"
        items += [("/cam/image_raw", kind, ns, message), ("/cam/camera_info", "sensor_msgs/msg/CameraInfo", ns, info(ns))]
    return write_ros2_bag(path, sorted(items, key=lambda item: item[2]))
