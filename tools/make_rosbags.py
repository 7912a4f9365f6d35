"""Write a dataset excerpt as ROS bags: ROS 1 ``.bag``, ROS 2 ``sqlite3`` and ROS 2 MCAP (issue 26).

Topics (the names a ROS camera driver and a motion-capture bridge would use):

* ``/cam0/image_raw`` (``sensor_msgs/Image``, ``mono8`` for grey cameras, else ``rgb8``) and
  ``/cam0/camera_info`` (``sensor_msgs/CameraInfo``: K, P, plumb_bob distortion) per frame;
  ``/cam1/...`` too for a stereo sequence (P of the right camera carries ``-fx * baseline``);
* ``/tf``: the ground truth as ``tf2_msgs/TFMessage`` from ``world`` to ``cam0`` at each
  ground-truth stamp (the camera-to-world pose of the dataset's ``Trajectory``);
* ``/imu0`` (``sensor_msgs/Imu``) from ``mav0/imu0/data.csv`` when the folder is EuRoC's.

Stamps are the dataset's own: EuRoC's integer nanoseconds exactly, KITTI's seconds rounded to
the nanosecond. Nothing else is invented (no odometry, no covariances).

    .venv/bin/python tools/make_rosbags.py kitti ../shared/data/kitti -o /tmp/bags -O sequence=07 -O max_frames=60
    .venv/bin/python tools/make_rosbags.py euroc ../shared/data/euroc/V1_01_easy_micro -o /tmp/bags -O stereo=true
"""

from __future__ import annotations

import argparse
import csv
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Ros2Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from scipy.spatial.transform import Rotation

from pytest_sal.cli.arg_types import parse_key_values
from sal_adapters import Sequence, open_dataset
from sal_adapters.camera import Camera
from sal_adapters.trajectory import seconds_to_ns

FORMATS = {"ros1": ".bag", "sqlite3": "_sqlite3", "mcap": "_mcap"}
TYPESTORES = {"ros1": Stores.ROS1_NOETIC, "sqlite3": Stores.ROS2_HUMBLE, "mcap": Stores.ROS2_HUMBLE}


def header(types: Any, ns: int, frame_id: str, ros1: bool) -> Any:
    """A ``std_msgs/Header`` at ``ns`` (ROS 1 headers carry a sequence number too)."""
    stamp = types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
    if ros1:
        return types["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame_id)
    return types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)


def image_message(types: Any, pixels: np.ndarray, grey: bool, head: Any) -> Any:
    """``sensor_msgs/Image`` of an RGB frame: ``mono8`` (its first channel) or ``rgb8``."""
    data = np.ascontiguousarray(pixels[..., 0] if grey else pixels)
    channels = 1 if grey else 3
    return types["sensor_msgs/msg/Image"](
        header=head,
        height=data.shape[0],
        width=data.shape[1],
        encoding="mono8" if grey else "rgb8",
        is_bigendian=0,
        step=data.shape[1] * channels,
        data=data.reshape(-1).view(np.uint8),
    )


def camera_info_message(types: Any, camera: Camera, head: Any, tx: float = 0.0) -> Any:
    """``sensor_msgs/CameraInfo`` of a pinhole camera (``tx = -fx * baseline`` for a right camera)."""
    K = np.array([camera.fx, 0, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1], np.float64)
    P = np.array([camera.fx, 0, camera.cx, tx, 0, camera.fy, camera.cy, 0, 0, 0, 1, 0], np.float64)
    D = np.array(list(camera.distortion) + [0.0] * (5 - len(camera.distortion)), np.float64)
    roi = types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    info = types["sensor_msgs/msg/CameraInfo"]
    upper = "K" in info.__dataclass_fields__  # ROS 1 spells the matrices D, K, R, P; ROS 2 d, k, r, p
    matrices = {"d": D, "k": K, "r": np.eye(3).reshape(-1), "p": P}
    return info(
        header=head,
        height=int(camera.height),
        width=int(camera.width),
        distortion_model="plumb_bob",
        binning_x=0,
        binning_y=0,
        roi=roi,
        **{name.upper() if upper else name: value for name, value in matrices.items()},
    )


