"""Native depth: the dataset's own depth maps (RGB-D sensors, the synthetic world)."""

from __future__ import annotations

from typing import Any

import numpy as np

from sal_adapters.camera import Camera
from sal_adapters.sequence import Frame, Sequence
from sal_modules.depth.base import DepthProvider, fill_unknown

__all__ = ["NativeDepth", "left_depth_to_right"]


class NativeDepth(DepthProvider):
    """Depth maps stored with the frames. The right stream of a stereo pair gets the left
    map re-projected into the right camera (``left_depth_to_right``)."""

    name = "native"

    def caches(self, stream: str) -> bool:
        """The left map is read as it is; the re-projected right map is computed once and stored."""
        return stream == "right"

    def settings(self) -> dict[str, Any]:
        return {"right_warp": 1}  # bumped when left_depth_to_right changes its output

    def unavailable(self, sequence: Sequence) -> str | None:
        if not sequence.records or any(r.depth is None for r in sequence.records):
            return f"sequence {sequence.name!r} ({sequence.sensor}) has no depth maps"
        return None

    def compute(self, sequence: Sequence, position: int, stream: str) -> np.ndarray:
        depth = Frame(sequence.records[position], sequence.camera).depth
        assert depth is not None
        if stream == "right":
            return left_depth_to_right(depth, sequence.camera)
        return depth


def left_depth_to_right(depth: np.ndarray, camera: Camera) -> np.ndarray:
    """Forward-warp a rectified left depth map into the right camera.

    A left pixel (u, v) at depth Z lands at u_r = u - fx B / Z; sky (0) is infinitely far and
    lands at u_r = u. Where several land on the same right pixel the nearest wins (z-buffer).
    Right pixels nothing lands on (occlusions, the band at the right border the left camera
    does not see) take the farther of their row neighbours (``fill_unknown``).
    """
    if camera.baseline_m is None:
        raise ValueError("the camera has no stereo baseline")
    h, w = depth.shape
    v, u = np.indices((h, w)).reshape(2, -1)
    z = depth.reshape(-1).astype(np.float32)
    sky = ~(z > 0)
    far = np.where(sky, np.inf, z)
    disparity = np.where(sky, 0.0, camera.fx * camera.baseline_m / np.where(sky, 1.0, z))
    ur = np.rint(u - disparity).astype(np.int64)
    inside = (ur >= 0) & (ur < w)
    v, ur, far, disparity = v[inside], ur[inside], far[inside], disparity[inside]
    # far first (small disparity), so nearer points overwrite them; a 16-bit key of 1/32 px
    # steps lets numpy's stable sort use radix sort (linear time)
    key = np.minimum(disparity * 32.0, 65535.0).astype(np.uint16)
    order = np.argsort(key, kind="stable")
    out = np.full((h, w), np.nan, dtype=np.float32)
    out[v[order], ur[order]] = far[order]
    out = fill_unknown(out)
    out[~np.isfinite(out)] = 0.0  # sky and rows with nothing known
    return out
