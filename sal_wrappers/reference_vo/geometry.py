"""Geometry of the reference visual odometry: depth of features, poses, projection, triangulation.

Everything here is deterministic: fixed parameters, RANSAC with fixed iteration counts and
OpenCV's fixed-seed generators, no randomised approximate search. Poses are 4x4 arrays;
``T_cw`` maps world points into the camera, ``T_wc`` is its inverse (camera-to-world). Pixels
are ideal pinhole pixels (``pts``; see ``sal_wrappers.reference_vo.lens``).
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial import cKDTree

from sal_wrappers.reference_vo.features import Features, best_matches
from sal_wrappers.reference_vo.lens import Lens

__all__ = [
    "backproject",
    "depth_points",
    "initial_pose",
    "invert",
    "matrix",
    "project",
    "project_each",
    "refine_pnp",
    "solve_pnp",
    "stereo_points",
    "triangulate",
]


# -- depth -----------------------------------------------------------------------------------


def backproject(K: np.ndarray, pts: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Camera-frame points (Nx3) of ideal pixels ``pts`` at depths ``z`` (NaN where z <= 0)."""
    x = (pts[:, 0] - K[0, 2]) / K[0, 0]
    y = (pts[:, 1] - K[1, 2]) / K[1, 1]
    z = np.where(z > 0, z, np.nan)
    return np.stack([x * z, y * z, z], axis=1)


def depth_points(lens: Lens, depth: np.ndarray, features: Features, step: float = 0.03) -> np.ndarray:
    """Camera-frame points from a depth map (m, 0 invalid) at the features: NaN where the
    depth is missing or jumps by more than ``step`` (relative) within the 3x3 pixels around."""
    h, w = depth.shape
    u = np.clip(np.rint(features.xy[:, 0]).astype(np.int64), 1, w - 2)
    v = np.clip(np.rint(features.xy[:, 1]).astype(np.int64), 1, h - 2)
    patch = np.stack([depth[v + dv, u + du] for dv in (-1, 0, 1) for du in (-1, 0, 1)], axis=1)
    patch = np.where(np.isfinite(patch), patch, 0)
    lo, hi = patch.min(axis=1), patch.max(axis=1)
    z = np.where((lo > 0) & (hi <= lo * (1 + step)), patch[:, 4], 0.0)
    return backproject(lens.K, features.pts, z)


def stereo_points(
    lens: Lens, left: Features, right: Features, left_grey: np.ndarray, right_grey: np.ndarray, max_disparity: float
) -> np.ndarray:
    """Camera-frame points of left features matched along the rectified rows of the right
    image (ORB descriptors, same pyramid octave +-1, then sub-pixel refinement by
    Lucas-Kanade); NaN where no match."""
    out = np.full((len(left), 3), np.nan)
    if not len(left) or len(right) < 2:
        return out
    # box search: |dy| <= 2 px, 0 < disparity <= max_disparity (Chebyshev metric, x scaled)
    sx = 4.0 / max_disparity
    tree = cKDTree(np.stack([right.xy[:, 0] * sx, right.xy[:, 1]], axis=1))
    centre = np.stack([(left.xy[:, 0] - max_disparity / 2) * sx, left.xy[:, 1]], axis=1)
    k = min(24, len(right))
    _, idx = tree.query(centre, k=k, distance_upper_bound=2.0, p=np.inf)
    idx = idx.reshape(len(left), k)
    valid = idx < len(right)
    safe = np.where(valid, idx, 0)
    valid &= np.abs(right.octave[safe] - left.octave[:, None]) <= 1
    valid &= right.xy[safe, 0] < left.xy[:, None, 0]
    match, _ = best_matches(left.descriptors, right.descriptors, safe, valid)
    rows = np.flatnonzero(match >= 0)
    if not len(rows):
        return out
    p0 = left.xy[rows].reshape(-1, 1, 2)
    p1 = right.xy[match[rows]].reshape(-1, 1, 2).copy()
    p1, status, _ = cv2.calcOpticalFlowPyrLK(
        left_grey,
        right_grey,
        p0,
        p1,
        winSize=(11, 11),
        maxLevel=1,
        criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 0.01),
        flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
    )
    p1 = p1.reshape(-1, 2)
    moved = np.linalg.norm(p1 - right.xy[match[rows]], axis=1)
    disparity = left.xy[rows, 0] - p1[:, 0]
    good = (status.ravel() == 1) & (np.abs(p1[:, 1] - left.xy[rows, 1]) < 1.0) & (moved < 3.0) & (disparity >= 1.0)
    rows, disparity = rows[good], disparity[good]
    z = lens.K[0, 0] * lens.baseline / disparity
    out[rows] = backproject(lens.K, left.pts[rows], z)
    return out


# -- poses -----------------------------------------------------------------------------------


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform."""
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def matrix(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3))[0]
    T[:3, 3] = np.asarray(tvec, np.float64).reshape(3)
    return T


def project(K: np.ndarray, T_cw: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Ideal pixels (Nx2) of world points ``X``; NaN for points not in front of the camera."""
    Xc = X @ T_cw[:3, :3].T + T_cw[:3, 3]
    z = Xc[:, 2]
    front = z > 1e-6
    z = np.where(front, z, 1.0)
    uv = np.stack([K[0, 0] * Xc[:, 0] / z + K[0, 2], K[1, 1] * Xc[:, 1] / z + K[1, 2]], axis=1)
    uv[~front] = np.nan
    return uv


