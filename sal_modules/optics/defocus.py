"""``defocus``: a thin lens focused at the wrong distance, depth-dependent disk blur.

Mathematical formulation
------------------------
A thin lens of focal length f (mm) at f-number N focused at distance S images a point at depth
d as a disk (circle of confusion) of diameter, on the sensor::

    c = f^2 / (N (S - f)) * |d - S| / d                    (mm; S, d in mm)

and in pixels c / p for a pixel pitch p (``pixel_pitch_um``). The focal length defaults to
fx p (the camera's focal length in pixels times the pitch; KITTI's cameras: 4.65 um). Invalid
depth (0, e.g. sky) counts as infinitely far: c = f^2 / (N (S - f)). The blur radius is
r = c / (2 p), capped at ``MAX_RADIUS_PX``.

Rendering (layered depth of field): the radii are quantised to the levels rho = 0, 1, 2, 4, ...,
64 px. A pixel of radius r between rho_j and rho_{j+1} spreads its light over both disks with
weights that keep its blur variance (a disk of radius r has variance r^2 / 4 per axis)::

    t = (r^2 - rho_j^2) / (rho_{j+1}^2 - rho_j^2):    PSF = (1 - t) disk(rho_j) + t disk(rho_{j+1})

The pixels of one such slab (one j, one side of the focus plane) add up; slabs are composited
back to front (the far side from the largest blur down, then the near side up) as premultiplied
colour C and coverage A: ``acc = acc (1 - A) + C``, normalised by the accumulated coverage at
the end. So a blurred foreground spreads over the background, as through a real lens. Disks of
radius rho >= 4 px are applied at 1/s resolution (s = rho / 2) with the radius
sqrt(rho^2 / s^2 - 1) that makes up for the resampling, so every level costs about the same.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import cv2
import numpy as np

from sal_modules.base import Perturbation
from sal_modules.context import ModuleContext
from sal_modules.errors import ModuleError
from sal_modules.params import Param
from sal_modules.work_buffers import scratch

__all__ = ["Defocus", "circle_of_confusion_px", "disk_kernel", "render_layers"]

#: Blur levels (disk radius, px); radii in between are split between two levels.
LEVELS = (0.0, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0)

#: Largest blur radius rendered (px).
MAX_RADIUS_PX = LEVELS[-1]

#: Index of the largest level.
TOP = len(LEVELS) - 1


def circle_of_confusion_px(depth_m: np.ndarray, f_number: float, focus_m: float, focal_mm: float, pitch_um: float) -> np.ndarray:
    """Circle-of-confusion diameter (px) of points at ``depth_m`` (0 or non-finite = infinity)."""
    s_mm = 1000.0 * focus_m
    at_infinity_px = focal_mm**2 / (f_number * (s_mm - focal_mm)) / (pitch_um / 1000.0)
    depth = np.asarray(depth_m, np.float32)
    inverse = np.divide(np.float32(1.0), depth, out=np.zeros_like(depth), where=depth > 0)  # 1/d (1/m), 0 = infinity
    np.multiply(inverse, np.float32(-focus_m), out=inverse)
    np.add(inverse, np.float32(1.0), out=inverse)
    return np.multiply(np.abs(inverse, out=inverse), np.float32(at_infinity_px), out=inverse)


@lru_cache(maxsize=32)
def disk_kernel(radius: float) -> np.ndarray:
    """Anti-aliased disk of ``radius`` px, normalised to sum 1 (float32)."""
    half = int(np.ceil(radius))
    y, x = np.mgrid[-half : half + 1, -half : half + 1]
    kernel = np.clip(radius + 0.5 - np.hypot(x, y), 0.0, 1.0).astype(np.float32)
    return kernel / kernel.sum()


def _blur(layer: np.ndarray, radius: float) -> np.ndarray:
    """``layer`` (HxW float32) convolved with a disk of ``radius`` px (pyramid for big ones)."""
    if radius <= 2.0:
        return cv2.filter2D(layer, -1, disk_kernel(radius), borderType=cv2.BORDER_REFLECT)
    factor = int(radius // 2)  # the levels are powers of two: an integer reduction
    height, width = layer.shape[:2]
    small_h, small_w = -(-height // factor), -(-width // factor)
    padded = cv2.copyMakeBorder(layer, 0, small_h * factor - height, 0, small_w * factor - width, cv2.BORDER_REFLECT)
    small = cv2.resize(padded, (small_w, small_h), interpolation=cv2.INTER_AREA)  # exact box means (OpenCV's fast path)
    small = cv2.filter2D(small, -1, disk_kernel(float(np.sqrt((radius / factor) ** 2 - 1.0))), borderType=cv2.BORDER_REFLECT)
    return cv2.resize(small, (small_w * factor, small_h * factor), interpolation=cv2.INTER_LINEAR)[:height, :width]


class Defocus(Perturbation):
    """Thin-lens defocus blur from depth: circle of confusion, layered disk blur."""

    name = "defocus"
    version = 2
    summary = "Lens focused at the wrong distance: thin-lens circle of confusion from depth, layered disk blur"
    needs_depth = True

    f_number = Param(
        1.4,
        min=0.95,
        max=32.0,
        searchable=True,
        worse="lower",
        doc="aperture f-number N (lower = wider aperture = more blur)",
    )
    focus_distance_m = Param(0.5, unit="m", min=0.05, max=100_000.0, doc="distance the lens is focused at")
    focal_length_mm = Param(None, unit="mm", min=0.1, max=2000.0, optional=True, doc="focal length (default: fx times pixel_pitch_um)")
    pixel_pitch_um = Param(4.65, unit="um", min=0.5, max=50.0, doc="sensor pixel pitch")

    def check_params(self, params: dict[str, Any]) -> None:
        focal = params["focal_length_mm"]
        if focal is not None and 1000.0 * params["focus_distance_m"] <= focal:
            raise self.param_error(f"focus_distance_m = {params['focus_distance_m']} m must exceed the focal length ({focal} mm)")

    def setup(self, context: ModuleContext) -> None:
        super().setup(context)
        for stream in ("left", "right"):
            self.focal_mm(stream)  # fail early on a focus distance inside the focal length

    def focal_mm(self, stream: str) -> float:
        """Focal length (mm) of ``stream``'s lens: the parameter, or fx times the pixel pitch."""
        if self.focal_length_mm is not None:
            return float(self.focal_length_mm)
        focal = self.ready_context().camera_for(stream).fx * self.pixel_pitch_um / 1000.0
        if 1000.0 * self.focus_distance_m <= focal:
            raise self.param_error(f"focus_distance_m = {self.focus_distance_m} m must exceed the focal length ({focal:.2f} mm)")
        return focal

    def blur_radius_px(self, depth: np.ndarray, stream: str = "left") -> np.ndarray:
        """Blur disk radius (px) per pixel: half the circle of confusion, capped."""
        coc = circle_of_confusion_px(depth, self.f_number, self.focus_distance_m, self.focal_mm(stream), self.pixel_pitch_um)
        return np.minimum(np.multiply(coc, np.float32(0.5), out=coc), np.float32(MAX_RADIUS_PX), out=coc)

    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray:
        if depth is None:
            raise ModuleError("defocus needs the depth of the frame; run it through sal_modules.perturb()")
        radius = self.blur_radius_px(depth, stream)
        if float(radius.max()) < 0.05:
            return image.copy()
        far = (depth >= self.focus_distance_m) | ~(depth > 0)  # invalid depth (sky) is far away
        return render_layers(image, radius, far)


