"""An open ROS bag of any format (ROS 1 ``.bag``, ROS 2 sqlite3 or MCAP folder, bare ``.mcap``)
read with the pure-Python ``rosbags`` library: topics, raw messages by log time, header stamps.

One ``Bag`` per process and path (``open_bag``): frame sources only hold the path and a
``MessageRef``, so a sequence pickles to a worker, which opens the bag there on first use.
Every error is one ``DatasetError`` naming the bag (and the topic where one is concerned).
"""

from __future__ import annotations

import atexit
import os
import struct
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sal_adapters.common.errors import DatasetError
from sal_adapters.common.suggest import suggestion

__all__ = ["Bag", "MessageRef", "bag_files", "bag_format", "bag_version", "header_stamp_ns", "open_bag"]

#: Message types whose serialised form starts with a ``std_msgs/Header``.
IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")


@dataclass(frozen=True)
class MessageRef:
    """Where one message sits: its topic, its log time (ns) and its rank among that topic's
    messages logged at the same nanosecond (0 almost always)."""

    topic: str
    log_ns: int
    rank: int = 0


def bag_format(path: Path) -> str:
    """``ros1`` (a ``.bag`` file), ``mcap_file`` (a bare ``.mcap``) or ``sqlite3`` / ``mcap``
    (a ROS 2 bag folder, by its ``metadata.yaml``)."""
    if path.is_dir():
        metadata = path / "metadata.yaml"
        if not metadata.is_file():
            raise DatasetError("not a ROS 2 bag folder (no metadata.yaml in it)", path)
        text = metadata.read_text(encoding="utf-8", errors="replace")
        return "mcap" if "storage_identifier: mcap" in text else "sqlite3"
    suffix = path.suffix.lower()
    if suffix == ".bag":
        return "ros1"
    if suffix == ".mcap":
        return "mcap_file"
    raise DatasetError("not a ROS bag: expected a .bag file, a .mcap file or a ROS 2 bag folder", path)


def bag_files(path: Path) -> list[Path]:
    """The bag's files: ``path`` itself, or the files of a ROS 2 bag folder (sorted)."""
    return [path] if path.is_file() else sorted(p for p in path.iterdir() if p.is_file())


def bag_version(path: Path) -> int:
    """The newest modification time (ns) of the bag's files: a rewritten bag is opened afresh."""
    return max((p.stat().st_mtime_ns for p in bag_files(path)), default=0)


def header_stamp_ns(raw: bytes | memoryview, ros1: bool) -> int:
    """The ``header.stamp`` (ns) of a serialised message that starts with a ``std_msgs/Header``,
    read from its first bytes without deserialising the rest (the pixels).

    ROS 1: ``uint32 seq, uint32 sec, uint32 nsec`` little-endian; ROS 2 CDR: a 4-byte
    encapsulation header (byte 1: 1 = little-endian) then ``int32 sec, uint32 nanosec``.
    """
    if ros1:
        sec, nsec = struct.unpack_from("<II", raw, 4)
    else:
        order = "<" if raw[1] == 1 else ">"
        sec, nsec = struct.unpack_from(order + "iI", raw, 4)
    return int(sec) * 1_000_000_000 + int(nsec)


