"""The ``rosbag`` dataset kind: camera images, calibration and ground truth from a ROS bag.

``open_dataset("rosbag", "run_0412.mcap", image_topic="/cam0/image_raw")`` reads a ROS 1
``.bag``, a ROS 2 bag folder (sqlite3 or MCAP) or a bare ``.mcap`` file with ``rosbags``; no ROS
installation is needed. Opening reads the image topics once for their stamps (the first bytes
of each message, never the pixels); frames are decoded when used, so a bag of any size opens in
constant memory. Frame times are the images' ``header.stamp`` (``stamps="log"``: the time the
recorder logged them). A right image or a depth map belongs to the left image of the nearest
stamp within ``pair_tolerance_s``; left images without one are left out with a warning.
"""

from __future__ import annotations

import functools
import re
import warnings
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from sal_adapters.common.errors import DatasetError, DatasetWarning
from sal_adapters.datasets import DatasetKind
from sal_adapters.rosbag.bag import IMAGE_TYPES, Bag, MessageRef, bag_files, bag_version, header_stamp_ns, open_bag
from sal_adapters.rosbag.calibration import camera_from, first_info, sibling_info, stereo_camera
from sal_adapters.rosbag.pixels import BagImage, check_encoding
from sal_adapters.rosbag.transforms import read_groundtruth
from sal_adapters.sequence import Frame, FrameRecord, Sequence

__all__ = ["ROSBAG", "RosbagDataset"]

STAMPS = ("header", "log")
FORMAT_NAMES = {"ros1": "ROS 1 bag", "sqlite3": "ROS 2 bag (sqlite3)", "mcap": "ROS 2 bag (MCAP)", "mcap_file": "MCAP file"}


