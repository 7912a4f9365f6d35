"""Writing a sequence as a bag: the source bag with its image topics replaced, or a new bag.

A sequence opened from a bag is written in the same format family (ROS 1 ``.bag``; ROS 2
sqlite3, MCAP folder or bare ``.mcap``): every message of the source is copied in log order with
its connection (type, definition, QoS, caller id), except the messages of the image topics the
sequence reads (left, right, depth). Those are written for the frames the sequence keeps, with
the original header, encoding and log time and the sequence's pixels (depth maps unchanged);
frames a perturbation dropped are absent from the image topics only. When the sequence is an
excerpt (``start``/``max_frames``), the other topics are copied over its log-time span. A
sequence from a folder, or one changing format family, is written as a new bag
(``sal_adapters.rosbag.messages``). Messages stream: memory holds a few frames, not the bag.
"""

from __future__ import annotations

import heapq
import shutil
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from sal_adapters.common.errors import DatasetError
from sal_adapters.rosbag.bag import Bag, MessageRef
from sal_adapters.rosbag.messages import FRESH_TOPICS, camera_info_message, header, image_message, tf_message, typestore
from sal_adapters.rosbag.pixels import BagImage, encode_like
from sal_adapters.sequence import Frame, Sequence
from sal_adapters.trajectory import seconds_to_ns

__all__ = ["write_bag", "write_messages"]

#: A message to write: (log time ns, topic, message object).
Item = tuple[int, str, Any]


def write_bag(
    sequence: Sequence, target: Path, fmt: str, frames: Iterable[Frame], clean: Sequence | None = None, extra: Iterable[Item] = ()
) -> None:
    """Write ``sequence`` as a bag of format ``fmt`` (``ros1``, ``sqlite3``, ``mcap``,
    ``mcap_file``) at ``target``, taking the pixels from ``frames``: a copy of its source bag
    when ``clean`` (the source bag opened as ``sequence`` was, before any perturbation) is
    given, else a new bag to which ``extra`` adds messages (``FRESH_TOPICS`` types, in time
    order)."""
    if clean is not None:
        _copy_through(sequence, clean, target, fmt, frames)
    else:
        store = typestore(fmt == "ros1")
        write_messages(
            target, fmt, store, heapq.merge(_fresh(sequence, frames, store.types, fmt == "ros1"), extra, key=lambda item: item[0])
        )


def write_messages(target: Path, fmt: str, store: Any, items: Iterable[Item]) -> None:
    """Write ``items`` (``FRESH_TOPICS`` message objects in time order) as a new bag."""
    ros1 = fmt == "ros1"
    with _Writer(target, fmt) as writer:
        connections: dict[str, Any] = {}
        for ns, topic, message in items:
            msgtype = FRESH_TOPICS[topic]
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=store)
            data = store.serialize_ros1(message, msgtype) if ros1 else store.serialize_cdr(message, msgtype)
            writer.write(connections[topic], ns, data)


def _fresh(sequence: Sequence, frames: Iterable[Frame], types: Any, ros1: bool) -> Iterator[Item]:
    """Messages of a sequence that did not come from a bag (see ``messages``), in time order."""
    camera, grey = sequence.camera, bool(sequence.grayscale)
    right = camera.right or camera
    T_lr = camera.T_lr if sequence.sensor == "stereo" else None
    truth = sequence.groundtruth
    gt = iter(()) if truth is None else zip((seconds_to_ns(t) for t in truth.timestamps), truth.matrices)
    pending = next(gt, None)
    for number, frame in enumerate(frames):
        ns = frame.record.time_ns
        while pending is not None and pending[0] <= ns:
            yield pending[0], "/tf", tf_message(types, pending[1], header(types, pending[0], "world", ros1), "cam0")
            pending = next(gt, None)
        if number == 0 and T_lr is not None:
            yield ns, "/tf_static", tf_message(types, T_lr, header(types, ns, "cam0", ros1), "cam1")
        yield ns, "/cam0/image_raw", image_message(types, frame.image, grey, header(types, ns, "cam0", ros1))
        yield ns, "/cam0/camera_info", camera_info_message(types, camera, header(types, ns, "cam0", ros1))
        if T_lr is not None:
            tx = -right.fx * float(np.linalg.norm(T_lr[:3, 3])) if camera.right is None else 0.0
            yield ns, "/cam1/image_raw", image_message(types, frame.require("right"), grey, header(types, ns, "cam1", ros1))
            yield ns, "/cam1/camera_info", camera_info_message(types, right, header(types, ns, "cam1", ros1), tx)
    while pending is not None:
        yield pending[0], "/tf", tf_message(types, pending[1], header(types, pending[0], "world", ros1), "cam0")
        pending = next(gt, None)


