"""Stereo depth: OpenCV semi-global matching on the (rectified) pair, converted to metres.

The pair is rectified as ``sal_modules.depth.stereo_rig`` says; the gaps of its disparity and
of the depth are filled as ``sal_modules.depth.stereo_fill`` says.

Mathematical formulation
------------------------
Matching. Semi-global matching (``cv2.StereoSGBM``, grey images) with ``numDisparities`` the
smallest multiple of 16 above ``d_max = f B / min_depth_m`` (px; by default an eighth of the
rectified width), block size ``b`` (odd px, 5 px at 1241x376, scaled with the image's linear
size), smoothness penalties ``P1 = 8 b^2`` and ``P2 = 32 b^2``, a uniqueness margin (%), a
left-right consistency check of 1 px and a speckle filter whose window grows with the image
area. Both images are padded on the left by ``numDisparities`` columns, so the left image's
first columns are matched over the disparities that stay inside the right image. A disparity
is kept only where the block around the pixel and around its match ``u - d`` lies inside the
raw image and is textured (local standard deviation >= ``min_texture`` grey levels). The
right camera's depth is matched the same way on the horizontally flipped, swapped pair.

Depth. ``Z = f B / d`` (m) for disparity ``d`` (px) >= 1 px (nearer than ``f B``); smaller or
missing disparities are 0 (unknown). For a pair that had to be rectified, each raw pixel ``p``
looks up its rectified position ``q = K_rect R1 undistort(p)`` (nearest sample, so depth never
blends across object edges) and its depth along the raw camera's axis is
``Z_raw = Z_rect(q) (R1^T K_rect^-1 q)_z``.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from sal_adapters.sequence import Sequence
from sal_modules.depth.base import DepthProvider
from sal_modules.depth.stereo_fill import MIN_DISPARITY_PX, fill_disparity, fill_unmeasurable
from sal_modules.depth.stereo_rig import StereoRig, geometry_problem, stereo_rig
from sal_modules.errors import ModuleError

__all__ = ["StereoDepth"]

#: SGBM modes by option name (``3way`` is the fastest, ``hh`` the full 8-path variant).
MODES = {
    "sgbm": cv2.StereoSGBM_MODE_SGBM,
    "3way": cv2.StereoSGBM_MODE_SGBM_3WAY,
    "hh": cv2.StereoSGBM_MODE_HH,
    "hh4": cv2.StereoSGBM_MODE_HH4,
}
#: Image area (px) the default block size and speckle window are tuned for (KITTI).
REFERENCE_AREA = 1241 * 376


class StereoDepth(DepthProvider):
    """Depth from the sequence's stereo pairs by semi-global matching.

    Args:
        min_depth_m: nearest depth to resolve (m); sets the disparity range ``f B / min_depth_m``.
            Default: a disparity range of one eighth of the rectified image width.
        block_size: matching block size (odd px); default 5 px at 1241x376, scaled with the
            image's linear size.
        mode: ``3way`` (default, fastest), ``sgbm`` (5 paths), ``hh`` (8 paths) or ``hh4``.
        uniqueness: the best match must beat the second best by this margin (%).
        speckle_window: largest disparity blob (px) removed as a speckle at 1241x376 (scaled
            with the image area); 0 turns the filter off.
        speckle_range: largest disparity step (px) inside one blob.
        min_texture: pixels whose matching block varies less than this (standard deviation,
            grey levels) get no depth from matching: sky, overexposed windows, blank walls
            (holes enclosed by depth on all sides are filled afterwards).
    """

    name = "stereo"
    #: Algorithm version: part of the cache key, bumped when the output changes.
    version = 2

    def __init__(
        self,
        *,
        min_depth_m: float | None = None,
        block_size: int | None = None,
        mode: str = "3way",
        uniqueness: int = 10,
        speckle_window: int = 100,
        speckle_range: int = 2,
        min_texture: float = 1.0,
    ):
        if min_depth_m is not None and not float(min_depth_m) > 0:
            raise ModuleError(f"stereo depth: min_depth_m must be > 0 m, got {min_depth_m!r}")
        if block_size is not None and (int(block_size) != block_size or block_size < 1 or block_size % 2 == 0):
            raise ModuleError(f"stereo depth: block_size must be an odd number of px >= 1, got {block_size!r}")
        if mode not in MODES:
            raise ModuleError(f"stereo depth: mode must be one of {', '.join(MODES)}, got {mode!r}")
        if not 0 <= uniqueness <= 100:
            raise ModuleError(f"stereo depth: uniqueness must be in 0..100 %, got {uniqueness!r}")
        if speckle_window < 0 or speckle_range < 0 or min_texture < 0:
            raise ModuleError("stereo depth: speckle_window, speckle_range and min_texture must be >= 0")
        self.min_depth_m = None if min_depth_m is None else float(min_depth_m)
        self.block_size = None if block_size is None else int(block_size)
        self.mode = mode
        self.uniqueness = int(uniqueness)
        self.speckle_window = int(speckle_window)
        self.speckle_range = int(speckle_range)
        self.min_texture = float(min_texture)

    def settings(self) -> dict[str, Any]:
        return {
            "version": self.version,
            "min_depth_m": self.min_depth_m,
            "block_size": self.block_size,
            "mode": self.mode,
            "uniqueness": self.uniqueness,
            "speckle_window": self.speckle_window,
            "speckle_range": self.speckle_range,
            "min_texture": self.min_texture,
        }

    def unavailable(self, sequence: Sequence) -> str | None:
        if sequence.sensor != "stereo":
            return f"sequence {sequence.name!r} is {sequence.sensor}, not a stereo pair (no right images)"
        return geometry_problem(sequence.camera)

    def num_disparities(self, rig: StereoRig) -> int:
        """Disparity search range (px, a multiple of 16) for ``rig``."""
        if self.min_depth_m is None:
            largest = rig.size[0] / 8
        else:
            largest = rig.focal * rig.baseline / self.min_depth_m
        return int(16 * max(1, np.ceil(largest / 16)))

    def block(self, rig: StereoRig) -> int:
        """Matching block size (odd px) for ``rig``: ``block_size`` or 5 px scaled with the image."""
        if self.block_size is not None:
            return self.block_size
        scale = np.sqrt(rig.size[0] * rig.size[1] / REFERENCE_AREA)
        return max(3, 2 * int(round(2.5 * scale - 0.5)) + 1)

    def matcher(self, rig: StereoRig) -> cv2.StereoSGBM:
        """The SGBM matcher with parameters scaled to the rectified image size."""
        scale = rig.size[0] * rig.size[1] / REFERENCE_AREA
        block = self.block(rig)
        return cv2.StereoSGBM.create(
            minDisparity=0,
            numDisparities=self.num_disparities(rig),
            blockSize=block,
            P1=8 * block * block,
            P2=32 * block * block,
            disp12MaxDiff=1,
            preFilterCap=63,
            uniquenessRatio=self.uniqueness,
            speckleWindowSize=int(round(self.speckle_window * scale)),
            speckleRange=self.speckle_range,
            mode=MODES[self.mode],
        )

    def compute(self, sequence: Sequence, position: int, stream: str) -> np.ndarray:
        reason = self.unavailable(sequence)
        if reason is not None:
            raise ModuleError(f"stereo depth: {reason}")
        frame = sequence[position]
        rig = stereo_rig(sequence.camera)
        grey = {"left": _grey(frame.image), "right": _grey(frame.right)}
        if not rig.rectified:
            grey = {s: cv2.remap(g, *rig.to_rectified[s], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT) for s, g in grey.items()}
        usable = {s: self.usable(g, rig.inside.get(s), rig) for s, g in grey.items()}
        margin = 2 * self.block(rig)
        inside = rig.inside or {s: np.ones(grey[s].shape, np.uint8) for s in grey}
        if stream == "right":  # the right view is the left view of the mirrored, swapped pair
            flip = {s: g[:, ::-1] for s, g in grey.items()}
            measurable, start = self.measurable(inside["right"][:, ::-1], inside["left"][:, ::-1], rig)
            disparity = _checked(self.disparity(flip["right"], flip["left"], rig), usable["right"][:, ::-1], usable["left"][:, ::-1])
            disparity = fill_disparity(disparity, margin, start)[:, ::-1]
            measurable = measurable[:, ::-1]
        else:
            measurable, start = self.measurable(inside["left"], inside["right"], rig)
            disparity = _checked(self.disparity(grey["left"], grey["right"], rig), usable["left"], usable["right"])
            disparity = fill_disparity(disparity, margin, start)
        valid = disparity >= MIN_DISPARITY_PX
        depth = np.where(valid, rig.focal * rig.baseline / np.where(valid, disparity, 1.0), 0.0).astype(np.float32)
        if not rig.rectified:
            x, y, factor = rig.to_raw[stream]
            depth = cv2.remap(depth, x, y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT) * factor
            measurable = cv2.remap(measurable.astype(np.uint8), x, y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0) > 0
        return fill_unmeasurable(depth, ~measurable, 2 * self.block(rig) + 1)

    def measurable(self, own: np.ndarray, other: np.ndarray, rig: StereoRig) -> tuple[np.ndarray, np.ndarray]:
        """Pixels of a rectified left view that geometry lets be matched, and per row the
        first column of the other view a match may land on.

        ``own`` and ``other`` (uint8 0/1) mark the rectified pixels showing raw content of this
        view and of the other one. A pixel is measurable when its matching block lies inside
        ``own`` and the other view's usable area (blocks inside ``other``) holds some column
        ``u - d`` of its row for a disparity ``1 <= d < numDisparities``.
        """
        kernel = np.ones((self.block(rig),) * 2, np.uint8)
        mine = cv2.erode(own, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0) > 0
        theirs = cv2.erode(other, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0) > 0
        h, w = theirs.shape
        # seen: some column of u - numDisparities + 1 .. u - 1 is usable in the other view
        count = np.zeros((h, w + 1), np.int32)
        np.cumsum(theirs, axis=1, out=count[:, 1:])
        u = np.arange(w)
        seen = count[:, u] - count[:, np.maximum(u - self.num_disparities(rig) + 1, 0)] > 0
        start = np.where(theirs.any(axis=1), np.argmax(theirs, axis=1), w)
        return mine & seen, start

    def usable(self, grey: np.ndarray, inside: np.ndarray | None, rig: StereoRig) -> np.ndarray:
        """Pixels whose matching block is textured (local standard deviation >= ``min_texture``
        grey levels) and lies wholly inside the raw image (``inside``, rectified pairs only)."""
        block = self.block(rig)
        g = grey.astype(np.float32)
        mean = cv2.blur(g, (block, block))
        usable = cv2.blur(g * g, (block, block)) - mean * mean >= self.min_texture**2
        if inside is not None:
            usable &= cv2.erode(inside, np.ones((block, block), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=0) > 0
        return usable

    def disparity(self, left: np.ndarray, right: np.ndarray, rig: StereoRig) -> np.ndarray:
        """Disparity (float32 px, 0 where unknown) of ``left`` against ``right`` (rectified grey)."""
        pad = self.num_disparities(rig)
        left = cv2.copyMakeBorder(np.ascontiguousarray(left), 0, 0, pad, 0, cv2.BORDER_CONSTANT, value=0)
        right = cv2.copyMakeBorder(np.ascontiguousarray(right), 0, 0, pad, 0, cv2.BORDER_CONSTANT, value=0)
        disparity = self.matcher(rig).compute(left, right)[:, pad:].astype(np.float32) / cv2.StereoMatcher_DISP_SCALE
        return np.where(disparity >= MIN_DISPARITY_PX, disparity, 0.0)


def _checked(disparity: np.ndarray, usable_left: np.ndarray, usable_right: np.ndarray) -> np.ndarray:
    """``disparity`` where the left pixel and its match ``u - d`` in the right image are usable
    (a match beyond the right image's border, in the padding, is unknown too)."""
    h, w = disparity.shape
    u_right = np.rint(np.arange(w, dtype=np.float32) - disparity).astype(np.int64)
    inside = u_right >= 0
    ok = usable_left & inside & usable_right[np.arange(h)[:, None], np.clip(u_right, 0, w - 1)]
    return np.where(ok, disparity, 0.0)


def _grey(rgb: np.ndarray | None) -> np.ndarray:
    """Luma of an HxWx3 RGB frame (uint8)."""
    if rgb is None:
        raise ModuleError("stereo depth: the frame has no right image")
    return cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
