"""Ground truth from a bag: a chain of TF transforms, ``nav_msgs/Odometry`` or
``geometry_msgs/PoseStamped``, as the camera-to-world ``Trajectory`` of the camera.

TF: each ``TransformStamped`` (``header.frame_id`` = parent, ``child_frame_id`` = child) is the
pose of the child in the parent, ``T_parent_child``; ``/tf_static`` holds the constant ones. The
pose of frame ``c`` in frame ``w`` is the product of the edges from ``w`` down to ``c``,
``T_w_c = T_w_a @ T_a_b @ ... @ T_x_c``. Moving edges are sampled at the stamps of the densest
one inside the span they all cover; the others are interpolated there (positions linearly,
rotations by slerp). Odometry and PoseStamped give the pose of their child frame (Odometry's
``child_frame_id``) in ``header.frame_id`` at ``header.stamp``; a static TF chain from that frame
to the camera's is applied when ``groundtruth_frames`` names another camera frame.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from sal_adapters.common.errors import DatasetError, DatasetWarning
from sal_adapters.common.suggest import suggestion
from sal_adapters.rosbag.bag import Bag
from sal_adapters.trajectory import Trajectory

__all__ = ["POSE_TYPES", "TF_TYPE", "TransformTree", "read_groundtruth"]

TF_TYPE = "tf2_msgs/msg/TFMessage"
POSE_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped")
_TF_TOPICS = ("/tf", "/tf_static")


@dataclass
class _Edge:
    """The pose of a child frame in its parent: one (static) or many stamped 4x4 matrices."""

    parent: str
    times: list[float]
    poses: list[np.ndarray]
    static: bool

    def sampled(self) -> tuple[np.ndarray, np.ndarray]:
        """Times (s, increasing, unique) and their Nx4x4 poses."""
        times = np.asarray(self.times)
        order = np.argsort(times, kind="stable")
        times, keep = np.unique(times[order], return_index=True)
        return times, np.asarray(self.poses)[order][keep]


class TransformTree:
    """The TF tree of a bag: child frame -> its edge from the parent."""

    def __init__(self, bag: Bag, topics: tuple[str, ...] = _TF_TOPICS):
        self.bag = bag
        self.edges: dict[str, _Edge] = {}
        for topic in topics:
            if topic not in bag.topics():
                continue
            bag.require(topic, "groundtruth_topic", (TF_TYPE,))
            for number, (_, raw) in enumerate(bag.raw_messages(topic)):
                for stamped in bag.deserialize(raw, topic).transforms:
                    try:
                        self._add(stamped, static=topic == "/tf_static")
                    except ValueError as exc:
                        raise DatasetError(f"topic {topic}: message {number}: {exc}", bag.path) from None

    def _add(self, stamped: Any, static: bool) -> None:
        parent, child = stamped.header.frame_id.lstrip("/"), stamped.child_frame_id.lstrip("/")
        edge = self.edges.setdefault(child, _Edge(parent, [], [], static))
        if edge.parent != parent:
            raise DatasetError(
                f"TF frame {child!r} has two parents, {edge.parent!r} and {parent!r}; a TF tree gives each frame one", self.bag.path
            )
        t = stamped.transform
        edge.times.append(_seconds(stamped.header.stamp))
        edge.poses.append(_matrix(t.translation, t.rotation))

    @property
    def frames(self) -> list[str]:
        """Every frame the tree names."""
        return sorted(set(self.edges) | {e.parent for e in self.edges.values()})

    def root(self, frame: str) -> str:
        """The top of the chain above ``frame``."""
        seen = {frame}
        while frame in self.edges:
            frame = self.edges[frame].parent
            if frame in seen:
                raise DatasetError(f"TF frames form a loop at {frame!r}", self.bag.path)
            seen.add(frame)
        return frame

    def chain(self, parent: str, child: str) -> list[_Edge]:
        """The edges from ``parent`` down to ``child``; ``DatasetError`` naming the frame not found."""
        for frame in (parent, child):
            if frame not in self.frames:
                raise DatasetError(
                    f"groundtruth_frames: TF has no frame {frame!r}" + suggestion(frame, self.frames, "its frames"), self.bag.path
                )
        edges, frame = [], child
        while frame != parent:
            if frame not in self.edges:
                raise DatasetError(
                    f"groundtruth_frames: {child!r} is not below {parent!r} in the TF tree (its root is {self.root(child)!r})",
                    self.bag.path,
                )
            edges.append(self.edges[frame])
            frame = edges[-1].parent
        return edges[::-1]

    def static_pose(self, parent: str, child: str) -> np.ndarray:
        """``T_parent_child`` of a chain of static transforms."""
        pose = np.eye(4)
        for edge in self.chain(parent, child):
            if not edge.static:
                raise DatasetError(
                    f"TF transform {edge.parent!r} -> a child of it moves; the frames {parent!r} -> {child!r} must be fixed", self.bag.path
                )
            pose = pose @ edge.poses[-1]
        return pose

    def trajectory(self, parent: str, child: str) -> Trajectory:
        """Poses of ``child`` in ``parent`` along the chain (see the module text)."""
        edges = self.chain(parent, child)
        samples = [None if edge.static else edge.sampled() for edge in edges]
        moving = [sample for sample in samples if sample is not None]
        if not moving:
            raise DatasetError(
                f"groundtruth_frames {parent!r} -> {child!r}: every transform on the chain is static; no motion to take as ground truth",
                self.bag.path,
            )
        start = max(times[0] for times, _ in moving)
        stop = min(times[-1] for times, _ in moving)
        dense = max(moving, key=lambda item: len(item[0]))[0]
        times = dense[(dense >= start) & (dense <= stop)]
        poses = np.tile(np.eye(4), (len(times), 1, 1))
        for edge, sample in zip(edges, samples):
            poses = poses @ (edge.poses[-1] if sample is None else _interpolated(*sample, times))
        return Trajectory.from_matrices(times, poses)


def read_groundtruth(bag: Bag, topic: str | None, frames: tuple[str, str] | None, camera_frame: str) -> Trajectory | None:
    """The camera's ground truth from ``topic`` (TF, Odometry or PoseStamped) between
    ``frames`` (world, camera); with neither given: the one Odometry/PoseStamped topic of the
    bag, else TF from the root above ``camera_frame`` (the images' ``header.frame_id``), else none."""
    if frames is not None and (len(frames) != 2 or not all(isinstance(f, str) and f for f in frames)):
        raise DatasetError(f"groundtruth_frames must be two frame names (world, camera), got {frames!r}", bag.path)
    if topic is None:
        candidates = list(bag.topics(POSE_TYPES))
        if frames is None and len(candidates) == 1:
            topic = candidates[0]
        elif frames is None and len(candidates) > 1:
            warnings.warn(
                f"{bag.path}: several ground-truth topics ({', '.join(candidates)}); opening without ground truth (pass groundtruth_topic=)",
                DatasetWarning,
                stacklevel=4,
            )
            return None
        else:
            tree = TransformTree(bag)
            if frames is None:
                return tree.trajectory(tree.root(camera_frame), camera_frame) if camera_frame in tree.edges else None
            return tree.trajectory(*frames)
    msgtype = bag.require(topic, "groundtruth_topic", (TF_TYPE, *POSE_TYPES))
    if msgtype == TF_TYPE:
        tree = TransformTree(bag, tuple(dict.fromkeys((topic, "/tf_static"))))
        world, camera = frames or (tree.root(camera_frame), camera_frame)
        return tree.trajectory(world, camera)
    return _pose_topic(bag, topic, frames)


def _pose_topic(bag: Bag, topic: str, frames: tuple[str, str] | None) -> Trajectory:
    """Odometry or PoseStamped poses, moved to ``frames[1]`` by a static TF chain when it is
    not the messages' own child frame."""
    times, poses, child = [], [], ""
    for number, (_, raw) in enumerate(bag.raw_messages(topic)):
        message = bag.deserialize(raw, topic)
        pose = message.pose.pose if hasattr(message, "child_frame_id") else message.pose
        child = getattr(message, "child_frame_id", "").lstrip("/")
        times.append(_seconds(message.header.stamp))
        try:
            poses.append(_matrix(pose.position, pose.orientation))
        except ValueError as exc:
            raise DatasetError(f"topic {topic}: message {number}: {exc}", bag.path) from None
    if not times:
        raise DatasetError(f"groundtruth_topic={topic!r} holds no messages", bag.path)
    order = np.argsort(times, kind="stable")
    trajectory = Trajectory.from_matrices(np.asarray(times)[order], np.asarray(poses)[order])
    camera = None if frames is None else frames[1].lstrip("/")
    if camera is None or camera == child or not child:
        return trajectory
    return trajectory.transformed(right=TransformTree(bag, ("/tf_static",)).static_pose(child, camera))


def _seconds(stamp: Any) -> float:
    return int(stamp.sec) + int(stamp.nanosec) * 1e-9


def _matrix(translation: Any, rotation: Any) -> np.ndarray:
    """4x4 of a ROS translation (Vector3 or Point) and quaternion (x, y, z, w)."""
    quaternion = np.array([rotation.x, rotation.y, rotation.z, rotation.w], np.float64)
    position = np.array([translation.x, translation.y, translation.z], np.float64)
    if not np.all(np.isfinite(quaternion)) or np.linalg.norm(quaternion) < 1e-9 or not np.all(np.isfinite(position)):
        raise ValueError(f"a pose with a non-finite position or an invalid quaternion: {position.tolist()}, {quaternion.tolist()}")
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_quat(quaternion).as_matrix()
    pose[:3, 3] = position
    return pose


def _interpolated(times: np.ndarray, poses: np.ndarray, at: np.ndarray) -> np.ndarray:
    """``poses`` at ``times`` interpolated at ``at`` (inside their span)."""
    if len(times) == 1:
        return np.repeat(poses[:1], len(at), axis=0)
    out = np.tile(np.eye(4), (len(at), 1, 1))
    out[:, :3, :3] = Slerp(times, Rotation.from_matrix(poses[:, :3, :3]))(at).as_matrix()
    for axis in range(3):
        out[:, axis, 3] = np.interp(at, times, poses[:, axis, 3])
    return out