def _copy_through(sequence: Sequence, clean: Sequence, target: Path, fmt: str, frames: Iterable[Frame]) -> None:
    """The source bag with the sequence's frames on its image topics (see the module text)."""
    assert sequence.source is not None
    roles: dict[MessageRef, tuple[int, str]] = {}
    for record in clean.records:
        for role, frame_source in (("image", record.image), ("right", record.right), ("depth", record.depth)):
            if isinstance(frame_source, BagImage):
                roles[frame_source.ref] = (record.index, role)
    kept = {record.index for record in sequence.records}
    span = _log_span(clean, sequence)
    source = Bag(sequence.source)  # a reader of its own: frames decode through the shared one meanwhile
    wanted = _Frames(frames, kept, {role for _, role in roles.values()})
    grey = bool(sequence.grayscale)
    options = clean.meta.get("options", {})
    image_topics = {options.get("image_topic"), options.get("right_image_topic"), options.get("depth_topic")}
    store = source.typestore
    try:
        with _Writer(target, fmt) as writer:
            connections = _connections_like(writer, source, fmt)
            last: dict[str, tuple[int, int]] = {}  # topic -> (log ns, rank) of its latest message
            for connection, log_ns, raw in source.all_messages():
                previous = last.get(connection.topic)
                rank = previous[1] + 1 if previous is not None and previous[0] == log_ns else 0
                last[connection.topic] = (log_ns, rank)
                ref = MessageRef(connection.topic, log_ns, rank)
                owner = roles.get(ref)
                if owner is None:
                    if span[0] <= log_ns <= span[1] and connection.topic not in image_topics:
                        writer.write(connections[connection.id], log_ns, raw)
                    continue
                index, role = owner
                if index not in kept:
                    continue
                frame = wanted.take(index, role)
                if role == "depth":
                    writer.write(connections[connection.id], log_ns, raw)
                    continue
                message = source.deserialize(raw, connection.topic)
                pixels = frame.image if role == "image" else frame.require("right")
                rebuilt = encode_like(message, pixels, grey, connection.topic)
                data = (
                    store.serialize_ros1(rebuilt, connection.msgtype) if fmt == "ros1" else store.serialize_cdr(rebuilt, connection.msgtype)
                )
                writer.write(connections[connection.id], log_ns, data)
    finally:
        source.close()
    if wanted.missing():
        raise DatasetError(f"{sequence.name}: frames {sorted(wanted.missing())[:5]} were not found in the source bag", sequence.source)


def _log_span(clean: Sequence, sequence: Sequence) -> tuple[float, float]:
    """Log times (ns) over which other topics are copied: all of the bag, or the excerpt's
    (``meta["excerpt"]``, set by ``truncate``) from its first to its last image."""
    excerpt = sequence.meta.get("excerpt")
    if not excerpt:
        return -np.inf, np.inf
    first, stop = excerpt
    start = -np.inf if first == 0 else _log_ns(clean.records[first].image)
    end = np.inf if stop >= len(clean) else _log_ns(clean.records[stop - 1].image)
    return start, end


def _log_ns(source: Any) -> float:
    assert isinstance(source, BagImage)
    return float(source.ref.log_ns)


class _Frames:
    """The sequence's frames by dataset index, pulled from ``frames`` in order as they are
    needed and let go once every image topic has had its message."""

    def __init__(self, frames: Iterable[Frame], kept: set[int], roles: set[str]):
        self._frames = iter(frames)
        self._held: dict[int, tuple[Frame, set[str]]] = {}
        self._kept = set(kept)
        self._roles = roles

    def take(self, index: int, role: str) -> Frame:
        while index not in self._held:
            frame = next(self._frames, None)
            if frame is None:
                raise DatasetError(f"frame {index} is not among the frames to write")
            self._held[frame.index] = (frame, set(self._roles))
        frame, left = self._held[index]
        left.discard(role)
        if not left:
            del self._held[index]
            self._kept.discard(index)
        return frame

    def missing(self) -> set[int]:
        """Kept frames whose messages never came."""
        return {i for i in self._kept if i not in self._held or self._held[i][1]}


def _connections_like(writer: Any, source: Bag, fmt: str) -> dict[int, Any]:
    """Source connection id -> a connection of ``writer`` like it (type, definition, extras);
    connections of one topic and type share one."""
    made: dict[tuple[str, str], Any] = {}
    out = {}
    for connection in source.connections:
        key = (connection.topic, connection.msgtype)
        if key not in made:
            ext, msgdef, digest = connection.ext, connection.msgdef.data or None, connection.digest or None
            if fmt == "ros1":
                made[key] = writer.add_connection(
                    *key, typestore=source.typestore, msgdef=msgdef, md5sum=digest, callerid=ext.callerid, latching=ext.latching
                )
            else:
                made[key] = writer.add_connection(
                    *key,
                    typestore=source.typestore,
                    msgdef=msgdef if digest else None,
                    rihs01=digest if msgdef else None,
                    serialization_format=ext.serialization_format,
                    offered_qos_profiles=ext.offered_qos_profiles,
                )
        out[connection.id] = made[key]
    return out


class _Writer:
    """A rosbags writer for ``fmt`` at ``target``; a bare ``.mcap`` is written as a ROS 2 MCAP
    bag beside it whose one file then takes the target's name."""

    def __init__(self, target: Path, fmt: str):
        from rosbags.rosbag1 import Writer as Ros1Writer
        from rosbags.rosbag2 import StoragePlugin
        from rosbags.rosbag2 import Writer as Ros2Writer

        self.target, self.fmt = target, fmt
        self.folder = target.with_name(target.name + ".rosbag2") if fmt == "mcap_file" else target
        if fmt == "ros1":
            self.writer: Any = Ros1Writer(target)
        else:
            plugin = StoragePlugin.SQLITE3 if fmt == "sqlite3" else StoragePlugin.MCAP
            self.writer = Ros2Writer(self.folder, version=9, storage_plugin=plugin)

    def __enter__(self) -> Any:
        self.writer.open()
        return self.writer

    def __exit__(self, kind: type[BaseException] | None, *exc: object) -> None:
        self.writer.close()
        if kind is None and self.fmt == "mcap_file":
            (self.folder / f"{self.folder.name}.mcap").replace(self.target)
            shutil.rmtree(self.folder)
