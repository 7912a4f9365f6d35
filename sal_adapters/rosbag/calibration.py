"""A camera from a bag: intrinsics and distortion from ``CameraInfo`` (or given), and a stereo
pair's right camera placed by its ``P`` (``Tx = -fx * baseline``), ``/tf_static`` or a given
baseline."""

from __future__ import annotations

from typing import Any

import numpy as np

from sal_adapters.camera import Camera
from sal_adapters.common.errors import DatasetError
from sal_adapters.rosbag.bag import Bag
from sal_adapters.rosbag.pixels import check_encoding, decode_image
from sal_adapters.rosbag.transforms import TransformTree

__all__ = ["CAMERA_INFO", "camera_from", "first_info", "sibling_info", "stereo_camera"]

CAMERA_INFO = ("sensor_msgs/msg/CameraInfo",)


def sibling_info(bag: Bag, image_topic: str, intrinsics: list[float] | None) -> str | None:
    """``<namespace>/camera_info`` of an image topic when the bag has it (``None`` with ``intrinsics``)."""
    if intrinsics is not None:
        return None
    parts = image_topic.rstrip("/").split("/")
    for cut in range(len(parts) - 1, 0, -1):  # /cam0/image_raw/compressed -> /cam0/camera_info
        candidate = "/".join(parts[:cut] + ["camera_info"])
        if candidate in bag.topics():
            return candidate
    infos = list(bag.topics(CAMERA_INFO))
    raise DatasetError(
        f"image_topic={image_topic!r} has no camera_info topic beside it; pass camera_info_topic= (the bag's: "
        f"{', '.join(infos) or 'none'}) or intrinsics=[fx, fy, cx, cy]",
        bag.path,
    )


def first_info(bag: Bag, info_topic: str | None) -> Any:
    """The first ``CameraInfo`` of ``info_topic`` (``None`` without a topic); ``DatasetError``
    naming it when it is not a CameraInfo topic or holds no message."""
    if info_topic is None:
        return None
    bag.require(info_topic, "camera_info_topic", CAMERA_INFO)
    info = next((bag.deserialize(raw, info_topic) for _, raw in bag.raw_messages(info_topic)), None)
    if info is None:
        raise DatasetError(f"camera_info_topic={info_topic!r} holds no messages", bag.path)
    return info


def camera_from(
    bag: Bag,
    info_topic: str | None,
    info: Any,
    intrinsics: list[float] | None,
    distortion: list[float] | None,
    image: Any,
    image_topic: str,
) -> Camera:
    """The camera from ``intrinsics`` or ``info`` (the first ``CameraInfo`` of ``info_topic``);
    its size is the images' (``image``: the first of ``image_topic``)."""
    height, width = (image.height, image.width) if hasattr(image, "height") else decode_image(image, image_topic, bag.path).shape[:2]
    try:
        if intrinsics is not None:
            fx, fy, cx, cy = (float(v) for v in intrinsics)
            return Camera(fx, fy, cx, cy, int(width), int(height), tuple(float(v) for v in distortion or ()))
        assert info is not None
        K = np.asarray(info.K if hasattr(info, "K") else info.k, np.float64).reshape(3, 3)
        D = tuple(float(v) for v in (info.D if hasattr(info, "D") else info.d))
        if info.distortion_model not in ("plumb_bob", "rational_polynomial", "") and any(D):
            raise DatasetError(
                f"topic {info_topic}: distortion model {info.distortion_model!r} is not supported (plumb_bob, rational_polynomial)",
                bag.path,
            )
        if (info.width, info.height) not in ((0, 0), (width, height)):
            raise DatasetError(
                f"topic {info_topic}: CameraInfo is {info.width}x{info.height} px but {image_topic}'s images are {width}x{height} px",
                bag.path,
            )
        D = D[: max((i + 1 for i, v in enumerate(D) if v), default=0)]  # plumb_bob's 5 with k3 = 0 is OpenCV's 4
        return Camera(float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), int(width), int(height), tuple(distortion or D))
    except (ValueError, TypeError) as exc:
        raise DatasetError(f"camera of {image_topic}: {exc}", bag.path) from None


def stereo_camera(
    bag: Bag,
    camera: Camera,
    first: Any,
    topic: str,
    info_topic: str | None,
    intrinsics: list[float] | None,
    distortion: list[float] | None,
    left_frame: str,
    baseline_m: float | None,
) -> Camera:
    """``camera`` with the right camera of ``topic`` (``first``: its first image; its own
    intrinsics when they differ)."""
    check_encoding(first, topic, bag.path)
    info_topic = info_topic or sibling_info(bag, topic, intrinsics)
    info = first_info(bag, info_topic)
    right_camera = camera_from(bag, info_topic, info, intrinsics, distortion, first, topic)
    T_lr = _right_pose(bag, info, left_frame, first.header.frame_id.lstrip("/"), baseline_m)
    same = right_camera.summary() == camera.summary() and right_camera.distortion == camera.distortion
    return camera.with_stereo(T_lr, right=None if same else right_camera)


def _right_pose(bag: Bag, info: Any, left_frame: str, right_frame: str, baseline_m: float | None) -> np.ndarray:
    """``T_left_right`` (4x4) from ``baseline_m``, else the right CameraInfo's ``P``
    (Tx = -fx * baseline), else ``/tf_static``."""
    T = np.eye(4)
    if baseline_m is not None:
        T[0, 3] = float(baseline_m)
        return T
    if info is not None:
        P = np.asarray(info.P if hasattr(info, "P") else info.p, np.float64).reshape(3, 4)
        if P[0, 3] != 0:
            T[0, 3] = -P[0, 3] / P[0, 0]
            return T
    tree = TransformTree(bag, ("/tf_static",))
    if left_frame in tree.frames and right_frame in tree.frames and left_frame != right_frame:
        return tree.static_pose(left_frame, right_frame)
    raise DatasetError(
        f"the right camera's pose is unknown: its CameraInfo P has no Tx and /tf_static has no {left_frame!r} -> {right_frame!r}; pass baseline_m=",
        bag.path,
    )
