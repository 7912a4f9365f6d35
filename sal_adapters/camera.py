"""Pinhole camera model with optional distortion and stereo extrinsics."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from numbers import Real
from typing import Any

import numpy as np

__all__ = ["MAX_FOCAL_PX", "MAX_FRAME_PIXELS", "MAX_FRAME_SIDE_PX", "Camera", "frame_size_problem"]

#: The largest frame pytest-sal reads: each side at most ``MAX_FRAME_SIDE_PX`` and at most
#: ``MAX_FRAME_PIXELS`` pixels in all (50 MP, 150 MB as RGB). A camera or an image file over it
#: is refused before any pixel is allocated (an image from its header).
MAX_FRAME_SIDE_PX = 32_768
MAX_FRAME_PIXELS = 50_000_000
#: The longest focal length a camera may have (px): a 10^6 px telescope.
MAX_FOCAL_PX = 1e6


def frame_size_problem(width: float, height: float) -> str | None:
    """Why ``width`` x ``height`` (px) cannot be a frame's size (not whole, not positive, over
    the limits above), or ``None`` when it can."""
    if not all(isinstance(v, Real) and 1 <= v <= MAX_FRAME_SIDE_PX and v == int(v) for v in (width, height)):
        return f"each side must be a whole number of pixels from 1 to {MAX_FRAME_SIDE_PX}, got {width!s:.20}x{height!s:.20} px"
    if width * height > MAX_FRAME_PIXELS:
        return f"{int(width)}x{int(height)} px is over the limit of {MAX_FRAME_PIXELS} pixels a frame"
    return None


@dataclass(frozen=True)
class Camera:
    """Intrinsics of the (left) camera in pixels, plus what a stereo or RGB-D sensor adds.

    Attributes:
        fx, fy: focal lengths (px). cx, cy: principal point (px).
        width, height: image size (px).
        distortion: OpenCV radial-tangential coefficients ``(k1, k2, p1, p2[, k3])``; empty = none.
        baseline_m: stereo baseline (m), the norm of the right camera's translation in the left
            camera frame; ``None`` for a single camera.
        depth_scale: raw depth units per metre in the dataset's depth images (TUM: 5000); ``None``
            when depth is stored in metres or absent.
        right: intrinsics of the right camera when a stereo pair is not rectified (EuRoC).
        T_left_right: pose of the right camera in the left camera frame, row-major 4x4
            (16 floats); ``None`` for a single camera.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    distortion: tuple[float, ...] = ()
    baseline_m: float | None = None
    depth_scale: float | None = None
    right: Camera | None = None
    T_left_right: tuple[float, ...] | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        for name in ("fx", "fy"):
            if not 0 < float(getattr(self, name)) <= MAX_FOCAL_PX:
                raise ValueError(f"camera {name} must be > 0 px and at most {MAX_FOCAL_PX:g} px, got {getattr(self, name)!r}")
        if not (np.isfinite(float(self.cx)) and np.isfinite(float(self.cy))):
            raise ValueError(f"camera principal point must be finite, got cx={self.cx!r} cy={self.cy!r} px")
        problem = frame_size_problem(self.width, self.height)
        if problem:
            raise ValueError(f"camera size: {problem}")
        if self.T_left_right is not None and len(self.T_left_right) != 16:
            raise ValueError("camera T_left_right must hold 16 floats (row-major 4x4)")

    @property
    def K(self) -> np.ndarray:
        """3x3 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def T_lr(self) -> np.ndarray | None:
        """Pose of the right camera in the left camera frame as a 4x4 array, or ``None``."""
        if self.T_left_right is not None:
            return np.asarray(self.T_left_right, dtype=np.float64).reshape(4, 4)
        if self.baseline_m is not None:
            T = np.eye(4)
            T[0, 3] = self.baseline_m
            return T
        return None

    def with_stereo(self, T_left_right: np.ndarray, right: Camera | None = None) -> Camera:
        """Copy with a right camera at ``T_left_right`` (4x4); the baseline is its translation norm."""
        T = np.asarray(T_left_right, dtype=np.float64).reshape(4, 4)
        return replace(
            self,
            baseline_m=float(np.linalg.norm(T[:3, 3])),
            T_left_right=tuple(float(v) for v in T.ravel()),
            right=right,
        )

    def summary(self) -> dict[str, Any]:
        """The figures ``sal dataset info`` prints: fx, fy, cx, cy, width, height, baseline_m."""
        return {
            "fx": float(self.fx),
            "fy": float(self.fy),
            "cx": float(self.cx),
            "cy": float(self.cy),
            "width": int(self.width),
            "height": int(self.height),
            "baseline_m": None if self.baseline_m is None else float(self.baseline_m),
        }

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary; ``Camera.from_dict`` restores it exactly."""
        data = asdict(self)
        data["distortion"] = list(self.distortion)
        data["right"] = None if self.right is None else self.right.to_dict()
        data["T_left_right"] = None if self.T_left_right is None else list(self.T_left_right)
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Camera:
        """Inverse of ``to_dict``."""
        data = dict(data)
        data["distortion"] = tuple(data.get("distortion") or ())
        if data.get("right") is not None:
            data["right"] = cls.from_dict(data["right"])
        if data.get("T_left_right") is not None:
            data["T_left_right"] = tuple(float(v) for v in data["T_left_right"])
        return cls(**data)