def project_each(K: np.ndarray, T_cw: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Ideal pixels (Nx2) of world points ``X`` (Nx3) each in its own pose ``T_cw`` (Nx4x4)."""
    Xc = np.einsum("nij,nj->ni", T_cw[:, :3, :3], X) + T_cw[:, :3, 3]
    z = np.where(Xc[:, 2] > 1e-6, Xc[:, 2], np.nan)
    return np.stack([K[0, 0] * Xc[:, 0] / z + K[0, 2], K[1, 1] * Xc[:, 1] / z + K[1, 2]], axis=1)


def solve_pnp(
    K: np.ndarray, X: np.ndarray, pts: np.ndarray, threshold: float, iterations: int = 100
) -> tuple[np.ndarray, np.ndarray] | None:
    """``T_cw`` from world points ``X`` seen at ideal pixels ``pts``: RANSAC (P3P, fixed
    iterations) then Levenberg-Marquardt on the inliers; returns (T_cw, inlier mask) or None."""
    if len(X) < 6:
        return None
    ok, rvec, tvec, inliers = cv2.solvePnPRansac(
        X.astype(np.float64),
        pts.astype(np.float64),
        K,
        None,
        iterationsCount=iterations,
        reprojectionError=threshold,
        confidence=0.999,
        flags=cv2.SOLVEPNP_AP3P,
    )
    if not ok or inliers is None or len(inliers) < 6:
        return None
    mask = np.zeros(len(X), bool)
    mask[inliers.ravel()] = True
    return refine_pnp(K, X, pts, matrix(rvec, tvec), threshold, mask, rounds=1)


def refine_pnp(
    K: np.ndarray, X: np.ndarray, pts: np.ndarray, T_cw: np.ndarray, threshold: float, inliers: np.ndarray | None = None, rounds: int = 2
) -> tuple[np.ndarray, np.ndarray] | None:
    """Levenberg-Marquardt refinement of ``T_cw`` on the correspondences that reproject within
    ``threshold`` px (``rounds`` times, re-selecting them); returns (T_cw, inlier mask) or None."""
    if inliers is None:
        inliers = np.linalg.norm(project(K, T_cw, X) - pts, axis=1) < threshold
    rvec, tvec = cv2.Rodrigues(T_cw[:3, :3])[0], T_cw[:3, 3].reshape(3, 1).copy()
    for _ in range(rounds):
        if np.count_nonzero(inliers) < 6:
            return None
        rvec, tvec = cv2.solvePnPRefineLM(X[inliers], pts[inliers], K, None, rvec, tvec)
        err = np.linalg.norm(project(K, matrix(rvec, tvec), X) - pts, axis=1)
        inliers = err < threshold
    if np.count_nonzero(inliers) < 6:
        return None
    return matrix(rvec, tvec), inliers


def triangulate(
    K: np.ndarray, T1_cw: np.ndarray, T2_cw: np.ndarray, p1: np.ndarray, p2: np.ndarray, threshold: float, min_angle_deg: float
) -> np.ndarray:
    """World points seen at ideal pixels ``p1`` (camera 1) and ``p2`` (camera 2); NaN rows
    where a point is behind a camera, reprojects worse than ``threshold`` px or is seen under
    a parallax angle below ``min_angle_deg``."""
    if not len(p1):
        return np.zeros((0, 3))
    P1, P2 = K @ T1_cw[:3], K @ T2_cw[:3]
    Xh = cv2.triangulatePoints(P1, P2, p1.T.astype(np.float64), p2.T.astype(np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):
        X = (Xh[:3] / Xh[3]).T
    ok = np.isfinite(X).all(axis=1)
    X = np.where(ok[:, None], X, 0.0)
    for T, p in ((T1_cw, p1), (T2_cw, p2)):
        err = np.linalg.norm(project(K, T, X) - p, axis=1)
        ok &= np.isfinite(err) & (err < threshold)
    c1, c2 = invert(T1_cw)[:3, 3], invert(T2_cw)[:3, 3]
    r1, r2 = X - c1, X - c2
    cos = np.sum(r1 * r2, axis=1) / np.maximum(np.linalg.norm(r1, axis=1) * np.linalg.norm(r2, axis=1), 1e-12)
    ok &= cos < np.cos(np.radians(min_angle_deg))
    X[~ok] = np.nan
    return X


def initial_pose(K: np.ndarray, p1: np.ndarray, p2: np.ndarray, threshold: float) -> np.ndarray | None:
    """Relative pose ``T_21`` (camera 1 -> camera 2, unit translation) from an essential matrix
    (RANSAC, fixed seed) and the cheirality check; ``None`` when it cannot be found."""
    if len(p1) < 8:
        return None
    E, mask = cv2.findEssentialMat(p1, p2, K, cv2.RANSAC, 0.999, threshold)
    if E is None or E.shape != (3, 3):
        return None
    good, R, t, _ = cv2.recoverPose(E, p1, p2, K, mask=mask)
    if good < 8:
        return None
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t.ravel()
    return T
