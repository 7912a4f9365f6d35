"""The few calls that differ across the supported library versions, in one place.

pytest-sal supports numpy 1.26 to 2.x and OpenCV 4.9 to 5.x (the lower bounds in
``pyproject.toml`` are tested by ``.ci/lowest``). Everything else is called the same way on
both ends.

>>> popcount(np.array([0, 1, 3, 2**64 - 1], np.uint64)).tolist()
[0, 1, 2, 64]
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

__all__ = ["popcount", "undistort_points_iter"]

_M1, _M2, _M4, _H01 = (np.uint64(v) for v in (0x5555555555555555, 0x3333333333333333, 0x0F0F0F0F0F0F0F0F, 0x0101010101010101))
_ONE, _TWO, _FOUR, _BYTE = (np.uint64(v) for v in (1, 2, 4, 56))


def popcount(words: np.ndarray) -> np.ndarray:
    """Set bits of every element of a uint64 array, as uint8 (``np.bitwise_count``, numpy >= 2.0;
    the SWAR popcount before it)."""
    if words.dtype != np.uint64:
        raise TypeError(f"popcount takes uint64 words, not {words.dtype}")
    bitwise_count = getattr(np, "bitwise_count", None)
    if bitwise_count is not None:
        return bitwise_count(words)
    x = words - ((words >> _ONE) & _M1)
    x = (x & _M2) + ((x >> _TWO) & _M2)
    x = (x + (x >> _FOUR)) & _M4
    return ((x * _H01) >> _BYTE).astype(np.uint8)  # uint64 arrays wrap silently on overflow


def undistort_points_iter(points: np.ndarray, K: np.ndarray, dist: np.ndarray | None, criteria: tuple[int, int, float]) -> Any:
    """``cv2.undistortPoints`` to normalised coordinates with the given stopping ``criteria``:
    OpenCV 5 takes ``criteria=`` there; OpenCV 4 has ``cv2.undistortPointsIter`` for it."""
    iterate = getattr(cv2, "undistortPointsIter", None)
    if iterate is not None:  # OpenCV 4.x
        return iterate(points, K, dist, None, None, criteria)
    return cv2.undistortPoints(points, K, dist, criteria=criteria)
