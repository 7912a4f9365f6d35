"""The YAML file beside a video that the ``video`` dataset kind reads and writes: the camera's
intrinsics, the clock of the frames and where the ground truth is.

``clip.yaml`` beside ``clip.mp4``::

    # pytest-sal video sidecar of clip.mp4
    fx: 707.0912            # pinhole intrinsics (px)
    fy: 707.0912
    cx: 601.8873
    cy: 183.1104
    width: 1226             # optional: checked against the video (px)
    height: 370             # optional
    distortion: []          # optional: OpenCV k1 k2 p1 p2 [k3 ...]
    fps: 9.6153846          # optional: nominal frame rate (Hz); default the stream's average rate
    grayscale: true         # optional: a grey camera; default: the stream's pix_fmt is gray*
    time_offset_s: 0.0      # optional: added to every frame time (s)
    time_offset_ns: 0       # optional: the same in integer ns, exact; wins over time_offset_s
    groundtruth: clip.groundtruth.txt   # optional: TUM file, relative to this file

An ORB-SLAM3 settings file (PinHole) is read too: the keys ``fx``, ``fy``, ``cx``, ``cy``,
``k1 k2 p1 p2 [k3]``, ``width``, ``height`` and ``fps`` prefixed ``Camera1.`` or ``Camera.``;
its other keys are ignored.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

from sal_adapters.camera import Camera
from sal_adapters.common.bounded_yaml import one_line, quote, read_dataset_yaml, type_name
from sal_adapters.common.errors import DatasetError
from sal_adapters.common.suggest import suggestion
from sal_adapters.common.textfiles import atomic_write_text, format_float
from sal_adapters.layout_io import DISTORTION_COUNTS, parse_numbers

__all__ = ["SIDECAR_KEYS", "Sidecar", "read_sidecar", "resolve_camera", "write_sidecar"]

#: The keys of a pytest-sal sidecar.
SIDECAR_KEYS = (
    "fx",
    "fy",
    "cx",
    "cy",
    "width",
    "height",
    "distortion",
    "fps",
    "grayscale",
    "time_offset_s",
    "time_offset_ns",
    "groundtruth",
)
_INTRINSICS = ("fx", "fy", "cx", "cy")
_ORB_PREFIXES = ("Camera1.", "Camera.")
_ORB_DISTORTION = ("k1", "k2", "p1", "p2", "k3")
#: ``time_offset_s`` and ``time_offset_ns`` may differ by this much (ns): ``time_offset_s``'s digits.
_OFFSET_TOLERANCE_NS = 1000
#: ``fail(key, problem)``: the ``DatasetError`` naming the sidecar, the key and its line.
_Fail = Callable[[str, str], DatasetError]


@dataclass(frozen=True)
class Sidecar:
    """What a sidecar says; ``None`` where it says nothing."""

    path: Path
    intrinsics: tuple[float, float, float, float] | None = None
    distortion: tuple[float, ...] = ()
    size: tuple[int, int] | None = None
    fps: float | None = None
    grayscale: bool | None = None
    time_offset_ns: int = 0
    groundtruth: Path | None = None


def read_sidecar(path: Path) -> Sidecar:
    """Read a sidecar (or an ORB-SLAM3 settings file); ``DatasetError`` naming the file, line
    and key of an unknown key, a value of the wrong type, a missing ``fx`` or ground-truth file."""
    document = read_dataset_yaml(path, "fx, fy, cx, cy[, distortion, time_offset_s, groundtruth, ...]", _opencv_yaml)
    data: dict[Any, Any] = document.data
    lines = document.key_lines
    if any(isinstance(key, str) and key.startswith(_ORB_PREFIXES) for key in data):
        if data.get("Camera.type", "PinHole") != "PinHole":
            raise DatasetError(
                f"Camera.type {quote(data['Camera.type'], 40)}: only PinHole cameras are read", path, lines.get("Camera.type")
            )
        data, lines = _from_orbslam3(data, lines)
    else:
        unknown = [key for key in data if key not in SIDECAR_KEYS]
        if unknown:
            raise DatasetError(
                f"unknown key {quote(unknown[0], 40)}" + suggestion(str(unknown[0]), SIDECAR_KEYS, "keys"), path, lines.get(unknown[0])
            )

    def fail(key: str, problem: str) -> DatasetError:
        return DatasetError(f"{key}: {problem}", path, lines.get(key))

    def number(key: str) -> float:
        value = data[key]
        try:
            if isinstance(value, bool) or not isinstance(value, int | float | str):
                raise ValueError
            result = float(value)  # YAML 1.1 reads 1e-05 as text
        except (ValueError, OverflowError):
            raise fail(key, f"expected a number, got {type_name(value)} {quote(value, 40)}") from None
        if not math.isfinite(result):
            raise fail(key, f"expected a finite number, got {quote(value, 40)}")
        return result

    present = [key for key in _INTRINSICS if key in data]
    if present and len(present) < len(_INTRINSICS):
        missing = next(key for key in _INTRINSICS if key not in data)
        raise DatasetError(f"missing {missing} (px): a sidecar gives all of fx, fy, cx, cy or none", path)
    intrinsics = None if not present else (number("fx"), number("fy"), number("cx"), number("cy"))
    distortion = [] if data.get("distortion") is None else data["distortion"]
    if not isinstance(distortion, list) or len(distortion) not in (0, *DISTORTION_COUNTS):
        counts = ", ".join(map(str, DISTORTION_COUNTS))
        raise fail("distortion", f"expected a list of {counts} numbers (k1 k2 p1 p2 [k3 ...]) or [], got {quote(distortion, 40)}")
    size = None
    if "width" in data or "height" in data:
        if "width" not in data or "height" not in data:
            raise fail("width" if "width" in data else "height", "give width and height (px) together, or neither")
        size = (int(number("width")), int(number("height")))
    fps = number("fps") if "fps" in data else None
    if fps is not None and not fps > 0:
        raise fail("fps", f"expected a rate > 0 Hz, got {fps:g}")
    grayscale = data.get("grayscale")
    if grayscale is not None and not isinstance(grayscale, bool):
        raise fail("grayscale", f"expected true or false, got {type_name(grayscale)} {quote(grayscale, 40)}")
    return Sidecar(
        path=path,
        intrinsics=intrinsics,
        distortion=tuple(_coefficient(v, fail) for v in distortion),
        size=size,
        fps=fps,
        grayscale=grayscale,
        time_offset_ns=_time_offset_ns(data, number, fail),
        groundtruth=_groundtruth(data, path, fail),
    )


def _opencv_yaml(text: str) -> str:
    """An OpenCV YAML text (ORB-SLAM3's settings) as plain YAML: the ``%YAML:1.0`` directive and
    the ``!!opencv-matrix`` tags dropped, line numbers kept."""
    return re.sub(r"!!opencv-matrix", "", re.sub(r"\A%YAML[: ]\s*1\.\d+[^\n]*", "", text))


def _from_orbslam3(data: dict[Any, Any], lines: dict[str, int]) -> tuple[dict[str, Any], dict[str, int]]:
    """The sidecar keys of an ORB-SLAM3 settings file, with the lines they come from."""
    found: dict[str, Any] = {}
    found_lines: dict[str, int] = {}
    for key in (*_INTRINSICS, "width", "height", "fps", *_ORB_DISTORTION):
        name = next((prefix + key for prefix in _ORB_PREFIXES if prefix + key in data), None)
        if name is not None:
            found[key] = data[name]
            if name in lines:
                found_lines[key] = lines[name]
    coefficients = [found.pop(key) for key in _ORB_DISTORTION if key in found]
    if coefficients:
        found["distortion"] = coefficients
        if "k1" in found_lines:
            found_lines["distortion"] = found_lines["k1"]
    return found, found_lines


def _coefficient(value: Any, fail: _Fail) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise fail("distortion", f"expected finite numbers, got {quote(value, 40)}")
    return float(value)


def _time_offset_ns(data: dict[str, Any], number: Callable[[str], float], fail: _Fail) -> int:
    """``time_offset_ns`` (exact), else ``time_offset_s`` in ns; both must agree when given."""
    seconds = None
    if "time_offset_s" in data:  # the decimal written (its shortest repr), not its float
        seconds = round(Fraction(repr(number("time_offset_s"))) * 10**9)
    if "time_offset_ns" not in data:
        return seconds or 0
    ns = data["time_offset_ns"]
    if isinstance(ns, bool) or not isinstance(ns, int):
        raise fail("time_offset_ns", f"expected a whole number of ns, got {type_name(ns)} {quote(ns, 40)}")
    if seconds is not None and abs(seconds - ns) > _OFFSET_TOLERANCE_NS:
        raise fail("time_offset_ns", f"{ns} ns differs from time_offset_s = {data['time_offset_s']} s; give one of them")
    return ns


def _groundtruth(data: dict[str, Any], path: Path, fail: _Fail) -> Path | None:
    name = data.get("groundtruth")
    if name is None:
        return None
    if not isinstance(name, str) or not name.strip():
        raise fail("groundtruth", f"expected a file name, got {type_name(name)} {quote(name, 40)}")
    file = path.parent / name
    if not file.is_file():
        raise fail("groundtruth", f"ground-truth file {file} not found")
    return file


def resolve_camera(
    video: Path,
    width: int,
    height: int,
    sidecar: Sidecar | None,
    looked_for: Path,
    intrinsics: Any,
    distortion: Any,
) -> Camera:
    """The camera of a ``width`` x ``height`` px video: the ``intrinsics`` option (no distortion
    unless ``distortion`` is given), else the sidecar's; ``distortion`` replaces the sidecar's.

    Raises:
        DatasetError: no intrinsics anywhere (naming the video, the sidecar ``looked_for`` and
            the option), a size other than the video's, or values no camera has.
    """
    coefficients: tuple[float, ...] = ()
    try:
        if intrinsics is not None:
            values, where = parse_numbers(intrinsics, "intrinsics (fx, fy, cx, cy in px)", (4,)), video
        elif sidecar is not None and sidecar.intrinsics is not None:
            values, coefficients, where = sidecar.intrinsics, sidecar.distortion, sidecar.path
        else:
            raise DatasetError(
                f"no camera intrinsics: no fx, fy, cx, cy in {looked_for} (sidecar YAML) and no option intrinsics=[fx, fy, cx, cy] (px)"
            )
        if distortion is not None:
            coefficients = parse_numbers(distortion, "distortion (k1 k2 p1 p2 [k3 ...])", (0, *DISTORTION_COUNTS))
    except DatasetError as exc:
        raise DatasetError(exc.problem, video) from None
    if sidecar is not None and sidecar.size not in (None, (width, height)):
        raise DatasetError(f"width x height is {sidecar.size[0]}x{sidecar.size[1]} px but the video is {width}x{height} px", sidecar.path)
    fx, fy, cx, cy = values
    try:
        camera = Camera(fx=fx, fy=fy, cx=cx, cy=cy, width=width, height=height, distortion=coefficients)
    except ValueError as exc:
        raise DatasetError(str(exc), where) from None
    if not (0 <= cx <= width and 0 <= cy <= height):
        raise DatasetError(f"principal point cx={cx:g} cy={cy:g} px lies outside the {width}x{height} px frame", where)
    return camera


def write_sidecar(
    path: Path,
    camera: Camera,
    *,
    fps: float,
    grayscale: bool,
    time_offset_ns: int,
    groundtruth: str | None,
    written_from: str,
) -> None:
    """Write the sidecar ``path`` so that ``read_sidecar`` restores ``camera``, ``fps``, the frame
    clock and the ground-truth file name exactly; ``written_from`` names the source in a comment."""
    lines = [
        f"# pytest-sal video sidecar: written by pytest-sal from {one_line(written_from, 120)}",
        "# pinhole intrinsics (px), OpenCV distortion; frame time (s) = pts x time_base + time_offset_s",
        *(f"{key}: {format_float(getattr(camera, key))}" for key in _INTRINSICS),
        f"width: {int(camera.width)}",
        f"height: {int(camera.height)}",
        f"distortion: [{', '.join(format_float(v) for v in camera.distortion)}]",
        f"fps: {format_float(fps)}",
        f"grayscale: {'true' if grayscale else 'false'}",
        f"time_offset_s: {_decimal_seconds(time_offset_ns)}",
        f"time_offset_ns: {time_offset_ns}",
    ]
    if groundtruth is not None:
        lines.append(f"groundtruth: {json.dumps(groundtruth)}")  # a JSON string is a YAML string
    atomic_write_text(path, "\n".join(lines) + "\n")


def _decimal_seconds(ns: int) -> str:
    """``ns`` as exact decimal seconds: ``1403715274.312143104``."""
    sign, ns = ("-" if ns < 0 else ""), abs(ns)
    return f"{sign}{ns // 10**9}.{ns % 10**9:09d}"
