"""The rectified geometry of a stereo camera pair: ``stereo_rig``.

Rectification. A pair is already rectified when neither camera has lens distortion, both share
the intrinsics and the right camera sits at ``T_left_right = [I | (B, 0, 0)]`` (KITTI, the
synthetic world). Otherwise (EuRoC) ``cv2.stereoRectify`` gives the rotations ``R1``, ``R2``
that turn each camera into a common rectified orientation; the rectified focal length ``f``
is the left camera's (capped so the rectified image holds at most 2.25 times the pixels) and
the rectified image is just large enough to hold every raw pixel of both cameras, so no pixel
of the original image is lost.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from sal_adapters.camera import Camera
from sal_modules.errors import ModuleError

__all__ = ["MAX_RECTIFIED_AREA", "StereoRig", "geometry_problem", "stereo_rig"]

#: Largest rectified image, as a multiple of the raw image area.
MAX_RECTIFIED_AREA = 2.25


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


def _is_rectified(camera: Camera, T: np.ndarray) -> bool:
    """No distortion, equal intrinsics and a pure +x baseline (``T``: the right camera's pose)."""
    right = camera.right or camera
    same = np.allclose([camera.fx, camera.fy, camera.cx, camera.cy], [right.fx, right.fy, right.cx, right.cy], rtol=0, atol=1e-6)
    straight = np.allclose(T[:3, :3], np.eye(3), rtol=0, atol=1e-9) and np.allclose(T[1:3, 3], 0, rtol=0, atol=1e-9 * abs(T[0, 3]))
    return same and straight and not any(camera.distortion) and not any(right.distortion)


def geometry_problem(camera: Camera) -> str | None:
    """Why ``camera`` is no usable horizontal stereo pair, or ``None``."""
    T = camera.T_lr
    if camera.baseline_m is None or not camera.baseline_m > 0 or T is None:
        return "the camera has no stereo baseline (the right camera's calibration is missing)"
    tx, ty, tz = T[:3, 3]
    if not (tx > 0 and abs(ty) < tx and abs(tz) < tx):
        return f"the right camera must sit to the right (+x) of the left camera; it sits at ({tx:.3f}, {ty:.3f}, {tz:.3f}) m"
    return None


@lru_cache(maxsize=8)
def stereo_rig(camera: Camera) -> StereoRig:
    """The rectified geometry of ``camera``'s stereo pair (computed once per camera)."""
    problem = geometry_problem(camera)
    T, baseline = camera.T_lr, camera.baseline_m
    if problem is not None or T is None or baseline is None:  # the last two: never without a problem
        raise ModuleError(f"stereo depth: {problem}")
    if _is_rectified(camera, T):
        return StereoRig(float(camera.fx), float(baseline), (camera.width, camera.height), {}, {}, {})
    right = camera.right or camera
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
    width, height = np.ceil((hi - lo) * focal) + 1
    size = (int(width), int(height))
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
    return StereoRig(focal, float(baseline), size, to_rectified, to_raw, inside)


def _undistorted(camera: Camera, K: np.ndarray, dist: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """Rectified normalised coordinates (H x W x 2) of every raw pixel of ``camera``."""
    v, u = np.mgrid[0 : camera.height, 0 : camera.width].astype(np.float64)
    points = np.stack([u.ravel(), v.ravel()], axis=1)[:, None, :]
    return cv2.undistortPoints(points, K, dist, R=rotation).reshape(camera.height, camera.width, 2)