class Bag:
    """An open bag: its topics and types, its messages by topic and log time.

    Args:
        path: a ``.bag`` file, a ``.mcap`` file or a ROS 2 bag folder.

    Raises:
        DatasetError: the path is not a bag, or is truncated or unreadable (naming it).
    """

    def __init__(self, path: Path):
        from rosbags.highlevel import AnyReader

        self.path = path
        self.format = bag_format(path)
        self.ros1 = self.format == "ros1"
        self._lock = threading.Lock()
        try:
            self._reader: Any = AnyReader([path])
            self._reader.open()
        except Exception as exc:  # rosbags raises its own errors, struct and OS errors for damaged files
            raise DatasetError(f"cannot read the bag ({type(exc).__name__}: {exc}); it is not a ROS bag or it is truncated", path) from None
        self._connections: dict[str, list[Any]] = {}
        for connection in self._reader.connections:
            self._connections.setdefault(connection.topic, []).append(connection)

    @property
    def typestore(self) -> Any:
        """The rosbags type store holding every message type of the bag."""
        return self._reader.typestore

    @property
    def connections(self) -> list[Any]:
        """Every rosbags ``Connection`` of the bag."""
        return list(self._reader.connections)

    def topics(self, msgtypes: tuple[str, ...] | None = None) -> dict[str, str]:
        """Topic -> message type, of the given types only when ``msgtypes`` is given."""
        found = {topic: conns[0].msgtype for topic, conns in sorted(self._connections.items())}
        return {t: m for t, m in found.items() if msgtypes is None or m in msgtypes}

    def message_count(self, topic: str) -> int:
        """How many messages ``topic`` holds."""
        return sum(c.msgcount for c in self._connections.get(topic, []))

    def require(self, topic: str, option: str, msgtypes: tuple[str, ...]) -> str:
        """The message type of ``topic``; a ``DatasetError`` naming the bag, the topic and the
        option when the bag has no such topic (with the closest name or the topics of the
        right types) or when its type is not one of ``msgtypes``."""
        if topic not in self._connections:
            fitting = self.topics(msgtypes) or self.topics()
            raise DatasetError(
                f"{option}={topic!r}: no such topic in the bag" + suggestion(topic, fitting, "its topics of that kind"), self.path
            )
        msgtype = self._connections[topic][0].msgtype
        if msgtype not in msgtypes:
            raise DatasetError(f"{option}={topic!r} holds {msgtype}, expected {' or '.join(msgtypes)}", self.path)
        return msgtype

    def raw_messages(self, topic: str, start: int | None = None, stop: int | None = None) -> Iterator[tuple[int, bytes]]:
        """``(log time ns, serialised message)`` of ``topic`` in log-time order, optionally in
        ``[start, stop)`` (ns)."""
        try:
            for _, log_ns, raw in self._reader.messages(connections=self._connections[topic], start=start, stop=stop):
                yield log_ns, raw
        except Exception as exc:  # a chunk cut short by truncation shows here, not at open
            raise DatasetError(
                f"topic {topic}: cannot read its messages ({type(exc).__name__}: {exc}); the bag is truncated or damaged", self.path
            ) from None

    def all_messages(self) -> Iterator[tuple[Any, int, bytes]]:
        """``(connection, log time ns, serialised message)`` of every topic in log-time order."""
        try:
            yield from self._reader.messages()
        except Exception as exc:
            raise DatasetError(
                f"cannot read the bag's messages ({type(exc).__name__}: {exc}); the bag is truncated or damaged", self.path
            ) from None

    def read(self, ref: MessageRef) -> Any:
        """The deserialised message at ``ref``."""
        with self._lock:  # frame sources may be decoded by several threads (prefetching)
            found = list(self.raw_messages(ref.topic, ref.log_ns, ref.log_ns + 1))
        if len(found) <= ref.rank:
            raise DatasetError(
                f"topic {ref.topic}: no message logged at {ref.log_ns} ns any more (the bag changed since it was opened)", self.path
            )
        return self.deserialize(found[ref.rank][1], ref.topic)

    def deserialize(self, raw: bytes | memoryview, topic: str) -> Any:
        """``raw`` (a message of ``topic``) as a message object."""
        msgtype = self._connections[topic][0].msgtype
        try:
            return self._reader.deserialize(raw, msgtype)
        except Exception as exc:
            raise DatasetError(
                f"topic {topic}: a {msgtype} message does not deserialise ({type(exc).__name__}: {exc})", self.path
            ) from None

    def close(self) -> None:
        """Close the files."""
        self._reader.close()


_OPEN: dict[tuple[int, str, int], Bag] = {}
_OPEN_LOCK = threading.Lock()


@atexit.register
def _close_all() -> None:
    """Close the bags this process opened (at interpreter exit)."""
    for key, bag in list(_OPEN.items()):
        if key[0] == os.getpid():
            bag.close()


def open_bag(path: Path) -> Bag:
    """The ``Bag`` at ``path`` of this process, opened on first use (a forked or unpickling
    worker opens its own)."""
    path = Path(path).resolve()
    key = (os.getpid(), str(path), bag_version(path))
    with _OPEN_LOCK:
        bag = _OPEN.get(key)
        if bag is None:
            bag = _OPEN[key] = Bag(path)
        return bag
