"""The working camera of the reference visual odometry: ``Lens`` and ``make_lens``.

Points live in two coordinate systems: ``xy`` are positions in the working image (the raw
image, or the rectified left image of an unrectified stereo pair), ``pts`` the matching ideal
pinhole pixels (``xy`` with lens distortion removed) that every geometric step uses with ``K``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from sal_adapters.common.compat import undistort_points_iter
from sal_adapters.sequence import Sequence

__all__ = ["Lens", "make_lens"]


@dataclass(frozen=True, eq=False)
class Lens:
    """The working camera: intrinsics ``K``, distortion of the working image (``None``: an
    ideal pinhole), and for stereo the rectification of the pair.

    Attributes:
        K: 3x3 intrinsics of the working image (the rectified left camera for a rectified pair).
        dist: distortion coefficients of the working image, or ``None``.
        maps: ``cv2.remap`` maps (left, right) into the rectified pair; ``None`` when the raw
            pair is rectified already (or for mono/RGB-D).
        masks: uint8 masks (left, right) of the working images where features may be
            detected (``None``: everywhere).
        baseline: stereo baseline (m), 0 without stereo.
        R_rect: rotation raw-left -> working camera (``x_work = R_rect x_raw``).
    """

    K: np.ndarray
    dist: np.ndarray | None
    maps: tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None
    masks: tuple[np.ndarray | None, np.ndarray | None]
    baseline: float
    R_rect: np.ndarray

    def undistort(self, xy: np.ndarray) -> np.ndarray:
        """Ideal pinhole pixels (float64 Nx2) of working-image positions ``xy``."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        if self.dist is None or not len(xy):
            return xy
        return cv2.undistortPoints(xy[:, None, :], self.K, self.dist, P=self.K).reshape(-1, 2)

    def distort(self, pts: np.ndarray) -> np.ndarray:
        """Working-image positions (float64 Nx2) of ideal pinhole pixels ``pts`` (NaN stays)."""
        pts = np.asarray(pts, np.float64).reshape(-1, 2)
        if self.dist is None or not len(pts):
            return pts
        ok = np.isfinite(pts).all(axis=1)
        out = np.full_like(pts, np.nan)
        if ok.any():
            rays = cv2.undistortPoints(pts[ok][:, None, :], self.K, None)  # normalised coordinates
            rays = np.concatenate([rays.reshape(-1, 2), np.ones((int(ok.sum()), 1))], axis=1)
            out[ok] = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), self.K, self.dist)[0].reshape(-1, 2)
        return out

    def to_raw(self, T: np.ndarray) -> np.ndarray:
        """Poses ``T`` (Nx4x4, working camera, world = first working camera) as raw-left
        camera poses in the first raw-left camera's frame."""
        C = np.eye(4)
        C[:3, :3] = self.R_rect
        return C.T @ T @ C


def make_lens(sequence: Sequence, mode: str) -> Lens:
    """The working camera of ``sequence`` in ``mode`` (``mono``, ``stereo``, ``rgbd``)."""
    camera = sequence.camera
    dist = np.array(camera.distortion, np.float64) if any(camera.distortion) else None
    if mode != "stereo":
        return Lens(camera.K, dist, None, (None, None), 0.0, np.eye(3))
    from sal_modules.depth.stereo_rig import stereo_rig

    rig = stereo_rig(camera)
    if rig.rectified:
        return Lens(camera.K, None, None, (None, None), rig.baseline, np.eye(3))
    K_rect, R_rect = _rectified_camera(rig.to_rectified["left"], rig.inside["left"], camera.K, dist)
    kernel = np.ones((15, 15), np.uint8)
    left, right = (cv2.erode(rig.inside[s], kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0) * 255 for s in ("left", "right"))
    return Lens(K_rect, None, (rig.to_rectified["left"], rig.to_rectified["right"]), (left, right), rig.baseline, R_rect)


def _rectified_camera(
    maps: tuple[np.ndarray, np.ndarray], inside: np.ndarray, K: np.ndarray, dist: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """Intrinsics ``K_rect`` and rotation ``R`` (raw -> rectified) of a rectification given by
    its remap maps: rectified pixels ``q`` and the raw pixels they sample satisfy
    ``q ~ K_rect R undistort(raw)``, a homography fitted exactly and split by RQ decomposition."""
    v, u = np.nonzero(inside[::8, ::8])
    u, v = u * 8, v * 8
    raw = np.stack([maps[0][v, u], maps[1][v, u]], axis=1).astype(np.float64)
    rays = undistort_points_iter(raw[:, None, :], K, dist, (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10))
    H, _ = cv2.findHomography(rays.reshape(-1, 2), np.stack([u, v], axis=1).astype(np.float64), 0)
    _, upper, rotation = cv2.RQDecomp3x3(H)[:3]
    signs = np.diag(np.sign(np.diag(upper)))
    upper, rotation = upper @ signs, signs @ rotation
    if np.linalg.det(rotation) < 0:
        rotation = -rotation
    return upper / upper[2, 2], rotation
