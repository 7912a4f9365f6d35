"""Pieces shared by the image-list layouts (``tum``, ``folder``): the ``camera.yaml`` file,
timestamped file lists, camera options, natural sort and a first-image probe.

``camera.yaml`` describes the pinhole camera of the images beside it::

    # pytest-sal camera: pinhole intrinsics (px), OpenCV distortion, depth units per metre
    fx: 520.9
    fy: 521.0
    cx: 325.1
    cy: 249.7
    width: 640             # optional: checked against the images when present
    height: 480            # optional
    distortion: [0.2312, -0.7849, -0.0033, -0.0001, 0.9172]   # optional, k1 k2 p1 p2 [k3 ...]
    depth_scale: 5000.0    # optional: raw depth units per metre (TUM: 5000)

The ``tum`` and ``folder`` writers always write it, and both readers prefer it to guessed
intrinsics, so a written copy reopens with exactly the same camera.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from sal_adapters.camera import Camera
from sal_adapters.common.bounded_yaml import quote, read_dataset_yaml
from sal_adapters.common.errors import DatasetError
from sal_adapters.common.textfiles import atomic_write_text, check_times, format_float, read_rows
from sal_adapters.sequence import Frame

__all__ = [
    "CAMERA_FILE",
    "DISTORTION_COUNTS",
    "checked_image",
    "fps_from_timestamps",
    "frame_file_stem",
    "natural_key",
    "parse_numbers",
    "read_camera_yaml",
    "read_list",
    "select_camera",
    "write_camera_yaml",
]

#: Name of the camera description the ``tum`` and ``folder`` layouts read and write.
CAMERA_FILE = "camera.yaml"

_CAMERA_KEYS = ("fx", "fy", "cx", "cy", "width", "height", "distortion", "depth_scale")
#: Coefficient counts OpenCV accepts for ``distortion`` (besides none).
DISTORTION_COUNTS = (4, 5, 8, 12, 14)


# -- camera.yaml ------------------------------------------------------------------------------
def read_camera_yaml(path: Path, width: int, height: int) -> Camera:
    """Read ``camera.yaml`` for images of ``width`` x ``height`` px.

    ``width``/``height`` in the file, when present, must match the images.

    Raises:
        DatasetError: naming the file and line of a YAML error, an unknown key, a missing or
            invalid value or a size that differs from the images.
    """
    path = Path(path)
    document = read_dataset_yaml(path, "fx, fy, cx, cy[, width, height, distortion, depth_scale]")
    data, lines = document.data, document.key_lines

    def fail(message: str, key: str | None = None) -> DatasetError:
        return DatasetError(message, path, lines.get(key) if key else None)

    def failing(key: str) -> Callable[[str], DatasetError]:
        """``fail`` for a bad value of ``key``, the message prefixed with the key."""
        return lambda message: fail(f"{key}: {message}", key)

    unknown = [str(k) for k in data if k not in _CAMERA_KEYS]
    if unknown:
        raise fail(f"unknown key {quote(unknown[0], 40)} (allowed: {', '.join(_CAMERA_KEYS)})", unknown[0])
    values: dict[str, Any] = {}
    for key in ("fx", "fy", "cx", "cy"):
        if key not in data:
            raise fail(f"missing {key} (px)")
        values[key] = _number(data[key], failing(key))
    for key, actual in (("width", width), ("height", height)):
        if data.get(key) is not None:
            given = _number(data[key], failing(key))
            if given != actual:
                raise fail(f"{key} is {given:g} px but the images are {width}x{height} px", key)
    distortion = data.get("distortion") or ()
    if not isinstance(distortion, list | tuple) or len(distortion) not in (0, *DISTORTION_COUNTS):
        counts = ", ".join(map(str, DISTORTION_COUNTS))
        raise fail(f"distortion must be a list of {counts} numbers (k1 k2 p1 p2 [k3 ...]) or empty", "distortion")
    values["distortion"] = tuple(_number(v, failing("distortion")) for v in distortion)
    scale = data.get("depth_scale")
    if scale is not None:
        scale = _number(scale, failing("depth_scale"))
        if scale <= 0:
            raise fail(f"depth_scale must be > 0 (raw units per metre), got {scale:g}", "depth_scale")
    try:
        return Camera(width=int(width), height=int(height), depth_scale=scale, **values)
    except ValueError as exc:
        raise fail(str(exc)) from None


def write_camera_yaml(path: Path, camera: Camera, depth_scale: float | None = None) -> None:
    """Write ``camera``'s pinhole intrinsics, size, distortion and ``depth_scale`` (omitted when
    ``None``) so that ``read_camera_yaml`` restores the same values exactly."""
    lines = [
        "# pytest-sal camera: pinhole intrinsics (px), OpenCV distortion, depth units per metre",
        *(f"{key}: {format_float(getattr(camera, key))}" for key in ("fx", "fy", "cx", "cy")),
        f"width: {int(camera.width)}",
        f"height: {int(camera.height)}",
        f"distortion: [{', '.join(format_float(v) for v in camera.distortion)}]",
    ]
    if depth_scale is not None:
        lines.append(f"depth_scale: {format_float(depth_scale)}")
    atomic_write_text(Path(path), "\n".join(lines) + "\n")


def _number(value: Any, fail: Callable[[str], DatasetError]) -> float:
    """A finite float from a YAML scalar (``1e-05`` loads as text in YAML 1.1, so text is parsed)."""
    if isinstance(value, bool):
        raise fail(f"expected a number, got {quote(value)}")
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        raise fail(f"expected a number, got {quote(value)}") from None
    if not np.isfinite(number):
        raise fail(f"expected a finite number, got {quote(value)}")
    return number


# -- camera options ---------------------------------------------------------------------------
def parse_numbers(value: Any, option: str, counts: Iterable[int]) -> tuple[float, ...]:
    """Numbers from an option given as a sequence or as text (``"517.3 516.5 318.6 255.3"``,
    commas allowed); their count must be one of ``counts``."""
    allowed = tuple(counts)
    items = value.replace(",", " ").split() if isinstance(value, str) else value
    try:
        numbers = tuple(float(v) for v in items)
    except (TypeError, ValueError):
        raise DatasetError(f"option {option} must be numbers, got {value!r}") from None
    if len(numbers) not in allowed or not all(np.isfinite(numbers)):
        raise DatasetError(f"option {option} needs {' or '.join(map(str, allowed))} finite numbers, got {value!r}")
    return numbers


def select_camera(
    folder: Path,
    width: int,
    height: int,
    intrinsics: Any,
    distortion: Any,
    fallback: Callable[[], Camera],
) -> Camera:
    """The camera of a layout, in priority: the ``intrinsics`` option ``(fx, fy, cx, cy)`` (with
    no distortion unless ``distortion`` is given), ``folder/camera.yaml``, then ``fallback()``
    (the layout's guess). ``distortion`` alone replaces the distortion of whichever is used."""
    if intrinsics is not None:
        fx, fy, cx, cy = parse_numbers(intrinsics, "intrinsics (fx, fy, cx, cy in px)", (4,))
        try:
            camera = Camera(fx=fx, fy=fy, cx=cx, cy=cy, width=width, height=height)
        except ValueError as exc:
            raise DatasetError(f"option intrinsics: {exc}") from None
    elif (folder / CAMERA_FILE).is_file():
        camera = read_camera_yaml(folder / CAMERA_FILE, width, height)
    else:
        camera = fallback()
    if distortion is not None:
        coeffs = parse_numbers(distortion, "distortion (k1 k2 p1 p2 [k3 ...])", (0, *DISTORTION_COUNTS))
        camera = replace(camera, distortion=coeffs)
    return camera


# -- timestamped lists ------------------------------------------------------------------------
def read_list(path: Path, pattern: str, what: str, increasing: bool = True) -> list[tuple[int, list[float | str]]]:
    """Rows of a list file as ``(line number, values)``; ``pattern`` gives each column, ``t`` a
    time (s, float) and ``f`` a file name (``"tf"`` for TUM ``rgb.txt``). With ``increasing``,
    times in the first column must increase strictly. Every time must be finite (``check_times``).
    ``what`` describes a line for messages (``"timestamp filename"``)."""
    rows: list[tuple[int, list[float | str]]] = []
    for number, fields in read_rows(path):
        if len(fields) != len(pattern):
            raise DatasetError(f"expected {len(pattern)} fields '{what}', got {len(fields)}: {' '.join(fields)!r}", path, number)
        values: list[float | str] = []
        for kind, field in zip(pattern, fields):
            if kind == "t":
                try:
                    values.append(float(field))
                except ValueError:
                    raise DatasetError(f"expected a timestamp in seconds, got {field!r}", path, number) from None
            else:
                values.append(field)
        rows.append((number, values))
    if not rows:
        raise DatasetError(f"no lines '{what}' found", path)
    for column, kind in enumerate(pattern):
        if kind == "t":
            check_times(((number, float(values[column])) for number, values in rows), path, increasing=increasing and column == 0)
    return rows


def fps_from_timestamps(timestamps: np.ndarray, default: float) -> float:
    """The camera rate (Hz): 1 / the median of the frame intervals close to the shortest
    common one, so gaps from dropped frames do not lower it; ``default`` for < 2 frames.

    The shortest common interval is the 10th percentile of the intervals; intervals up to
    1.5 times it count as one frame period (jitter), longer ones are gaps.
    """
    t = np.asarray(timestamps, dtype=np.float64)
    if len(t) < 2:
        return float(default)
    steps = np.diff(t)
    shortest = float(np.percentile(steps, 10))
    return 1.0 / float(np.median(steps[steps <= 1.5 * shortest]))


# -- files ------------------------------------------------------------------------------------
def natural_key(name: str) -> tuple[Any, ...]:
    """Sort key putting ``img2.png`` before ``img10.png`` (digit runs compare as numbers)."""
    parts = re.split(r"(\d+)", name.lower())
    return tuple(int(p) if i % 2 else p for i, p in enumerate(parts))


def frame_file_stem(stem: str, position: int, used: set[str]) -> str:
    """A file name stem for a written frame: the frame's own stem when it is a plain, unused
    name, else the zero-padded position (``000042``)."""
    plain = bool(stem) and re.fullmatch(r"[A-Za-z0-9._+-]+", stem) is not None and not stem.startswith(".")
    name = stem if plain and stem not in used else f"{position:06d}"
    while name in used:
        name += "_"
    used.add(name)
    return name


def checked_image(frame: Frame, camera: Camera, sequence_name: str) -> np.ndarray:
    """``frame.image``, after checking that its size is the camera's (what ``camera.yaml`` says)."""
    image = frame.image
    if image.shape[:2] != (camera.height, camera.width):
        raise DatasetError(
            f"{sequence_name}: frame {frame.index} is {image.shape[1]}x{image.shape[0]} px but the camera is "
            f"{camera.width}x{camera.height} px"
        )
    return image