def render_layers(image: np.ndarray, radius: np.ndarray, far: np.ndarray) -> np.ndarray:
    """``image`` (HxWx3 uint8) blurred by a disk of ``radius`` (px) per pixel.

    Slab j holds the pixels with LEVELS[j] <= radius < LEVELS[j + 1] on one side of the focus
    plane; its pixels spread their light additively over the two disks (no self-occlusion), and
    slabs are composited back to front: the far side (``far`` True) from the largest blur down,
    then the near side up.
    """
    lower, upper = _split_levels(radius)
    top = int(lower.max())
    height, width = radius.shape
    colour = scratch("defocus.colour", (4, height, width))  # planar RGBA
    for channel in range(3):
        np.copyto(colour[channel], image[..., channel], casting="unsafe")
    colour[3] = 1.0
    acc = scratch("defocus.acc", (4, height, width))
    acc.fill(0.0)
    near = ~far
    order = [(j, far) for j in range(top, -1, -1)] + ([(j, near) for j in range(top + 1)] if near.any() else [])
    for slab, side in order:
        members = (lower == slab) & side
        if members.any():
            _composite_slab(acc, colour, members, upper, slab)
    coverage = np.maximum(acc[3], 1e-6, out=acc[3])
    return cv2.merge([cv2.convertScaleAbs(cv2.divide(plane, coverage, dst=plane)) for plane in acc[:3]])


