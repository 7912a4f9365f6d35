"""The sequence model: frames decoded lazily, with camera, sensor, rate and ground truth."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, Literal

import numpy as np

from sal_adapters.camera import Camera
from sal_adapters.common.errors import DatasetError
from sal_adapters.images import Size, read_depth, read_image
from sal_adapters.trajectory import Trajectory, seconds_to_ns

__all__ = ["SENSORS", "Frame", "FrameRecord", "Sensor", "Sequence", "Source", "as_sensor"]

Sensor = Literal["mono", "stereo", "rgbd"]
SENSORS: tuple[str, ...] = ("mono", "stereo", "rgbd")


def as_sensor(name: object) -> Sensor:
    """``name`` as a ``Sensor`` (``mono``, ``stereo`` or ``rgbd``); ``ValueError`` for anything else."""
    match name:
        case "mono" | "stereo" | "rgbd":
            return name
    raise ValueError(f"sensor must be one of {', '.join(SENSORS)}; got {name!r}")


#: Where a frame's pixels come from: an image file, or a function that makes them.
Source = Path | Callable[[], np.ndarray]


@dataclass(frozen=True)
class FrameRecord:
    """What a sequence knows about one frame before decoding it.

    Attributes:
        index: position of the frame in the dataset it came from (stable under frame drops).
        timestamp: capture time (s).
        stem: file name stem used when the frame is written back (KITTI ``000042``, EuRoC ns).
        image, right, depth: sources of the left image, right image and depth map.
        timestamp_ns: the exact integer time (ns) when the dataset stores one (EuRoC).
    """

    index: int
    timestamp: float
    stem: str
    image: Source
    right: Source | None = None
    depth: Source | None = None
    timestamp_ns: int | None = None

    @property
    def time_ns(self) -> int:
        """The capture time in integer ns: the dataset's own (EuRoC), else the nearest to ``timestamp``."""
        return self.timestamp_ns if self.timestamp_ns is not None else seconds_to_ns(self.timestamp)

    @property
    def files(self) -> list[Path]:
        """The files this frame decodes from."""
        return [s for s in (self.image, self.right, self.depth) if isinstance(s, Path)]


class Frame:
    """One frame; ``image`` (HxWx3 uint8 RGB), ``right`` and ``depth`` (float32 m, 0 = invalid)
    are decoded on first access."""

    def __init__(self, record: FrameRecord, camera: Camera):
        self.record = record
        self._camera = camera

    @property
    def index(self) -> int:
        return self.record.index

    @property
    def timestamp(self) -> float:
        return self.record.timestamp

    @cached_property
    def image(self) -> np.ndarray:
        """The left image; a file of another size than the camera's is refused undecoded."""
        return _decode(self.record.image, lambda p: read_image(p, _size(self._camera)))

    @cached_property
    def right(self) -> np.ndarray | None:
        """The right image (the size of ``camera.right`` when the pair is not rectified)."""
        if self.record.right is None:
            return None
        return _decode(self.record.right, lambda p: read_image(p, _size(self._camera.right or self._camera)))

    @cached_property
    def depth(self) -> np.ndarray | None:
        """The depth map (m), of the camera's size."""
        if self.record.depth is None:
            return None
        return _decode(self.record.depth, lambda p: read_depth(p, self._camera.depth_scale, _size(self._camera)))

    def require(self, what: Literal["right", "depth"]) -> np.ndarray:
        """The right image or the depth map of a frame that must have it (a stereo or an RGB-D
        sequence's); ``DatasetError`` naming the frame when it has none."""
        value = self.right if what == "right" else self.depth
        if value is None:
            raise DatasetError(f"frame {self.index} has no {'right image' if what == 'right' else 'depth map'}")
        return value

    def __repr__(self) -> str:
        return f"Frame(index={self.index}, timestamp={self.timestamp:.6f})"


def _size(camera: Camera) -> Size:
    """``(width, height)`` (px) of the images of ``camera``."""
    return int(camera.width), int(camera.height)


def _decode(source: Source, reader: Callable[[Path], np.ndarray]) -> np.ndarray:
    return reader(source) if isinstance(source, Path) else source()


