"""ORB features of the reference visual odometry and how they are matched.

Matching is deterministic: exact Hamming distances (of 256 bits), a distance limit and a
ratio test, one-to-one (each train descriptor goes to its nearest query), candidates from a
k-d tree of predicted positions or from OpenCV's brute-force matcher.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial import cKDTree

from sal_adapters.common.compat import popcount
from sal_wrappers.reference_vo.lens import Lens

__all__ = ["MAX_DISTANCE", "RATIO", "Features", "best_matches", "brute_match", "detect", "guided_match"]

#: largest Hamming distance (of 256 bits) accepted for a match
MAX_DISTANCE = 64
#: best match must be this much better than the second best (ratio test)
RATIO = 0.85


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

    @property
    def descriptors(self) -> np.ndarray:
        """``desc`` of detected keypoints (points followed by optical flow have none)."""
        if self.desc is None:
            raise ValueError("these keypoints were followed by optical flow: they have no ORB descriptors")
        return self.desc

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


def best_matches(query: np.ndarray, train: np.ndarray, candidates: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
    out[rows] = best_matches(desc[rows], current.descriptors, idx, idx < len(current))[0]
    return out


def brute_match(desc: np.ndarray, current: Features) -> np.ndarray:
    """Match ``desc`` to every current descriptor (ratio test, one-to-one); index per row."""
    out = np.full(len(desc), -1, np.int64)
    if len(desc) == 0 or len(current) < 2:
        return out
    pairs = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(desc, current.descriptors, k=2)
    idx = np.array([[m.trainIdx for m in p] + [-1] * (2 - len(p)) for p in pairs], np.int64)
    return best_matches(desc, current.descriptors, np.maximum(idx, 0), idx >= 0)[0]
