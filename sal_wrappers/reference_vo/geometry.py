"""Geometry of the reference visual odometry: lens model, features, matching, depth, poses.

Everything here is deterministic: fixed parameters, RANSAC with fixed iteration counts and
OpenCV's fixed-seed generators, no randomised approximate search. Poses are 4x4 arrays;
``T_cw`` maps world points into the camera, ``T_wc`` is its inverse (camera-to-world).

Points live in two coordinate systems: ``xy`` are positions in the working image (the raw
image, or the rectified left image of an unrectified stereo pair), ``pts`` the matching ideal
pinhole pixels (``xy`` with lens distortion removed) that every geometric step uses with ``K``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial import cKDTree

from sal_adapters.compat import popcount, undistort_points_iter
from sal_adapters.sequence import Sequence

__all__ = [
    "Features",
    "Lens",
    "brute_match",
    "depth_points",
    "detect",
    "guided_match",
    "initial_pose",
    "invert",
    "make_lens",
    "refine_pnp",
    "solve_pnp",
    "stereo_points",
    "triangulate",
]

#: largest Hamming distance (of 256 bits) accepted for a match
MAX_DISTANCE = 64
#: best match must be this much better than the second best (ratio test)
RATIO = 0.85


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
    from sal_modules.depth.stereo import stereo_rig

    rig = stereo_rig(camera)
    if rig.rectified:
        return Lens(camera.K, None, None, (None, None), rig.baseline, np.eye(3))
    K_rect, R_rect = _rectified_camera(rig.to_rectified["left"], rig.inside["left"], camera.K, dist)
    kernel = np.ones((15, 15), np.uint8)
    masks = tuple(cv2.erode(rig.inside[s], kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0) * 255 for s in ("left", "right"))
    return Lens(K_rect, None, (rig.to_rectified["left"], rig.to_rectified["right"]), masks, rig.baseline, R_rect)


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


# -- features --------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Features:
    """Keypoints of one image: positions ``xy`` (float32 Nx2, working image), ideal pixels
    ``pts`` (float64 Nx2), pyramid ``octave`` (int N) and ORB ``desc`` (uint8 Nx32 or ``None``)."""

    xy: np.ndarray
    pts: np.ndarray
    octave: np.ndarray
    desc: np.ndarray | None

    def __len__(self) -> int:
        return len(self.xy)

    def take(self, index: np.ndarray) -> Features:
        return Features(self.xy[index], self.pts[index], self.octave[index], None if self.desc is None else self.desc[index])


def detect(orb: cv2.ORB, grey: np.ndarray, lens: Lens, stream: int = 0, mask: np.ndarray | None = None) -> Features:
    """ORB keypoints and descriptors of ``grey`` (``stream`` 0: left, 1: right image) where
    ``mask`` (default: the lens's) is not 0."""
    keypoints, desc = orb.detectAndCompute(grey, lens.masks[stream] if mask is None else mask)
    if not keypoints or desc is None:
        return Features(np.zeros((0, 2), np.float32), np.zeros((0, 2)), np.zeros(0, np.int32), np.zeros((0, 32), np.uint8))
    xy = np.array([k.pt for k in keypoints], np.float32)
    octave = np.array([k.octave for k in keypoints], np.int32)
    return Features(xy, lens.undistort(xy), octave, desc)


def _hamming(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamming distances between (broadcast) descriptor arrays (..., 32) of uint8."""
    a, b = np.ascontiguousarray(a).view(np.uint64), np.ascontiguousarray(b).view(np.uint64)
    return popcount(np.bitwise_xor(a, b)).sum(axis=-1, dtype=np.int32)


def _best(query: np.ndarray, train: np.ndarray, candidates: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per query row, the candidate (index into ``train``) that passes the distance and ratio
    tests, or -1; ``candidates`` is NxK, ``valid`` marks real candidates. Each train
    descriptor goes to at most one query (the nearest)."""
    n = len(query)
    if n == 0 or candidates.shape[1] == 0:
        return np.full(n, -1, np.int64), np.zeros(n, np.int32)
    safe = np.where(valid, candidates, 0)
    dist = np.where(valid, _hamming(query[:, None, :], train[safe]), 1 << 20)
    order = np.argsort(dist, axis=1, kind="stable")
    rows = np.arange(n)
    best = dist[rows, order[:, 0]]
    second = dist[rows, order[:, 1]] if dist.shape[1] > 1 else np.full(n, 1 << 20)
    ok = (best <= MAX_DISTANCE) & (best < RATIO * second)
    match = np.where(ok, safe[rows, order[:, 0]], -1)
    return _unique(match, best), best


def _unique(match: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Drop all but the nearest query of each train index in ``match`` (-1 = none)."""
    hit = np.flatnonzero(match >= 0)
    if not len(hit):
        return match
    order = hit[np.lexsort((dist[hit], match[hit]))]
    keep = np.ones(len(order), bool)
    keep[1:] = match[order[1:]] != match[order[:-1]]
    out = np.full_like(match, -1)
    out[order[keep]] = match[order[keep]]
    return out


def guided_match(desc: np.ndarray, predicted: np.ndarray, current: Features, radius: float, k: int = 8) -> np.ndarray:
    """Match descriptors ``desc`` whose positions are predicted at ``predicted`` (Nx2 ideal
    pixels, NaN: none) to the ``k`` nearest current keypoints within ``radius`` px; returns
    the current index per row (-1: none)."""
    out = np.full(len(desc), -1, np.int64)
    rows = np.flatnonzero(np.isfinite(predicted).all(axis=1))
    if not len(rows) or not len(current):
        return out
    k = min(k, len(current))
    _, idx = cKDTree(current.pts).query(predicted[rows], k=k, distance_upper_bound=radius)
    idx = idx.reshape(len(rows), k)
    out[rows] = _best(desc[rows], current.desc, idx, idx < len(current))[0]
    return out


def brute_match(desc: np.ndarray, current: Features) -> np.ndarray:
    """Match ``desc`` to every current descriptor (ratio test, one-to-one); index per row."""
    out = np.full(len(desc), -1, np.int64)
    if len(desc) == 0 or len(current) < 2:
        return out
    pairs = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(desc, current.desc, k=2)
    idx = np.array([[m.trainIdx for m in p] + [-1] * (2 - len(p)) for p in pairs], np.int64)
    return _best(desc, current.desc, np.maximum(idx, 0), idx >= 0)[0]


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
    match, _ = _best(left.desc, right.desc, safe, valid)
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
