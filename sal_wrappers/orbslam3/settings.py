"""ORB-SLAM3 settings files (OpenCV YAML, ``File.version: "1.0"``) made from a ``Camera``.

ORB-SLAM3 is strict about types and calls ``exit(-1)`` on a mismatch: every real must be
written with a decimal point or an exponent (``500.0``, ``1.76e-05``) and every integer
without one (``Camera.fps: 10``), and all ten ``Viewer.*`` keys are required even without a
viewer. This module writes values through typed formatters so that both rules always hold.

What is written, per sensor mode:

* always: ``File.version``, ``Camera.type: "PinHole"``, ``Camera1.fx/fy/cx/cy`` (px),
  ``Camera1.k1 k2 p1 p2`` (zeros when the camera has no distortion) and ``Camera1.k3`` when the
  camera has five coefficients, ``Camera.width/height`` (px, int), ``Camera.fps`` (Hz, rounded
  int, at least 1), ``Camera.RGB: 1`` (colour input is RGB; the wrapper passes grey images,
  for which ORB-SLAM3 ignores it), ``ORBextractor.*`` and ``Viewer.*``;
* stereo: ``Camera2.*`` (the right camera's own intrinsics and distortion for an unrectified
  pair such as EuRoC, else a copy of ``Camera1``), ``Stereo.T_c1_c2`` (pose of camera 2 in
  camera 1, the camera's ``T_lr``) and ``Stereo.ThDepth`` (close/far threshold in baselines).
  ``Camera.type: "Rectified"`` is never used: ORB-SLAM3 segfaults on it in stereo; with
  ``PinHole`` it rectifies the pair itself;
* rgbd: ``RGBD.DepthMapFactor: 1.0`` (depth is passed as float32 metres), ``Stereo.ThDepth``
  and ``Stereo.b`` (the virtual baseline in metres, required by ORB-SLAM3 even for RGB-D).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sal_adapters.camera import Camera
from sal_adapters.common.textfiles import atomic_write_text

__all__ = [
    "DEFAULT_RGBD_BASELINE_M",
    "VIEWER_KEYS",
    "Matrix",
    "OrbParameters",
    "format_value",
    "settings_entries",
    "settings_yaml",
    "write_settings",
]

#: Virtual baseline (m) written as ``Stereo.b`` for RGB-D when the camera has none; with
#: ``Stereo.ThDepth`` 40 it puts the close/far point threshold at 3.2 m (upstream TUM files:
#: bf 40 / fx 517 = 0.077 m).
DEFAULT_RGBD_BASELINE_M = 0.08

#: The ten ``Viewer.*`` keys ORB-SLAM3 requires, with upstream's values (all reals).
VIEWER_KEYS: tuple[tuple[str, float], ...] = (
    ("Viewer.KeyFrameSize", 0.05),
    ("Viewer.KeyFrameLineWidth", 1.0),
    ("Viewer.GraphLineWidth", 0.9),
    ("Viewer.PointSize", 2.0),
    ("Viewer.CameraSize", 0.08),
    ("Viewer.CameraLineWidth", 3.0),
    ("Viewer.ViewpointX", 0.0),
    ("Viewer.ViewpointY", -0.7),
    ("Viewer.ViewpointZ", -1.8),
    ("Viewer.ViewpointF", 500.0),
)


@dataclass(frozen=True)
class Matrix:
    """A float matrix written as ``!!opencv-matrix`` (``dt: f``)."""

    values: np.ndarray

    def __post_init__(self) -> None:
        a = np.asarray(self.values, dtype=np.float64)
        if a.ndim != 2:
            raise ValueError(f"an opencv-matrix needs a 2-D array, got shape {a.shape}")
        object.__setattr__(self, "values", a)


Value = bool | int | float | str | Matrix


@dataclass(frozen=True)
class OrbParameters:
    """ORB extractor and depth parameters of a settings file.

    Attributes:
        features: ``ORBextractor.nFeatures``, features per image.
        scale_factor: ``ORBextractor.scaleFactor``, scale between pyramid levels (> 1).
        levels: ``ORBextractor.nLevels``, pyramid levels.
        fast_threshold: ``ORBextractor.iniThFAST``, FAST threshold (grey levels).
        min_fast_threshold: ``ORBextractor.minThFAST``, FAST threshold used where the first
            finds too few corners (grey levels).
        th_depth: ``Stereo.ThDepth``: points closer than ``th_depth`` baselines are "close"
            (stereo and RGB-D only).
    """

    features: int = 2000
    scale_factor: float = 1.2
    levels: int = 8
    fast_threshold: int = 20
    min_fast_threshold: int = 7
    th_depth: float = 40.0


def format_value(value: Value) -> str:
    """The YAML text of one value: ints without a point, reals always with a ``.`` or an
    exponent, strings double-quoted, ``Matrix`` as an ``!!opencv-matrix`` block.

    Raises ``ValueError`` for a non-finite real (ORB-SLAM3 cannot read ``.nan``).
    """
    if isinstance(value, Matrix):
        rows, cols = value.values.shape
        data = ", ".join(_real(v) for v in value.values.ravel())
        return f"!!opencv-matrix\n  rows: {rows}\n  cols: {cols}\n  dt: f\n  data: [{data}]"
    if isinstance(value, (bool, np.bool_)):
        return "1" if value else "0"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return _real(float(value))
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    raise TypeError(f"cannot write {type(value).__name__} {value!r} in an ORB-SLAM3 settings file")


def _real(value: float) -> str:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"ORB-SLAM3 settings cannot hold the non-finite real {value!r}")
    text = repr(value)  # shortest round-trip text: '500.0', '1.76187114e-05', '1e+16'
    if not any(c in text for c in ".eE"):
        text += ".0"
    return text


def _camera_block(prefix: str, camera: Camera) -> list[tuple[str, Value]]:
    d = [float(v) for v in camera.distortion]
    if len(d) not in (0, 4, 5):
        raise ValueError(f"{prefix}: ORB-SLAM3 PinHole takes 4 or 5 distortion coefficients (k1 k2 p1 p2 [k3]), got {len(d)}")
    k = (d + [0.0] * 4)[:4]
    entries: list[tuple[str, Value]] = [
        (f"{prefix}.fx", float(camera.fx)),
        (f"{prefix}.fy", float(camera.fy)),
        (f"{prefix}.cx", float(camera.cx)),
        (f"{prefix}.cy", float(camera.cy)),
        (f"{prefix}.k1", k[0]),
        (f"{prefix}.k2", k[1]),
        (f"{prefix}.p1", k[2]),
        (f"{prefix}.p2", k[3]),
    ]
    if len(d) == 5:
        entries.append((f"{prefix}.k3", d[4]))
    return entries


def settings_entries(camera: Camera, mode: str, fps: float, params: OrbParameters | None = None) -> list[tuple[str, Value]]:
    """The ``(key, value)`` pairs of the settings file for ``camera`` in ``mode``
    (``mono``, ``stereo`` or ``rgbd``) at ``fps`` (Hz); see the module text."""
    params = params or OrbParameters()
    if mode not in ("mono", "stereo", "rgbd"):
        raise ValueError(f"mode must be mono, stereo or rgbd, got {mode!r}")
    if not fps > 0:
        raise ValueError(f"fps must be > 0 Hz, got {fps!r}")
    entries: list[tuple[str, Value]] = [("File.version", "1.0"), ("Camera.type", "PinHole")]
    entries += _camera_block("Camera1", camera)
    if mode == "stereo":
        T = camera.T_lr
        if T is None:
            raise ValueError("stereo settings need the camera's T_lr (pose of the right camera in the left one)")
        right_in_left = Matrix(T)
        entries += _camera_block("Camera2", camera.right or camera)
    entries += [
        ("Camera.width", int(camera.width)),
        ("Camera.height", int(camera.height)),
        ("Camera.fps", max(1, int(round(float(fps))))),
        ("Camera.RGB", 1),
    ]
    if mode == "stereo":
        entries += [("Stereo.ThDepth", float(params.th_depth)), ("Stereo.T_c1_c2", right_in_left)]
    elif mode == "rgbd":
        baseline = camera.baseline_m if camera.baseline_m else DEFAULT_RGBD_BASELINE_M
        entries += [
            ("Stereo.ThDepth", float(params.th_depth)),
            ("Stereo.b", float(baseline)),
            ("RGBD.DepthMapFactor", 1.0),
        ]
    entries += [
        ("ORBextractor.nFeatures", int(params.features)),
        ("ORBextractor.scaleFactor", float(params.scale_factor)),
        ("ORBextractor.nLevels", int(params.levels)),
        ("ORBextractor.iniThFAST", int(params.fast_threshold)),
        ("ORBextractor.minThFAST", int(params.min_fast_threshold)),
    ]
    entries += list(VIEWER_KEYS)
    return entries


def _render(entries: Iterable[tuple[str, Value]]) -> str:
    return "%YAML:1.0\n" + "".join(f"{key}: {format_value(value)}\n" for key, value in entries)


def settings_yaml(camera: Camera, mode: str, fps: float, params: OrbParameters | None = None) -> str:
    """The settings file text (``%YAML:1.0`` header first)."""
    return _render(settings_entries(camera, mode, fps, params))


def write_settings(path: str | Path, camera: Camera, mode: str, fps: float, params: OrbParameters | None = None) -> Path:
    """Write the settings file to ``path`` (atomically) and return the path."""
    path = Path(path)
    atomic_write_text(path, settings_yaml(camera, mode, fps, params))
    return path
