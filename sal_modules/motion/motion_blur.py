"""``motion_blur``: blur of a camera driving forward during the exposure, from metric depth.

Mathematical formulation
------------------------
During the exposure ``T`` (s) the camera moves forward along its optical axis by
``dz = v / 3.6 * T`` (m) for a speed ``v`` (km/h); rotation and lateral motion are ignored.
A static point at z-depth ``Z`` (m) seen at pixel ``p`` when the exposure starts (the frame
time) is seen at ``c + (p - c) Z / (Z - s dz)`` after the fraction ``s`` of it, ``c = (cx, cy)``
being the principal point, so its streak runs over ``(p - c) dz / (Z - dz)`` (px).

The pixel ``x`` integrates with uniform (box) weights over the exposure what it sees, the
clean image at ``c + (x - c) (1 - s dz / Z)``, approximating the depth of those points by the
depth ``Z(x)`` at ``x``. The integral is computed by recursive doubling with
``n = ceil(log2(L))`` levels, ``L`` the longest streak (px), so ``2^n`` samples at most one
pixel apart cost ``n + 1`` bilinear remaps: level ``k`` averages the image with itself
sampled at ``c + (x - c) q^(1/2^k)``, ``q = 1 - dz / Z``. Scalings about ``c`` compose by
multiplying, so the samples sit at ``c + (x - c) q^s`` for ``s = (j + 1/2) / 2^n``: on a plane
of constant depth the streak of a point has exactly the length ``|p - c| dz / (Z - dz)``,
with samples uniform in ``log`` of the distance to ``c`` (for small ``dz / Z`` uniform in time).

Pixels without depth (0, sky) do not move. Points closer than ``dz + 0.1 m`` would be reached
by the camera; they get the blur of a point at that distance (the longest, never frozen).
"""

from __future__ import annotations

import math
import threading

import cv2
import numpy as np

from sal_modules.base import Perturbation
from sal_modules.errors import ModuleError
from sal_modules.motion.flow import centred_grid
from sal_modules.params import Param

__all__ = ["MotionBlur"]

#: Points nearer than dz + NEAR_MARGIN_M (m) are blurred as if at that distance.
NEAR_MARGIN_M = 0.1
#: At most 2^MAX_LEVELS samples per streak (1024: one per pixel up to 1024 px streaks).
MAX_LEVELS = 10


class MotionBlur(Perturbation):
    """Depth-aware blur of forward motion at ``speed_kmh`` during ``exposure_ms``."""

    name = "motion_blur"
    version = 1
    summary = "Depth-aware blur of a camera moving forward during the exposure (box-integrated streaks)"
    needs_depth = True

    speed_kmh = Param(50.0, unit="km/h", min=0.0, max=400.0, searchable=True, worse="higher", doc="forward speed of the camera")
    exposure_ms = Param(20.0, unit="ms", min=0.01, max=1000.0, doc="exposure time; the frame time is its start")

    @property
    def travel_m(self) -> float:
        """Forward distance dz (m) the camera covers during the exposure."""
        return self.speed_kmh / 3.6 * self.exposure_ms / 1000.0

    def unchanged_reason(self) -> str | None:
        return "speed_kmh = 0 km/h does not move the camera during the exposure" if self.speed_kmh == 0.0 else None

    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray:
        camera = self.ready_context().camera_for(stream)
        dz = self.travel_m
        if dz <= 0.0:
            return image.copy()
        if depth is None:
            raise ModuleError(f"{self.name} needs the depth of frame {index} ({stream}); sal_modules.perturb() passes it")
        if depth.shape != image.shape[:2]:
            raise ModuleError(
                f"{self.name}: depth of frame {index} ({stream}) is {depth.shape[1]}x{depth.shape[0]} px, the image {image.shape[1]}x{image.shape[0]} px"
            )
        h, w = image.shape[:2]
        dx, dy, radius = centred_grid(h, w, camera.cx, camera.cy)
        ratio = _end_ratio(depth, dz)
        longest = float(np.max(radius * -np.log(ratio)))  # px, in the log-spaced sample metric
        if longest <= 0.0:
            return image.copy()
        levels = min(max(1, math.ceil(math.log2(longest))), MAX_LEVELS)
        work = _workspace(h, w)
        # q^(1/2^(levels+1)) (the half-sample offset that centres each sample in its slot),
        # then squared back up: q^(1/2^levels), ..., q^(1/2) (the scaling of each level)
        for _ in range(levels + 1):
            np.sqrt(ratio, out=ratio)
        cv2.cvtColor(image, cv2.COLOR_RGB2RGBA, dst=work.rgba)
        np.copyto(work.shifted, work.rgba)
        centre = (np.float32(camera.cx), np.float32(camera.cy))
        _scaled(work.shifted, dx, dy, centre, ratio, work, out=work.planes)
        planes = work.planes
        for _ in range(levels):
            np.multiply(ratio, ratio, out=ratio)
            shifted = _scaled(planes, dx, dy, centre, ratio, work, out=work.shifted)
            cv2.addWeighted(planes, 0.5, shifted, 0.5, 0.0, dst=planes)
        return cv2.cvtColor(cv2.convertScaleAbs(planes), cv2.COLOR_RGBA2RGB)


def _end_ratio(depth: np.ndarray, dz: float) -> np.ndarray:
    """q = 1 - dz / max(Z, dz + margin) (1 where there is no depth): the scaling about the
    principal point of what a pixel sees at the end of the exposure."""
    travel = np.float32(dz) / np.maximum(depth, np.float32(dz + NEAR_MARGIN_M))
    np.putmask(travel, depth <= 0, np.float32(0.0))
    return np.subtract(np.float32(1.0), travel, dtype=np.float32)


class _Workspace:
    """Preallocated per-size arrays: fresh 7 MB arrays per level cost page faults (~40 %)."""

    def __init__(self, height: int, width: int):
        self.rgba = np.empty((height, width, 4), np.uint8)
        self.planes = np.empty((height, width, 4), np.float32)
        self.shifted = np.empty((height, width, 4), np.float32)
        self.map_x = np.empty((height, width), np.float32)
        self.map_y = np.empty((height, width), np.float32)


_WORKSPACES = threading.local()


def _workspace(height: int, width: int) -> _Workspace:
    """This thread's workspace for ``height x width`` images (the last size only)."""
    work = getattr(_WORKSPACES, "work", None)
    if work is None or work.planes.shape[:2] != (height, width):
        work = _WORKSPACES.work = _Workspace(height, width)
    return work


def _scaled(
    planes: np.ndarray,
    dx: np.ndarray,
    dy: np.ndarray,
    centre: tuple[np.float32, np.float32],
    ratio: np.ndarray,
    work: _Workspace,
    out: np.ndarray,
) -> np.ndarray:
    """``planes`` sampled at ``c + (x - c) * ratio`` into ``out`` (bilinear, replicated border)."""
    np.multiply(dx, ratio, out=work.map_x)
    np.add(work.map_x, centre[0], out=work.map_x)
    np.multiply(dy, ratio, out=work.map_y)
    np.add(work.map_y, centre[1], out=work.map_y)
    return cv2.remap(planes, work.map_x, work.map_y, cv2.INTER_LINEAR, dst=out, borderMode=cv2.BORDER_REPLICATE)
