"""Filling unknown stereo depth that the geometry explains: ``fill_disparity``, ``fill_unmeasurable``.

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
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["MIN_DISPARITY_PX", "STEP", "fill_disparity", "fill_unmeasurable"]

#: Smallest disparity (px) turned into depth.
MIN_DISPARITY_PX = 1.0
#: Largest relative depth step (log) between neighbours inside one surface when filling.
STEP = 0.1


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
