"""Stereo depth: OpenCV semi-global matching on the (rectified) pair, converted to metres.

Mathematical formulation
------------------------
Rectification. A pair is already rectified when neither camera has lens distortion, both share
the intrinsics and the right camera sits at ``T_left_right = [I | (B, 0, 0)]`` (KITTI, the
synthetic world). Otherwise (EuRoC) ``cv2.stereoRectify`` gives the rotations ``R1``, ``R2``
that turn each camera into a common rectified orientation; the rectified focal length ``f``
is the left camera's (capped so the rectified image holds at most 2.25 times the pixels) and
the rectified image is just large enough to hold every raw pixel of both cameras, so no pixel
of the original image is lost.

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

Holes (``fill_disparity``, per row, vectorised). A strip at the left border narrower than the
first valid disparity ``dR`` (it matches outside the other image; counted from the first
column where the other image's rectified row holds raw content) takes ``dR``; a gap between
``dL`` and ``dR`` no wider than ``|dL - dR| + 2 b`` (an occlusion) takes ``min(dL, dR)``, the
background; a gap with valid depth on all four sides (at most a quarter of the image in each
direction) is interpolated linearly along the row (exact on planes).

Border (``fill_unmeasurable``, on the output depth, vectorised). Unknown depth means sky to
the weather modules, so unknown pixels the geometry explains take the depth of the nearest
dependable pixel (inside a ``2 b + 1`` square of depth, on a smooth surface, in a region of at
least 1 % of the image): pixels that cannot be matched whatever the scene (the block leaves
the rectified raw content, or the other camera sees nothing of the row within the disparity
range: the curved rectification border, rows only one camera sees) and unknown regions that
reach the left, right or bottom border but not the top (surface hidden from the other
camera by a near object, nearer than the disparity range, cut by the border). Sky,
overexposed windows and other unknown regions open to the top stay unknown, and so does the
unmeasurable border next to them; holes enclosed by depth stay unknown too.

Depth. ``Z = f B / d`` (m) for disparity ``d`` (px) >= 1 px (nearer than ``f B``); smaller or
missing disparities are 0 (unknown). For a pair that had to be rectified, each raw pixel ``p``
looks up its rectified position ``q = K_rect R1 undistort(p)`` (nearest sample, so depth never
blends across object edges) and its depth along the raw camera's axis is
``Z_raw = Z_rect(q) (R1^T K_rect^-1 q)_z``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import cv2
import numpy as np

from sal_adapters.camera import Camera
from sal_adapters.sequence import Sequence
from sal_modules.depth.base import DepthProvider
from sal_modules.errors import ModuleError

__all__ = ["StereoDepth", "StereoRig", "fill_disparity", "fill_unmeasurable", "stereo_rig"]

#: SGBM modes by option name (``3way`` is the fastest, ``hh`` the full 8-path variant).
MODES = {
    "sgbm": cv2.StereoSGBM_MODE_SGBM,
    "3way": cv2.StereoSGBM_MODE_SGBM_3WAY,
    "hh": cv2.StereoSGBM_MODE_HH,
    "hh4": cv2.StereoSGBM_MODE_HH4,
}
#: Image area (px) the default block size and speckle window are tuned for (KITTI).
REFERENCE_AREA = 1241 * 376
#: Largest rectified image, as a multiple of the raw image area.
MAX_RECTIFIED_AREA = 2.25
#: Smallest disparity (px) turned into depth.
MIN_DISPARITY_PX = 1.0
#: Largest relative depth step (log) between neighbours inside one surface when filling.
STEP = 0.1


@dataclass(frozen=True, eq=False)
class StereoRig:
    """Rectified geometry of a stereo camera pair.

    Attributes:
        focal: rectified focal length (px). baseline: stereo baseline (m).
        size: rectified image size ``(width, height)`` (px).
        to_rectified: per stream, the ``cv2.remap`` maps that resample a raw image into the
            rectified one; empty when the pair is already rectified.
        to_raw: per stream, the rectified position ``(x, y)`` of every raw pixel (rounded to
            the nearest pixel, float32 maps for ``cv2.remap``) and the factor that turns rectified depth into depth
            along the raw camera's axis; empty when the pair is already rectified.
        inside: per stream, the rectified pixels that show raw image content (uint8 0/1);
            empty when the pair is already rectified.
    """

    focal: float
    baseline: float
    size: tuple[int, int]
    to_rectified: dict[str, tuple[np.ndarray, np.ndarray]]
    to_raw: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]
    inside: dict[str, np.ndarray]

    @property
    def rectified(self) -> bool:
        """True when the raw images are already rectified."""
        return not self.to_rectified


def _is_rectified(camera: Camera) -> bool:
    """No distortion, equal intrinsics and a pure +x baseline."""
    right = camera.right or camera
    T = camera.T_lr
    same = np.allclose([camera.fx, camera.fy, camera.cx, camera.cy], [right.fx, right.fy, right.cx, right.cy], rtol=0, atol=1e-6)
    straight = np.allclose(T[:3, :3], np.eye(3), rtol=0, atol=1e-9) and np.allclose(T[1:3, 3], 0, rtol=0, atol=1e-9 * abs(T[0, 3]))
    return same and straight and not any(camera.distortion) and not any(right.distortion)


def _geometry_problem(camera: Camera) -> str | None:
    """Why ``camera`` is no usable horizontal stereo pair, or ``None``."""
    if camera.baseline_m is None or not camera.baseline_m > 0:
        return "the camera has no stereo baseline (the right camera's calibration is missing)"
    tx, ty, tz = camera.T_lr[:3, 3]
    if not (tx > 0 and abs(ty) < tx and abs(tz) < tx):
        return f"the right camera must sit to the right (+x) of the left camera; it sits at ({tx:.3f}, {ty:.3f}, {tz:.3f}) m"
    return None


@lru_cache(maxsize=8)
def stereo_rig(camera: Camera) -> StereoRig:
    """The rectified geometry of ``camera``'s stereo pair (computed once per camera)."""
    problem = _geometry_problem(camera)
    if problem is not None:
        raise ModuleError(f"stereo depth: {problem}")
    if _is_rectified(camera):
        return StereoRig(float(camera.fx), float(camera.baseline_m), (camera.width, camera.height), {}, {}, {})
    right = camera.right or camera
    T = camera.T_lr
    R = T[:3, :3].T  # left-camera coordinates -> right-camera coordinates
    t = (-R @ T[:3, 3]).reshape(3, 1)
    lenses = {"left": (camera.K, np.array(camera.distortion, np.float64)), "right": (right.K, np.array(right.distortion, np.float64))}
    R1, R2 = cv2.stereoRectify(*lenses["left"], *lenses["right"], (camera.width, camera.height), R, t, flags=cv2.CALIB_ZERO_DISPARITY)[:2]
    rotations = {"left": R1, "right": R2}
    cams = {"left": camera, "right": right}
    # every raw pixel of both cameras on the rectified normalised plane
    rays = {s: _undistorted(cams[s], *lenses[s], rotations[s]) for s in cams}
    lo = np.minimum(*(r.reshape(-1, 2).min(0) for r in rays.values()))
    hi = np.maximum(*(r.reshape(-1, 2).max(0) for r in rays.values()))
    focal = float(camera.fx)
    focal *= min(1.0, np.sqrt(MAX_RECTIFIED_AREA * camera.width * camera.height / np.prod((hi - lo) * focal)))
    size = tuple(int(v) for v in np.ceil((hi - lo) * focal) + 1)
    cx, cy = -lo * focal
    K_rect = np.array([[focal, 0, cx], [0, focal, cy], [0, 0, 1]])
    to_rectified, to_raw, inside = {}, {}, {}
    for s in cams:
        to_rectified[s] = cv2.initUndistortRectifyMap(*lenses[s], rotations[s], K_rect, size, cv2.CV_32FC1)
        ones = np.ones((cams[s].height, cams[s].width), np.uint8)
        inside[s] = cv2.remap(ones, *to_rectified[s], cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        x, y = rays[s][..., 0], rays[s][..., 1]
        # depth along the raw axis: Z_raw = Z_rect * (R^T (x, y, 1))_z
        factor = (rotations[s][0, 2] * x + rotations[s][1, 2] * y + rotations[s][2, 2]).astype(np.float32)
        xi = np.rint(x * focal + cx).astype(np.float32)
        yi = np.rint(y * focal + cy).astype(np.float32)
        to_raw[s] = (xi, yi, factor)
    return StereoRig(focal, float(camera.baseline_m), size, to_rectified, to_raw, inside)


def _undistorted(camera: Camera, K: np.ndarray, dist: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """Rectified normalised coordinates (H x W x 2) of every raw pixel of ``camera``."""
    v, u = np.mgrid[0 : camera.height, 0 : camera.width].astype(np.float64)
    points = np.stack([u.ravel(), v.ravel()], axis=1)[:, None, :]
    return cv2.undistortPoints(points, K, dist, R=rotation).reshape(camera.height, camera.width, 2)


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
        return _geometry_problem(sequence.camera)

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
        return cv2.StereoSGBM_create(
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


def fill_disparity(disparity: np.ndarray, margin: int, start: np.ndarray | None = None) -> np.ndarray:
    """Fill gaps of unknown disparity (< 1 px) of a left view that the geometry explains.

    Border strip: the first ``u`` columns of a row whose first valid disparity ``dR`` at
    column ``u`` is at least ``u - start - margin`` match outside the other image, whose
    usable part of that row begins at column ``start`` (per row, default 0); they take ``dR``.
    Occlusions: a row gap between valid neighbours ``dL`` and ``dR`` no wider than
    ``|dL - dR| + margin`` px (the background strip the nearer surface hides from the other
    camera, plus small matching gaps) takes the farther neighbour's disparity. Enclosed holes:
    a gap with valid pixels on all four sides, at most a quarter of the image wide and high
    (a blank poster on a wall), takes the disparity interpolated linearly along its row, which
    is exact on planes. Other gaps open to the image border (sky, an overexposed window) stay 0.
    """
    h, w = disparity.shape
    valid = disparity >= MIN_DISPARITY_PX
    left, right = _neighbours(valid, axis=1)
    up, down = _neighbours(valid, axis=0)
    v, u = np.nonzero(~valid)
    lft, r = left[v, u], right[v, u]
    v, u, lft, r = v[r < w], u[r < w], lft[r < w], r[r < w]
    d_right = disparity[v, r]
    first = 0 if start is None else np.asarray(start)[v]
    border = (lft < 0) & (r - first <= d_right + margin)
    d_left = np.where(lft < 0, d_right, disparity[v, np.maximum(lft, 0)])
    width = r - lft - 1
    occluded = border | ((lft >= 0) & (width <= np.abs(d_left - d_right) + margin))
    enclosed = (lft >= 0) & (up[v, u] >= 0) & (down[v, u] < h) & (width <= w // 4) & (down[v, u] - up[v, u] - 1 <= h // 4)
    value = np.where(occluded, np.minimum(d_left, d_right), d_left + (u - lft) / (r - lft) * (d_right - d_left))
    fill = occluded | enclosed
    out = disparity.astype(np.float32, copy=True)
    out[v[fill], u[fill]] = value[fill]
    return out


def fill_unmeasurable(depth: np.ndarray, unmeasurable: np.ndarray, solid: int = 11, region: float = 0.01) -> np.ndarray:
    """Give unknown depth (0) that the geometry explains the depth of the nearest dependable pixel.

    Dependable depth covers a ``solid`` x ``solid`` square of pixels with depth, in a region
    of such pixels covering at least ``region`` of the image (thin streaks and stray patches
    of depth are often mismatches). ``unmeasurable`` marks pixels that cannot be matched
    whatever the scene: their block leaves the image, or the other camera sees nothing of
    their row. The other pixels without dependable depth form connected regions
    (4-connected). A region open to the top (it reaches the first measurable pixel of some
    column) may be sky and stays as it is, as does a region enclosed by dependable depth (it
    reaches no border of the measurable area). A region that reaches only the left, right or
    bottom border is surface the other camera could not match (occluded by a near object,
    beyond the disparity range, cut by the image border): its unknown pixels take the depth
    of the nearest dependable pixel, and so do the unmeasurable ones, unless an unknown pixel
    of a region open to the top is nearer: the border above the sky stays 0, the border
    below a wall takes the wall's depth. Pixels with depth keep it.
    """
    unmeasurable = np.asarray(unmeasurable, bool)
    known = depth > 0
    if known.all() or not known.any():
        return depth
    kernel = np.ones((solid, solid), np.uint8)

    def dependable(mask: np.ndarray) -> np.ndarray:
        opened = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_OPEN, kernel)
        _, parts, stats, _ = cv2.connectedComponentsWithStats(opened, connectivity=4)
        large = stats[:, cv2.CC_STAT_AREA] >= region * depth.size
        large[0] = False
        return large[parts]

    rest = ~dependable(known) & ~unmeasurable
    count, labels = cv2.connectedComponents(rest.astype(np.uint8), connectivity=4)
    top = np.zeros(count, bool)
    top[labels[rest & _beyond(unmeasurable, 0, False)]] = True
    border = top.copy()
    for axis, reverse in ((0, True), (1, False), (1, True)):
        border[labels[rest & _beyond(unmeasurable, axis, reverse)]] = True
    fill = ~known & (unmeasurable | (rest & (border & ~top)[labels]))
    sky = ~known & rest & top[labels]
    # fill values come from smooth surfaces only: cut the depth at steps of more than STEP
    log = np.log(np.where(known, depth, 1.0))
    step = np.zeros_like(known)
    step[:, 1:] |= np.abs(np.diff(log, axis=1)) > STEP
    step[1:] |= np.abs(np.diff(log, axis=0)) > STEP
    step[:, :-1] |= step[:, 1:].copy()
    step[:-1] |= step[1:].copy()
    source = dependable(known & ~step) | sky
    if not fill.any() or not source.any():
        return depth
    _, nearest = cv2.distanceTransformWithLabels((~source).astype(np.uint8), cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
    values = depth.ravel()[np.flatnonzero(source)]
    return np.where(fill, values[np.maximum(nearest, 1) - 1], depth).astype(np.float32)


def _beyond(outside: np.ndarray, axis: int, reverse: bool) -> np.ndarray:
    """Pixels whose every pixel towards one edge of the image (``axis`` 0: the top, 1: the
    left; ``reverse``: the bottom, the right) is ``outside``; the pixels on the edge count."""
    mask = np.flip(outside, axis) if reverse else outside
    run = np.logical_and.accumulate(mask, axis=axis)
    first = np.ones_like(run[:1] if axis == 0 else run[:, :1])
    run = np.concatenate([first, run[:-1] if axis == 0 else run[:, :-1]], axis=axis)
    return np.flip(run, axis) if reverse else run


def _neighbours(valid: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """Index along ``axis`` of the nearest valid pixel at or before each pixel (-1: none) and
    at or after it (the axis length: none)."""
    n = valid.shape[axis]
    index = np.arange(n, dtype=np.int32).reshape((-1, 1) if axis == 0 else (1, -1))
    before = np.maximum.accumulate(np.where(valid, index, -1), axis=axis)
    after = np.flip(np.minimum.accumulate(np.flip(np.where(valid, index, n), axis), axis=axis), axis)
    return before, after


def _grey(rgb: np.ndarray | None) -> np.ndarray:
    """Luma of an HxWx3 RGB frame (uint8)."""
    if rgb is None:
        raise ModuleError("stereo depth: the frame has no right image")
    return cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
