"""ROS messages of a sequence that did not come from a bag, and the type stores to serialise them.

A sequence from a folder (KITTI, EuRoC, TUM, the synthetic world) is written as a bag with the
topics a ROS camera driver and a motion-capture bridge would use:

* ``/cam0/image_raw`` (``sensor_msgs/Image``: ``mono8`` for grey cameras, else ``rgb8``) and
  ``/cam0/camera_info`` (``sensor_msgs/CameraInfo``: K, P, plumb_bob distortion) per frame;
  ``/cam1/...`` too for a stereo sequence (P of the right camera carries ``-fx * baseline``),
  and ``/tf_static`` with ``cam0 -> cam1`` (the right camera's pose in the left one);
* ``/tf``: the ground truth as ``tf2_msgs/TFMessage`` from ``world`` to ``cam0`` at each
  ground-truth stamp (the camera-to-world pose of the sequence's ``Trajectory``).

ROS 1 spells CameraInfo's matrices ``D K R P`` and gives headers a ``seq``; ROS 2 spells them
``d k r p``. Stamps are the frames' integer nanoseconds (``FrameRecord.time_ns``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from sal_adapters.camera import Camera

__all__ = ["FRESH_TOPICS", "camera_info_message", "header", "image_message", "tf_message", "typestore"]

#: Topic -> message type of a bag written from a sequence that did not come from one.
FRESH_TOPICS = {
    "/cam0/image_raw": "sensor_msgs/msg/Image",
    "/cam1/image_raw": "sensor_msgs/msg/Image",
    "/cam0/camera_info": "sensor_msgs/msg/CameraInfo",
    "/cam1/camera_info": "sensor_msgs/msg/CameraInfo",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/tf_static": "tf2_msgs/msg/TFMessage",
    "/imu0": "sensor_msgs/msg/Imu",
}

#: ROS 1 Noetic's store in rosbags lacks tf2_msgs; its definition is one line.
_TF_MESSAGE_ROS1 = "geometry_msgs/TransformStamped[] transforms\n"


def typestore(ros1: bool) -> Any:
    """The rosbags type store of ROS 1 Noetic or ROS 2 Humble, with ``tf2_msgs/msg/TFMessage``."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if "tf2_msgs/msg/TFMessage" not in store.types:
        store.register(get_types_from_msg(_TF_MESSAGE_ROS1, "tf2_msgs/msg/TFMessage"))
    return store


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
    upper = "K" in info.__dataclass_fields__
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
    """``tf2_msgs/TFMessage`` holding one transform: ``pose`` (4x4, the child in ``head.frame_id``)."""
    x, y, z, w = Rotation.from_matrix(pose[:3, :3]).as_quat()
    transform = types["geometry_msgs/msg/Transform"](
        translation=types["geometry_msgs/msg/Vector3"](x=pose[0, 3], y=pose[1, 3], z=pose[2, 3]),
        rotation=types["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
    )
    stamped = types["geometry_msgs/msg/TransformStamped"](header=head, child_frame_id=child, transform=transform)
    return types["tf2_msgs/msg/TFMessage"](transforms=[stamped])
