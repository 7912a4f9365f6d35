"""The files of a EuRoC camera: ``sensor.yaml`` (read and written) and the frame list ``data.csv``.

A camera ``sensor.yaml`` (OpenCV's ``%YAML:1.0`` flavour) holds the intrinsics
``[fu, fv, cu, cv]`` (px), radial-tangential distortion ``[k1, k2, p1, p2]``, resolution, rate
(Hz) and ``T_BS``, the camera's pose in the body (IMU) frame. ``data.csv`` lists
``timestamp [ns], filename`` per frame, the file in the ``data/`` folder beside it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sal_adapters.camera import Camera, frame_size_problem
from sal_adapters.common.bounded_yaml import quote, read_dataset_yaml
from sal_adapters.common.errors import DatasetError
from sal_adapters.common.textfiles import check_times, read_rows

__all__ = [
    "CAMERA_KEYS",
    "FRAME_CSV_HEADER",
    "GT_SENSOR_YAML",
    "CameraSensor",
    "FrameRow",
    "read_camera_sensor",
    "read_frame_csv",
    "read_sensor_yaml",
    "read_transform",
    "sensor_yaml",
]

#: Keys every camera ``sensor.yaml`` must hold.
CAMERA_KEYS = ("T_BS", "rate_hz", "resolution", "intrinsics", "distortion_coefficients")
FRAME_CSV_HEADER = "#timestamp [ns],filename"
#: The fastest camera rate a sensor.yaml may state (Hz).
_MAX_RATE_HZ = 1e6
_RADTAN_NAMES = ("radial-tangential", "radtan", "plumb_bob", "none")


@dataclass(frozen=True)
class CameraSensor:
    """One camera's ``sensor.yaml``: intrinsics and distortion, rate (Hz) and pose in the body
    frame (``T_BS``, 4x4)."""

    camera: Camera
    rate_hz: float
    T_BS: np.ndarray


@dataclass(frozen=True)
class FrameRow:
    """One ``data.csv`` row: its line number, time (ns) and image file."""

    line: int
    ns: int
    file: Path


def read_sensor_yaml(path: Path) -> dict[str, Any]:
    """Parse a EuRoC ``sensor.yaml`` within the bounded loader's limits (the OpenCV
    ``%YAML:1.0`` directive is dropped)."""
    return read_dataset_yaml(Path(path), "sensor keys", _drop_directive).data


def _drop_directive(text: str) -> str:
    return re.sub(r"\A%YAML[: ]\s*1\.\d+[^\n]*", "", text)  # keeps the line numbers


def read_camera_sensor(path: Path) -> CameraSensor:
    """Camera, rate (Hz) and ``T_BS`` from a camera ``sensor.yaml``; every key of ``CAMERA_KEYS``
    must be present, the resolution within ``MAX_FRAME_SIDE_PX`` and ``MAX_FRAME_PIXELS``."""
    path = Path(path)
    data = read_sensor_yaml(path)
    missing = [key for key in CAMERA_KEYS if key not in data]
    if missing:
        raise DatasetError(f"missing key {', '.join(map(repr, missing))} (a camera sensor.yaml needs {', '.join(CAMERA_KEYS)})", path)
    model = data.get("camera_model", "pinhole")
    if model != "pinhole":
        raise DatasetError(f"camera_model {quote(model)} is not supported (pinhole only)", path)
    dist_model = data.get("distortion_model", "radial-tangential")
    if dist_model not in _RADTAN_NAMES:
        raise DatasetError(f"distortion_model {quote(dist_model)} is not supported (radial-tangential only)", path)
    intrinsics = _numbers(data, "intrinsics", path, (4,))
    resolution = _numbers(data, "resolution", path, (2,))
    distortion = _numbers(data, "distortion_coefficients", path, (0, 4, 5))
    T_BS = read_transform(data["T_BS"], path)
    rate = data["rate_hz"]
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not 0 < rate <= _MAX_RATE_HZ:
        raise DatasetError(f"key 'rate_hz' must be a positive number of Hz up to {_MAX_RATE_HZ:g}, got {quote(rate)}", path)
    problem = frame_size_problem(*resolution)
    if problem:
        raise DatasetError(f"key 'resolution' must be [width, height] (px): {problem}", path)
    try:
        fx, fy, cx, cy = intrinsics
        camera = Camera(fx, fy, cx, cy, width=int(resolution[0]), height=int(resolution[1]), distortion=tuple(distortion))
    except ValueError as exc:  # only the intrinsics are left to check
        raise DatasetError(f"key 'intrinsics': {exc}", path) from None
    return CameraSensor(camera=camera, rate_hz=float(rate), T_BS=T_BS)


def read_frame_csv(path: Path) -> list[FrameRow]:
    """Rows of a camera ``data.csv``: ``timestamp [ns], filename`` (relative to ``data/``).

    Timestamps must be integers and increase; a bad line raises ``DatasetError`` with its number.
    """
    path = Path(path)
    folder = path.parent / "data"
    rows: list[FrameRow] = []
    for number, fields in read_rows(path, delimiter=","):
        if not rows and fields[0].lower().startswith("timestamp"):
            continue  # a header written without '#'
        if len(fields) != 2 or not fields[1]:
            raise DatasetError(f"expected 2 comma-separated values (timestamp [ns], filename), got {len(fields)}", path, number)
        if not fields[0].isdigit():
            raise DatasetError(f"expected an integer timestamp in ns, got {fields[0]!r}", path, number)
        rows.append(FrameRow(number, int(fields[0]), folder / fields[1]))
    check_times(((row.line, row.ns) for row in rows), path, unit="ns")
    return rows


def _numbers(data: dict[str, Any], key: str, path: Path, counts: tuple[int, ...]) -> list[float]:
    """The list of numbers under ``key``; its length must be one of ``counts``."""
    value = data[key]
    numbers: list[float] | None = None
    if isinstance(value, (list, tuple)):
        try:
            numbers = [float(v) for v in value]
        except (TypeError, ValueError, OverflowError):
            numbers = None
    if numbers is None or len(numbers) not in counts or not np.all(np.isfinite(numbers)):
        expected = " or ".join(map(str, counts))
        raise DatasetError(f"key {key!r} must be a list of {expected} numbers, got {quote(value)}", path)
    return numbers


def read_transform(value: Any, path: Path) -> np.ndarray:
    """A 4x4 ``T_BS`` from ``{cols: 4, rows: 4, data: [16 numbers]}`` (or a nested list)."""
    data = value.get("data") if isinstance(value, dict) else value
    try:
        T = np.array(data, dtype=np.float64).reshape(4, 4)
    except (TypeError, ValueError, OverflowError):
        raise DatasetError(f"key 'T_BS' must hold 16 numbers (4x4 row-major), got {quote(value)}", path) from None
    if isinstance(value, dict) and (value.get("rows", 4) != 4 or value.get("cols", 4) != 4):
        raise DatasetError("key 'T_BS' must be 4 rows x 4 cols", path)
    if not np.all(np.isfinite(T)) or abs(np.linalg.det(T[:3, :3]) - 1.0) > 1e-3:
        raise DatasetError("key 'T_BS' is not a rigid transform (its rotation has determinant != 1)", path)
    return T


#: The ``sensor.yaml`` of written ground truth: body poses, so the identity ``T_BS``.
GT_SENSOR_YAML = """%YAML:1.0
# General sensor definitions.
sensor_type: visual-inertial
comment: Body (IMU) frame poses, written by pytest-sal.