def _split_levels(radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel: the level j just below its radius (uint8) and the share t of level j + 1,
    linear in the radius squared, t = (r^2 - rho_j^2) / (rho_{j+1}^2 - rho_j^2), so that the
    mixture of the two disks has the blur variance r^2 / 4 of a disk of radius r."""
    lower = np.zeros(radius.shape, np.uint8)
    for level in LEVELS[1:-1]:
        lower += radius >= level
    base, span = _LEVEL_TABLES
    table = scratch("defocus.table", radius.shape)
    share = cv2.multiply(radius, radius, dst=scratch("defocus.upper", radius.shape))
    cv2.subtract(share, cv2.LUT(lower, base, dst=table), dst=share)
    cv2.divide(share, cv2.LUT(lower, span, dst=table), dst=share)
    return lower, np.clip(share, 0.0, 1.0, out=share)


def _level_tables() -> tuple[np.ndarray, np.ndarray]:
    """256-entry tables (cv2.LUT) of rho_j^2 and rho_{j+1}^2 - rho_j^2 by level j."""
    rho2 = np.square(np.asarray(LEVELS, np.float32))
    base, span = np.zeros(256, np.float32), np.ones(256, np.float32)
    base[: TOP + 1], span[:TOP] = rho2, rho2[1:] - rho2[:-1]
    return base, span


_LEVEL_TABLES = _level_tables()


def _composite_slab(acc: np.ndarray, colour: np.ndarray, members: np.ndarray, upper: np.ndarray, slab: int) -> None:
    """``acc = acc (1 - A) + C`` (planar 4xHxW): C and A are the slab's colour and coverage, its
    pixels' share ``1 - upper`` blurred by disk LEVELS[slab] plus ``upper`` by LEVELS[slab + 1];
    done within the slab's bounding box plus the blur reach."""
    rows = np.flatnonzero(members.any(axis=1))
    cols = np.flatnonzero(members.any(axis=0))
    reach = int(np.ceil(2 * LEVELS[slab + 1])) + 2
    height, width = members.shape
    y0, y1 = max(rows[0] - reach, 0), min(rows[-1] + 1 + reach, height)
    x0, x1 = max(cols[0] - reach, 0), min(cols[-1] + 1 + reach, width)
    box = (slice(y0, y1), slice(x0, x1))
    box_shape = (y1 - y0, x1 - x0)
    # work arrays of the full frame, used on the box: one allocation per frame size, not per slab
    share = scratch("defocus.share", members.shape)[: box_shape[0], : box_shape[1]]
    remainder = scratch("defocus.remainder", members.shape)[: box_shape[0], : box_shape[1]]
    layer = scratch("defocus.layer", (4, height, width))[:, : box_shape[0], : box_shape[1]]
    rest = scratch("defocus.rest", (4, height, width))[:, : box_shape[0], : box_shape[1]]
    np.multiply(upper[box], members[box], out=share)
    np.subtract(members[box], share, out=remainder)
    np.multiply(colour[(slice(None), *box)], share, out=layer)
    for plane in layer:
        plane[...] = _blur(plane, LEVELS[slab + 1])
    np.multiply(colour[(slice(None), *box)], remainder, out=rest)
    if slab > 0:
        for plane in rest:
            plane[...] = _blur(plane, LEVELS[slab])
    layer += rest
    window = acc[(slice(None), *box)]
    window *= np.subtract(1.0, layer[3], out=remainder)
    window += layer