class Sequence:
    """An ordered, lazily decoded list of frames with its camera, sensor, rate and ground truth.

    Args:
        kind: dataset kind whose layout the sequence came from and is written back in
            (``kitti``, ``tum``, ``euroc``, ``folder``, ``synthetic`` or a plug-in kind).
        name: human-readable name (``kitti/07``).
        camera: the (left) camera.
        sensor: ``mono``, ``stereo`` (every record has a right image) or ``rgbd`` (depth).
        fps: nominal frame rate (Hz).
        records: the frames, in time order.
        groundtruth: camera-to-world poses of the (left) camera, or ``None``.
        grayscale: the dataset stores single-channel images (``Frame.image`` is still RGB).
        source: the dataset folder read from (never written to), or ``None``.
        meta: layout details the writer of ``kind`` needs (JSON-serialisable).
        content_key: replaces the file-based part of the fingerprint (rendered data).
    """

    def __init__(
        self,
        *,
        kind: str,
        name: str,
        camera: Camera,
        sensor: Sensor,
        fps: float,
        records: list[FrameRecord],
        groundtruth: Trajectory | None = None,
        grayscale: bool = False,
        source: Path | None = None,
        meta: dict[str, Any] | None = None,
        content_key: str | None = None,
    ):
        if sensor not in SENSORS:
            raise ValueError(f"sensor must be one of {', '.join(SENSORS)}; got {sensor!r}")
        if not fps > 0:
            raise ValueError(f"fps must be > 0 Hz, got {fps!r}")
        if sensor == "stereo" and any(r.right is None for r in records):
            raise ValueError("a stereo sequence needs a right image for every frame")
        if sensor == "rgbd" and any(r.depth is None for r in records):
            raise ValueError("an RGB-D sequence needs a depth map for every frame")
        self.kind = kind
        self.name = name
        self.camera = camera
        self.sensor: Sensor = sensor
        self.fps = float(fps)
        self.records = list(records)
        self.groundtruth = groundtruth
        self.grayscale = grayscale
        self.source = None if source is None else Path(source)
        self.meta = dict(meta or {})
        self.content_key = content_key

    # -- list behaviour ------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.records)

    def __getitem__(self, position: int) -> Frame:
        return Frame(self.records[position], self.camera)

    def __iter__(self) -> Iterator[Frame]:
        return (Frame(r, self.camera) for r in self.records)

    def __repr__(self) -> str:
        return f"Sequence({self.name!r}, kind={self.kind}, {len(self)} frames, {self.sensor}, {self.fps:g} Hz)"

    @property
    def timestamps(self) -> np.ndarray:
        """Frame times (s), float64."""
        return np.array([r.timestamp for r in self.records], dtype=np.float64)

    @property
    def indices(self) -> np.ndarray:
        """Dataset indices of the frames (gaps where frames were dropped)."""
        return np.array([r.index for r in self.records], dtype=np.int64)

    # -- derived sequences ---------------------------------------------------------------------
    def replace(self, **changes: Any) -> Sequence:
        """Copy with some constructor arguments changed."""
        args: dict[str, Any] = {
            "kind": self.kind,
            "name": self.name,
            "camera": self.camera,
            "sensor": self.sensor,
            "fps": self.fps,
            "records": self.records,
            "groundtruth": self.groundtruth,
            "grayscale": self.grayscale,
            "source": self.source,
            "meta": self.meta,
            "content_key": self.content_key,
        }
        args.update(changes)
        return Sequence(**args)

    def select(self, positions: Iterable[int] | np.ndarray) -> Sequence:
        """The frames at ``positions`` (in order); per-frame ground truth follows them."""
        positions = [int(p) for p in positions]
        records = [self.records[p] for p in positions]
        groundtruth = self.groundtruth
        if groundtruth is not None and self.groundtruth_is_per_frame:
            groundtruth = groundtruth.select(positions)
        return self.replace(records=records, groundtruth=groundtruth)

    @property
    def groundtruth_is_per_frame(self) -> bool:
        """True when the ground truth has exactly one pose per frame, at the frame times."""
        gt = self.groundtruth
        return gt is not None and len(gt) == len(self) and np.allclose(gt.timestamps, self.timestamps, rtol=0, atol=1e-6)

    # -- identity ------------------------------------------------------------------------------
    @cached_property
    def fingerprint(self) -> str:
        """SHA-256 (hex) of everything that defines the frames: files (name, size, mtime),
        frame selection, timestamps, camera, sensor, rate and ground truth."""
        h = hashlib.sha256()
        header = {
            "kind": self.kind,
            "camera": self.camera.to_dict(),
            "sensor": self.sensor,
            "fps": self.fps,
            "meta": self.meta,
            "content_key": self.content_key,
        }
        h.update(json.dumps(header, sort_keys=True, default=str).encode())
        h.update(self.timestamps.tobytes())
        h.update(self.indices.tobytes())
        if self.content_key is None:
            for record in self.records:
                for path in record.files:
                    try:
                        st = path.stat()
                    except OSError:
                        raise DatasetError("image file not found", path) from None
                    h.update(f"{path.name}:{st.st_size}:{st.st_mtime_ns};".encode())
        if self.groundtruth is not None:
            for arr in (self.groundtruth.timestamps, self.groundtruth.positions, self.groundtruth.quaternions):
                h.update(arr.tobytes())
        return h.hexdigest()

    def info(self) -> dict[str, Any]:
        """The summary ``sal dataset info --json`` prints."""
        return {
            "frames": len(self),
            "sensor": self.sensor,
            "fps": round(self.fps, 6),
            "camera": self.camera.summary(),
            "groundtruth_poses": 0 if self.groundtruth is None else len(self.groundtruth),
        }
