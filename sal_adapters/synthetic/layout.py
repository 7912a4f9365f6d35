"""The synthetic folder layout, written for any sequence and read back exactly.

::

    sequence.json           kind, name, scene, seed, renderer_version, sensor, fps, camera,
                            grayscale (false), frames, cache (true for a render cache)
    times.txt               "stem index timestamp_s [timestamp_ns]" per frame (exact floats)
    groundtruth.txt         TUM poses of the left camera (when there is ground truth)
    image_left/STEM.png     RGB
    image_right/STEM.png    RGB (stereo, or whenever a frame has a right image)
    depth/STEM.npy          float32 z-depth in metres, 0 = invalid (whenever a frame has depth)
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sal_adapters.camera import Camera
from sal_adapters.common.errors import DatasetError
from sal_adapters.common.textfiles import atomic_write_text, check_times, format_float, read_rows
from sal_adapters.images import write_depth, write_image
from sal_adapters.sequence import SENSORS, Frame, FrameRecord, Sequence, as_sensor
from sal_adapters.trajectory import Trajectory

__all__ = [
    "DEPTH",
    "GROUNDTRUTH",
    "LEFT",
    "METADATA",
    "RIGHT",
    "TIMES",
    "FrameRow",
    "read_layout",
    "read_metadata",
    "read_times",
    "write_layout",
    "write_metadata",
]

METADATA, TIMES, GROUNDTRUTH = "sequence.json", "times.txt", "groundtruth.txt"
LEFT, RIGHT, DEPTH = "image_left", "image_right", "depth"
REQUIRED_KEYS = ("kind", "name", "sensor", "fps", "camera", "frames")


@dataclass(frozen=True)
class FrameRow:
    """One line of ``times.txt``."""

    stem: str
    index: int
    timestamp: float
    timestamp_ns: int | None = None


def write_metadata(folder: Path, info: dict[str, Any], rows: list[FrameRow], groundtruth: Trajectory | None) -> None:
    """Write ``times.txt``, ``groundtruth.txt`` and, last, ``sequence.json`` (atomically each)."""
    lines = ["# stem index timestamp_s [timestamp_ns]"]
    for row in rows:
        fields = [row.stem, str(row.index), format_float(row.timestamp)]
        if row.timestamp_ns is not None:
            fields.append(str(row.timestamp_ns))
        lines.append(" ".join(fields))
    atomic_write_text(folder / TIMES, "\n".join(lines) + "\n")
    if groundtruth is not None:
        groundtruth.write_tum(folder / GROUNDTRUTH)
    atomic_write_text(folder / METADATA, json.dumps(info, indent=2) + "\n")


def read_metadata(folder: Path) -> dict[str, Any]:
    """``sequence.json`` of a synthetic folder, checked for the keys every reader needs."""
    path = folder / METADATA
    if not path.is_file():
        raise DatasetError(f"not a synthetic dataset folder: {METADATA} not found", folder)
    try:
        info = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DatasetError(f"cannot read metadata ({exc})", path) from None
    if not isinstance(info, dict):
        raise DatasetError("metadata must be a JSON object", path)
    missing = [key for key in REQUIRED_KEYS if key not in info]
    if missing:
        raise DatasetError(f"metadata lacks {', '.join(missing)}", path)
    if info["sensor"] not in SENSORS:
        raise DatasetError(f"sensor must be one of {', '.join(SENSORS)}, got {info['sensor']!r}", path)
    if not isinstance(info["fps"], (int, float)) or not info["fps"] > 0:
        raise DatasetError(f"fps must be a number > 0, got {info['fps']!r}", path)
    try:
        info["camera"] = Camera.from_dict(info["camera"])
    except (TypeError, ValueError, AttributeError) as exc:
        raise DatasetError(f"bad camera ({exc})", path) from None
    return info


def read_times(path: Path) -> list[tuple[int, FrameRow]]:
    """``(line number, row)`` for every frame of a ``times.txt``."""
    rows = []
    stems: set[str] = set()
    for number, fields in read_rows(path):
        if len(fields) not in (3, 4):
            raise DatasetError(f"expected 3 or 4 fields (stem index timestamp_s [timestamp_ns]), got {len(fields)}", path, number)
        try:
            row = FrameRow(fields[0], int(fields[1]), float(fields[2]), int(fields[3]) if len(fields) == 4 else None)
        except ValueError as exc:
            raise DatasetError(f"expected an integer index, a time in seconds and optionally integer ns ({exc})", path, number) from None
        if row.stem in stems:
            raise DatasetError(f"frame stem {row.stem!r} appears twice", path, number)
        stems.add(row.stem)
        rows.append((number, row))
    if not rows:
        raise DatasetError("no frames listed", path)
    check_times(((number, row.timestamp) for number, row in rows), path)
    return rows


def write_layout(sequence: Sequence, out_dir: Path, frames: Iterable[Frame]) -> Path:
    """Write ``sequence`` (any kind and sensor) in the synthetic layout; ``frames`` are its
    decoded frames in order. Returns ``out_dir``."""
    out_dir = Path(out_dir)
    rows = [FrameRow(r.stem, r.index, r.timestamp, r.timestamp_ns) for r in sequence.records]
    stems = set()
    for row in rows:
        if not row.stem or row.stem != row.stem.strip() or any(c.isspace() or c in "/\\" for c in row.stem) or row.stem.startswith("."):
            raise DatasetError(f"frame stem {row.stem!r} cannot be used as a file name in the synthetic layout")
        if row.stem in stems:
            raise DatasetError(f"frame stem {row.stem!r} appears twice in {sequence.name}")
        stems.add(row.stem)
    written = 0
    for frame in frames:
        stem = frame.record.stem
        write_image(out_dir / LEFT / f"{stem}.png", frame.image)
        if frame.right is not None:
            write_image(out_dir / RIGHT / f"{stem}.png", frame.right)
        if frame.depth is not None:
            write_depth(out_dir / DEPTH / f"{stem}.npy", frame.depth, None)
        written += 1
    if written != len(rows):
        raise DatasetError(f"expected {len(rows)} frames of {sequence.name} to write, got {written}")
    meta = sequence.meta if sequence.kind == "synthetic" else {}
    info = {
        "kind": "synthetic",
        "name": sequence.name,
        "scene": meta.get("scene"),
        "seed": meta.get("seed"),
        "renderer_version": meta.get("renderer_version"),
        "sensor": sequence.sensor,
        "fps": sequence.fps,
        "camera": sequence.camera.to_dict(),
        "grayscale": False,
        "frames": len(rows),
        "cache": False,
    }
    write_metadata(out_dir, info, rows, sequence.groundtruth)
    return out_dir


def read_layout(folder: Path, info: dict[str, Any], sensor: str | None) -> Sequence:
    """The sequence of a written synthetic folder (``info`` from ``read_metadata``).

    Every frame needs its left image; with ``sensor=None`` every stored right image and depth
    map is attached and the stored sensor kept, otherwise only the streams of ``sensor``
    (which must exist for every frame).
    """
    times = folder / TIMES
    listing = {name: set(os.listdir(folder / name)) if (folder / name).is_dir() else set() for name in (LEFT, RIGHT, DEPTH)}
    explicit = sensor is not None
    chosen = as_sensor(sensor or info["sensor"])
    needed = [LEFT] + ([RIGHT] if chosen == "stereo" else []) + ([DEPTH] if chosen == "rgbd" else [])
    records = []
    for number, row in read_times(times):
        files = {name: folder / name / f"{row.stem}{'.npy' if name == DEPTH else '.png'}" for name in listing}
        present = {name: path.name in listing[name] for name, path in files.items()}
        for name in needed:
            if not present[name]:
                raise DatasetError(f"frame {row.stem!r} (listed in {times}:{number}) has no file", files[name])
        right = files[RIGHT] if present[RIGHT] and (not explicit or chosen == "stereo") else None
        depth = files[DEPTH] if present[DEPTH] and (not explicit or chosen == "rgbd") else None
        records.append(FrameRecord(row.index, row.timestamp, row.stem, files[LEFT], right, depth, row.timestamp_ns))
    groundtruth = Trajectory.read_tum(folder / GROUNDTRUTH) if (folder / GROUNDTRUTH).is_file() else None
    camera: Camera = info["camera"]
    meta = {key: info[key] for key in ("scene", "seed", "renderer_version") if info.get(key) is not None}
    return Sequence(
        kind="synthetic",
        name=str(info["name"]),
        camera=camera,
        sensor=chosen,
        fps=float(info["fps"]),
        records=records,
        groundtruth=groundtruth,
        source=folder,
        meta=meta,
    )
