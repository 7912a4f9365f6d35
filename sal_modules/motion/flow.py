"""Shared helpers of the motion modules: pixel grids, warps, clean neighbour frames, flow.

Mathematical formulation
------------------------
Warping. ``warp(image, F, s)`` samples ``image`` at ``x + s F(x)`` (px) for a displacement
field ``F`` and a scale ``s`` (a number, or one per row) with bilinear interpolation and
replicated borders: a backward warp, one ``cv2.remap``.

Dense optical flow. ``F_{a->b}(x)`` (px) is the displacement that carries frame a onto frame b,
``I_a(x) ~ I_b(x + F_{a->b}(x))``, estimated by DIS (``cv2.DISOpticalFlow``, ultrafast preset) on
the grey images of the clean frames.

Reprojection flow. With z-depth ``Z(x)`` (m) of frame a, intrinsics ``K`` and the rigid motion
``M = [R | t]`` that maps camera-a coordinates to camera-b coordinates, the point seen at
``x`` is ``X_b ~ R K^-1 (x, 1) + t / Z``; projecting gives ``x_b = K X_b / X_b,z`` and
``F_{a->b} = x_b - x``. Pixels without depth (0, sky) are at infinity and follow the rotation
alone (``t / Z = 0``); points that end behind camera b get no flow.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from functools import lru_cache
from threading import Lock

import cv2
import numpy as np

from sal_adapters.camera import Camera
from sal_adapters.sequence import Frame, Sequence

__all__ = [
    "CleanFrames",
    "centred_grid",
    "dense_flow",
    "pixel_grid",
    "remap",
    "reprojection_flow",
    "warp",
]


@lru_cache(maxsize=8)
def pixel_grid(height: int, width: int) -> np.ndarray:
    """Read-only float32 HxWx2 pixel coordinates ``(x, y)`` of an ``height x width`` image."""
    xs, ys = np.meshgrid(np.arange(width, dtype=np.float32), np.arange(height, dtype=np.float32))
    grid = np.stack([xs, ys], axis=-1)
    grid.flags.writeable = False
    return grid


@lru_cache(maxsize=8)
def centred_grid(height: int, width: int, cx: float, cy: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read-only float32 ``(x - cx, y - cy, |(x - cx, y - cy)|)`` of an ``height x width`` image."""
    grid = pixel_grid(height, width)
    dx, dy = grid[..., 0] - np.float32(cx), grid[..., 1] - np.float32(cy)
    radius = np.sqrt(dx * dx + dy * dy)
    for array in (dx, dy, radius):
        array.flags.writeable = False
    return dx, dy, radius


def warp(image: np.ndarray, flow: np.ndarray, scale: float | np.ndarray) -> np.ndarray:
    """RGB ``image`` sampled at ``x + scale * flow(x)`` (bilinear, replicated border); same
    dtype. ``flow`` is HxWx2 (px); ``scale`` a number or an array that broadcasts to HxWx1
    (e.g. one value per row, Hx1x1)."""
    coordinates = np.multiply(flow, scale, dtype=np.float32)
    coordinates += pixel_grid(*image.shape[:2])
    return remap(image, coordinates)


def remap(image: np.ndarray, coordinates: np.ndarray) -> np.ndarray:
    """``image`` (HxW, HxWx3 or HxWx4) sampled at ``coordinates`` (HxWx2 float32 ``(x, y)``),
    bilinear, replicated border. Three channels go through four, where OpenCV's remap is
    about 2.5x faster."""
    if image.ndim == 3 and image.shape[2] == 3:
        padded = cv2.cvtColor(image, cv2.COLOR_RGB2RGBA)
        return cv2.cvtColor(remap(padded, coordinates), cv2.COLOR_RGBA2RGB)
    # one (x, y) map and no second one: OpenCV takes it, its stubs want two maps
    return cv2.remap(image, coordinates, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)  # type: ignore[call-overload]