class RosbagDataset(DatasetKind):
    """ROS 1 bags, ROS 2 sqlite3 and MCAP bags: raw or compressed images, CameraInfo, TF,
    Odometry or PoseStamped ground truth.

    Options of ``open``:
        path: a ``.bag`` file, a ``.mcap`` file or a ROS 2 bag folder.
        image_topic: the (left) camera's ``Image`` or ``CompressedImage`` topic; default:
            the bag's only image topic.
        camera_info_topic: its ``CameraInfo``; default ``camera_info`` beside the image
            topic (``/cam0/image_raw`` -> ``/cam0/camera_info``).
        right_image_topic, right_camera_info_topic: a stereo pair's right camera. Its pose
            comes from the right CameraInfo's ``P`` (``Tx = -fx * baseline``), else from
            ``/tf_static`` between the two images' frames, else ``baseline_m``.
        depth_topic: an RGB-D camera's depth (``16UC1`` mm or ``32FC1`` m).
        groundtruth_topic: ``/tf`` (a ``TFMessage`` topic), an Odometry or a PoseStamped
            topic; default: the bag's only Odometry/PoseStamped topic, else TF when it
            holds the images' frame.
        groundtruth_frames: ``(world, camera)`` TF frames; default: the root of the TF tree
            above the images' ``frame_id``, and that frame.
        intrinsics: ``[fx, fy, cx, cy]`` (px) instead of a CameraInfo; ``distortion``:
            OpenCV ``k1 k2 p1 p2 [k3]`` with it.
        pair_tolerance_s: largest stamp difference (s) of a stereo or RGB-D pair.
        stamps: ``header`` (capture time) or ``log`` (recording time).
    """

    name = "rosbag"
    description = (
        "ROS bag (.bag, ROS 2 sqlite3/MCAP folder, .mcap): Image/CompressedImage, CameraInfo, ground truth on TF/Odometry/PoseStamped"
    )
    opens_files = True
    file_suffixes = (".bag", ".mcap")

    def open(
        self,
        path: Path | None,
        *,
        image_topic: str | None = None,
        camera_info_topic: str | None = None,
        right_image_topic: str | None = None,
        right_camera_info_topic: str | None = None,
        depth_topic: str | None = None,
        groundtruth_topic: str | None = None,
        groundtruth_frames: list[str] | tuple[str, str] | None = None,
        intrinsics: list[float] | None = None,
        distortion: list[float] | None = None,
        baseline_m: float | None = None,
        pair_tolerance_s: float = 0.02,
        stamps: str = "header",
    ) -> Sequence:
        """Open a bag (the options are the class's).

        Raises:
            DatasetError: the bag, a topic, a frame, an encoding or an option is wrong (named).
        """
        # the options as given, which the writer reopens the source bag with
        options = {name: value for name, value in locals().items() if name not in ("self", "path") and value is not None}
        if groundtruth_frames is not None:
            options["groundtruth_frames"] = list(groundtruth_frames)
        if path is None:
            raise DatasetError("the rosbag dataset needs a path (a .bag file, a .mcap file or a ROS 2 bag folder)")
        if stamps not in STAMPS:
            raise DatasetError(f"stamps must be 'header' or 'log', got {stamps!r}")
        if not (isinstance(pair_tolerance_s, int | float) and 0 <= pair_tolerance_s <= 10):
            raise DatasetError(f"pair_tolerance_s must be from 0 to 10 s, got {pair_tolerance_s!r}")
        if right_image_topic is not None and depth_topic is not None:
            raise DatasetError("give right_image_topic (stereo) or depth_topic (RGB-D), not both")
        path = Path(path).resolve()
        bag = open_bag(path)
        image_topic = image_topic or _only_image_topic(bag, {right_image_topic, depth_topic})
        left = _indexed(bag, image_topic, "image_topic", stamps)
        first = bag.read(left.refs[0])
        grey = check_encoding(first, image_topic, path)
        camera_frame = first.header.frame_id.lstrip("/")
        camera_info_topic = camera_info_topic or sibling_info(bag, image_topic, intrinsics)
        camera = camera_from(bag, camera_info_topic, first_info(bag, camera_info_topic), intrinsics, distortion, first, image_topic)

        partner, sensor = None, "mono"
        if right_image_topic is not None:
            partner, sensor = _indexed(bag, right_image_topic, "right_image_topic", stamps), "stereo"
            right_first = bag.read(partner.refs[0])
            camera = stereo_camera(
                bag, camera, right_first, right_image_topic, right_camera_info_topic, intrinsics, distortion, camera_frame, baseline_m
            )
        elif depth_topic is not None:
            partner, sensor = _indexed(bag, depth_topic, "depth_topic", stamps), "rgbd"
            check_encoding(bag.read(partner.refs[0]), depth_topic, path, depth=True)

        pairs = _paired(left, partner, pair_tolerance_s, path, image_topic)
        records = _records(path, left, partner, sensor, pairs)
        frames = None if groundtruth_frames is None else tuple(groundtruth_frames)
        return Sequence(
            kind=self.name,
            name=f"rosbag/{path.stem}",
            camera=camera,
            sensor=sensor,  # type: ignore[arg-type]
            fps=_rate(left.stamps),
            records=records,
            groundtruth=read_groundtruth(bag, groundtruth_topic, frames, camera_frame),  # type: ignore[arg-type]
            grayscale=grey,
            source=path,
            meta={
                "format": bag.format,
                "options": {
                    **options,
                    "image_topic": image_topic,
                    **({"camera_info_topic": camera_info_topic} if camera_info_topic else {}),
                },
                "excerpt": None,
            },
            content_key=_content_key(path),
        )

    def details(self, sequence: Sequence) -> list[tuple[str, str]]:
        """The bag's format and every topic: type, message count, and what the sequence reads
        from it."""
        assert sequence.source is not None
        bag = open_bag(sequence.source)
        options = sequence.meta.get("options", {})
        roles = {options.get(k): k.removesuffix("_topic") for k in ("image_topic", "right_image_topic", "depth_topic", "camera_info_topic")}
        lines = [("format", FORMAT_NAMES[bag.format])]
        for topic, msgtype in bag.topics().items():
            role = f"  <- {roles[topic]}" if topic in roles else ""
            lines.append(("topic", f"{topic}  {msgtype}  {bag.message_count(topic)} messages{role}"))
        return lines

    def write(self, sequence: Sequence, out_dir: Path, frames: Iterable[Frame]) -> Path:
        """Write the bag under ``out_dir`` in the source bag's format (a sequence from another
        kind: a ROS 2 MCAP bag folder) and return its path."""
        fmt = str(sequence.meta.get("format", "mcap")) if sequence.kind == self.name else "mcap"
        stem = re.sub(r"[^A-Za-z0-9._-]+", "_", sequence.name.rsplit("/", 1)[-1]).strip("._") or "sequence"
        target = out_dir / (stem + {"ros1": ".bag", "mcap_file": ".mcap"}.get(fmt, ""))
        self._write(sequence, target, fmt, frames)
        return target

    def write_file(self, sequence: Sequence, path: Path, frames: Iterable[Frame]) -> None:
        """Write ``path``: a ROS 1 bag (``.bag``) or a bare MCAP file (``.mcap``)."""
        self._write(sequence, path, "ros1" if path.suffix.lower() == ".bag" else "mcap_file", frames)

    def _write(self, sequence: Sequence, target: Path, fmt: str, frames: Iterable[Frame]) -> None:
        """A copy of the source bag when ``sequence`` came from one of the same family (ROS 1
        or ROS 2), else a new bag (``sal_adapters.rosbag.writer``)."""
        from sal_adapters.rosbag.writer import write_bag

        clean = None
        if sequence.kind == self.name and sequence.source is not None:
            if (sequence.meta.get("format") == "ros1") != (fmt == "ros1"):
                source, wanted = ("a ROS 1 bag", ".bag") if sequence.meta.get("format") == "ros1" else ("a ROS 2 bag", ".mcap or a folder")
                raise DatasetError(
                    f"{sequence.name} comes from {source} and is written back as one (its other topics keep their "
                    f"serialisation): name the output {wanted}, or convert the bag first (rosbags-convert)",
                    target.name,
                )
            clean = self.open(sequence.source, **sequence.meta.get("options", {}))
        write_bag(sequence, target, fmt, frames, clean=clean)


class _Topic:
    """An image topic's messages in log order: where each is (``refs``) and its stamp (ns)."""

    def __init__(self, topic: str, refs: list[MessageRef], stamps: np.ndarray):
        self.topic, self.refs, self.stamps = topic, refs, stamps