# Sensor extrinsics wrt. the body-frame.
T_BS:
  cols: 4
  rows: 4
  data: [1.0, 0.0, 0.0, 0.0,
         0.0, 1.0, 0.0, 0.0,
         0.0, 0.0, 1.0, 0.0,
         0.0, 0.0, 0.0, 1.0]
"""


def sensor_yaml(camera: Camera, T_BS: np.ndarray, fps: float, comment: str) -> str:
    """A camera ``sensor.yaml`` that reads back to exactly ``camera`` (values as shortest floats)."""
    T = [_yaml_float(v) for v in np.ravel(T_BS)]
    rows = ",\n         ".join(", ".join(T[4 * r : 4 * r + 4]) for r in range(4))
    intrinsics = ", ".join(_yaml_float(v) for v in (camera.fx, camera.fy, camera.cx, camera.cy))
    distortion = ", ".join(_yaml_float(v) for v in camera.distortion)
    return (
        "%YAML:1.0\n"
        "# General sensor definitions.\n"
        "sensor_type: camera\n"
        f"comment: {_yaml_string(comment)}\n\n"
        "# Sensor extrinsics wrt. the body-frame.\n"
        "T_BS:\n  cols: 4\n  rows: 4\n"
        f"  data: [{rows}]\n\n"
        "# Camera specific definitions.\n"
        f"rate_hz: {_yaml_float(fps)}\n"
        f"resolution: [{int(camera.width)}, {int(camera.height)}]\n"
        "camera_model: pinhole\n"
        f"intrinsics: [{intrinsics}] #fu, fv, cu, cv\n"
        "distortion_model: radial-tangential\n"
        f"distortion_coefficients: [{distortion}]\n"
    )


def _yaml_float(value: float) -> str:
    """Shortest round-trip text of a float that YAML 1.1 also reads as a float (``1.0e-05``)."""
    text = repr(float(value))
    mantissa, e, exponent = text.partition("e")
    if e and "." not in mantissa:
        text = f"{mantissa}.0e{exponent}"
    return text


def _yaml_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'