def tf_message(types: Any, pose: np.ndarray, head: Any, child: str) -> Any:
    """``tf2_msgs/TFMessage`` holding one transform: ``pose`` (camera-to-world 4x4)."""
    x, y, z, w = Rotation.from_matrix(pose[:3, :3]).as_quat()
    transform = types["geometry_msgs/msg/Transform"](
        translation=types["geometry_msgs/msg/Vector3"](x=pose[0, 3], y=pose[1, 3], z=pose[2, 3]),
        rotation=types["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
    )
    stamped = types["geometry_msgs/msg/TransformStamped"](header=head, child_frame_id=child, transform=transform)
    return types["tf2_msgs/msg/TFMessage"](transforms=[stamped])


def imu_rows(folder: Path) -> Iterator[tuple[int, list[float]]]:
    """EuRoC's ``mav0/imu0/data.csv``: (ns, [wx, wy, wz, ax, ay, az]) per line, if present."""
    path = folder / "mav0" / "imu0" / "data.csv"
    if not path.is_file():
        return
    with path.open() as handle:
        for row in csv.reader(line for line in handle if not line.startswith("#")):
            yield int(row[0]), [float(v) for v in row[1:7]]


def imu_messages(types: Any, folder: Path, first: int, last: int, ros1: bool) -> Iterator[tuple[str, int, Any]]:
    """(``/imu0``, ns, ``sensor_msgs/Imu``) of EuRoC's IMU samples from ``first`` to ``last`` ns."""
    vector, quaternion = types["geometry_msgs/msg/Vector3"], types["geometry_msgs/msg/Quaternion"]
    unknown = np.zeros(9)
    unknown[0] = -1.0  # orientation not estimated (REP 145)
    for ns, (wx, wy, wz, ax, ay, az) in imu_rows(folder):
        if first <= ns <= last:
            yield (
                "/imu0",
                ns,
                types["sensor_msgs/msg/Imu"](
                    header=header(types, ns, "imu0", ros1),
                    orientation=quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
                    orientation_covariance=unknown,
                    angular_velocity=vector(x=wx, y=wy, z=wz),
                    angular_velocity_covariance=np.zeros(9),
                    linear_acceleration=vector(x=ax, y=ay, z=az),
                    linear_acceleration_covariance=np.zeros(9),
                ),
            )


def messages(seq: Sequence, folder: Path | None, ros1: bool, types: Any) -> Iterator[tuple[str, int, Any]]:
    """(topic, ns, message) of the whole sequence, in no particular order."""
    grey = bool(seq.grayscale)
    camera = seq.camera
    for frame in seq:
        ns = frame.record.time_ns
        yield "/cam0/image_raw", ns, image_message(types, frame.image, grey, header(types, ns, "cam0", ros1))
        yield "/cam0/camera_info", ns, camera_info_message(types, camera, header(types, ns, "cam0", ros1))
        if seq.sensor == "stereo" and frame.right is not None:
            right = camera.right or camera
            yield "/cam1/image_raw", ns, image_message(types, frame.right, grey, header(types, ns, "cam1", ros1))
            tx = -right.fx * (camera.baseline_m or 0.0) if camera.right is None else 0.0
            yield "/cam1/camera_info", ns, camera_info_message(types, right, header(types, ns, "cam1", ros1), tx)
    truth = seq.groundtruth
    if truth is not None:
        for t, pose in zip(truth.timestamps, truth.matrices):
            ns = seconds_to_ns(t)
            yield "/tf", ns, tf_message(types, pose, header(types, ns, "world", ros1), "cam0")
    if folder is not None:
        yield from imu_messages(types, folder, seq.records[0].time_ns, seq.records[-1].time_ns, ros1)


MSGTYPES = {
    "/cam0/image_raw": "sensor_msgs/msg/Image",
    "/cam1/image_raw": "sensor_msgs/msg/Image",
    "/cam0/camera_info": "sensor_msgs/msg/CameraInfo",
    "/cam1/camera_info": "sensor_msgs/msg/CameraInfo",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/imu0": "sensor_msgs/msg/Imu",
}


#: ROS 1 Noetic's store in rosbags lacks tf2_msgs; its definition is one line.
TF_MESSAGE_ROS1 = "geometry_msgs/TransformStamped[] transforms\n"


def typestore(fmt: str) -> Any:
    """The rosbags type store of ``fmt``, with ``tf2_msgs/msg/TFMessage`` registered."""
    store = get_typestore(TYPESTORES[fmt])
    if "tf2_msgs/msg/TFMessage" not in store.types:
        store.register(get_types_from_msg(TF_MESSAGE_ROS1, "tf2_msgs/msg/TFMessage"))
    return store


def write_bag(seq: Sequence, folder: Path | None, out: Path, fmt: str) -> Path:
    """Write ``seq`` as a bag of format ``fmt`` (``ros1``, ``sqlite3``, ``mcap``) at ``out``."""
    store = typestore(fmt)
    types = store.types
    ros1 = fmt == "ros1"
    items = sorted(messages(seq, folder, ros1, types), key=lambda item: item[1])
    writer: Any = (
        Ros1Writer(out)
        if ros1
        else Ros2Writer(out, version=9, storage_plugin=StoragePlugin.MCAP if fmt == "mcap" else StoragePlugin.SQLITE3)
    )
    with writer:
        connections = {topic: writer.add_connection(topic, MSGTYPES[topic], typestore=store) for topic in sorted({i[0] for i in items})}
        for topic, ns, message in items:
            msgtype = MSGTYPES[topic]
            data = store.serialize_ros1(message, msgtype) if ros1 else store.serialize_cdr(message, msgtype)
            writer.write(connections[topic], ns, data)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("kind", help="dataset kind: kitti, euroc, tum, folder, synthetic")
    parser.add_argument("path", type=Path, help="the dataset folder")
    parser.add_argument("-o", "--out", type=Path, required=True, help="folder to write the bags into")
    parser.add_argument("-O", "--option", action="append", default=[], help="dataset option KEY=VALUE, JSON values (repeatable)")
    parser.add_argument("--formats", default="ros1,sqlite3,mcap", help="comma-separated: ros1, sqlite3, mcap")
    args = parser.parse_args()
    seq = open_dataset(args.kind, args.path, **parse_key_values(args.option, "--option"))
    args.out.mkdir(parents=True, exist_ok=True)
    for fmt in args.formats.split(","):
        target = args.out / f"{args.path.name}{FORMATS[fmt]}"
        print(write_bag(seq, args.path if args.kind == "euroc" else None, target, fmt))


if __name__ == "__main__":
    main()