def _indexed(bag: Bag, topic: str, option: str, stamps: str) -> _Topic:
    """The messages of the image topic ``topic``; ``DatasetError`` naming it when it is empty or
    its stamps do not increase."""
    bag.require(topic, option, IMAGE_TYPES)
    log, stamp = _stamps(bag.path, bag_version(bag.path), topic, stamps, bag.ros1)
    if not len(log):
        raise DatasetError(f"{option}={topic!r} holds no messages", bag.path)
    back = np.flatnonzero(np.diff(stamp) <= 0)
    if len(back):
        k = int(back[0]) + 1
        raise DatasetError(
            f"topic {topic}: message {k} has {stamps} stamp {stamp[k] * 1e-9:.9f} s, not after message {k - 1}'s "
            f"{stamp[k - 1] * 1e-9:.9f} s; frame stamps must increase" + (" (all zero: try stamps='log')" if not stamp.any() else ""),
            bag.path,
        )
    ranks = np.zeros(len(log), np.int64)
    same = np.flatnonzero(np.diff(log) == 0)
    for m in same:
        ranks[m + 1] = ranks[m] + 1
    refs = [MessageRef(topic, int(t), int(r)) for t, r in zip(log, ranks)]
    return _Topic(topic, refs, stamp)


@functools.lru_cache(maxsize=16)
def _stamps(path: Path, version: int, topic: str, stamps: str, ros1: bool) -> tuple[np.ndarray, np.ndarray]:
    """Log times and stamps (ns) of ``topic``'s messages (cached per bag version)."""
    log, stamp = [], []
    for log_ns, raw in open_bag(path).raw_messages(topic):
        log.append(log_ns)
        stamp.append(log_ns if stamps == "log" else header_stamp_ns(raw, ros1))
    return np.asarray(log, np.int64), np.asarray(stamp, np.int64)


def _only_image_topic(bag: Bag, others: set[str | None]) -> str:
    found = [topic for topic in bag.topics(IMAGE_TYPES) if topic not in others]
    if len(found) == 1:
        return found[0]
    if not found:
        raise DatasetError(
            f"the bag has no sensor_msgs/Image or CompressedImage topic; its topics: {', '.join(bag.topics()) or 'none'}", bag.path
        )
    raise DatasetError(f"the bag has several image topics ({', '.join(found)}); pass image_topic=", bag.path)


def _paired(left: _Topic, partner: _Topic | None, tolerance_s: float, path: Path, topic: str) -> list[tuple[int, int]]:
    """``(left message, partner message)`` pairs: the partner of the nearest stamp within the
    tolerance; left images without one are left out (one warning)."""
    if partner is None:
        return [(i, -1) for i in range(len(left.refs))]
    after = (
        np.clip(np.searchsorted(partner.stamps, left.stamps), 1, len(partner.stamps) - 1)
        if len(partner.stamps) > 1
        else np.zeros(len(left.stamps), np.int64)
    )
    before = np.maximum(after - 1, 0)
    nearest = np.where(np.abs(partner.stamps[after] - left.stamps) < np.abs(partner.stamps[before] - left.stamps), after, before)
    ok = np.abs(partner.stamps[nearest] - left.stamps) <= round(tolerance_s * 1e9)
    if not ok.all():
        warnings.warn(
            f"{path}: {int((~ok).sum())} of {len(ok)} images on {topic} have no {partner.topic} message within {tolerance_s:g} s; left out",
            DatasetWarning,
            stacklevel=4,
        )
    if not ok.any():
        raise DatasetError(f"no image on {topic} has a {partner.topic} message within pair_tolerance_s={tolerance_s:g} s", path)
    return [(int(i), int(nearest[i])) for i in np.flatnonzero(ok)]


def _records(path: Path, left: _Topic, partner: _Topic | None, sensor: str, pairs: list[tuple[int, int]]) -> list[FrameRecord]:
    """One record per pair: the left image, and the right image or the depth map."""
    records = []
    for position, (i, j) in enumerate(pairs):
        other = None if partner is None else partner.refs[j]
        records.append(
            FrameRecord(
                index=position,
                timestamp=int(left.stamps[i]) * 1e-9,
                stem=str(int(left.stamps[i])),
                image=BagImage(path, left.refs[i]),
                right=BagImage(path, other) if other is not None and sensor == "stereo" else None,
                depth=BagImage(path, other, depth=True) if other is not None and sensor == "rgbd" else None,
                timestamp_ns=int(left.stamps[i]),
            )
        )
    return records


def _rate(stamps: np.ndarray) -> float:
    """Frame rate (Hz) from the median stamp step; 10 Hz for a single frame."""
    steps = np.diff(stamps)
    return 1e9 / float(np.median(steps)) if len(steps) else 10.0


def _content_key(path: Path) -> str:
    """The bag's identity for caches: its files' names, sizes and modification times."""
    return "rosbag:" + ";".join(f"{p.name}:{p.stat().st_size}:{p.stat().st_mtime_ns}" for p in bag_files(path))


ROSBAG = RosbagDataset()