def dense_flow(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """DIS optical flow ``F`` (HxWx2 float32 px) with ``source(x) ~ target(x + F(x))``;
    both are HxW uint8 grey images."""
    dis = cv2.DISOpticalFlow.create(cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST)
    return dis.calc(source, target, None)  # type: ignore[call-overload]  # no initial flow: OpenCV takes None, its stubs do not


def reprojection_flow(depth: np.ndarray, camera: Camera, motion: np.ndarray) -> np.ndarray:
    """Flow (HxWx2 float32 px) of a static scene with z-depth ``depth`` (m, 0 = infinitely
    far) when the camera moves by ``motion`` (4x4, camera-a to camera-b coordinates)."""
    h, w = depth.shape
    grid = pixel_grid(h, w)
    xs, ys = grid[..., 0], grid[..., 1]
    rx = (xs - camera.cx) / camera.fx
    ry = (ys - camera.cy) / camera.fy
    inverse = np.divide(1.0, depth, out=np.zeros_like(depth, dtype=np.float32), where=depth > 0)
    R, t = motion[:3, :3].astype(np.float32), motion[:3, 3].astype(np.float32)
    x, y, z = (R[i, 0] * rx + R[i, 1] * ry + R[i, 2] + t[i] * inverse for i in range(3))
    ahead = z > 1e-6
    z = np.where(ahead, z, 1.0)
    flow = np.empty((h, w, 2), np.float32)
    flow[..., 0] = np.where(ahead, camera.fx * x / z + camera.cx - xs, 0.0)
    flow[..., 1] = np.where(ahead, camera.fy * y / z + camera.cy - ys, 0.0)
    return flow


class CleanFrames:
    """The clean frames of a sequence by position and stream, decoded once and kept in a
    small cache, and the dense optical flow between any two of them (cached too).

    Args:
        sequence: the clean sequence (``ModuleContext.sequence``).
        keep: how many decoded images (and as many flow fields) stay in memory.
    """

    def __init__(self, sequence: Sequence, keep: int = 16):
        self.sequence = sequence
        self.times = sequence.timestamps
        self._images: OrderedDict[tuple[int, str], np.ndarray] = OrderedDict()
        self._greys: OrderedDict[tuple[int, str], np.ndarray] = OrderedDict()
        self._flows: OrderedDict[tuple[int, int, str], np.ndarray] = OrderedDict()
        self._keep = keep
        self._lock = Lock()

    def __len__(self) -> int:
        return len(self.sequence)

    def image(self, position: int, stream: str) -> np.ndarray:
        """The clean HxWx3 uint8 image of frame ``position`` in ``stream`` (read-only)."""
        return self._cached(self._images, (position, stream), lambda: self._decode(position, stream))

    def flow(self, source: int, target: int, stream: str) -> np.ndarray:
        """Dense flow (read-only) from clean frame ``source`` to clean frame ``target``."""
        return self._cached(
            self._flows, (source, target, stream), lambda: dense_flow(self._grey(source, stream), self._grey(target, stream))
        )

    def _grey(self, position: int, stream: str) -> np.ndarray:
        return self._cached(self._greys, (position, stream), lambda: cv2.cvtColor(self.image(position, stream), cv2.COLOR_RGB2GRAY))

    def _decode(self, position: int, stream: str) -> np.ndarray:
        frame = Frame(self.sequence.records[position], self.sequence.camera)
        image = frame.image if stream == "left" else frame.right
        if image is None:
            raise ValueError(f"frame {frame.index} of {self.sequence.name!r} has no {stream} image")
        return image

    def _cached(self, cache: OrderedDict, key: tuple, compute: Callable[[], np.ndarray]) -> np.ndarray:
        """``cache[key]``, computed (outside the lock) and stored read-only when missing;
        the least recently used entries beyond ``keep`` are dropped."""
        with self._lock:
            if key in cache:
                cache.move_to_end(key)
                return cache[key]
        value = compute()
        value.flags.writeable = False
        with self._lock:
            cache[key] = value
            while len(cache) > self._keep:
                cache.popitem(last=False)
        return value
