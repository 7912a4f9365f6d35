"""Native depth: the dataset's own depth maps (RGB-D sensors, the synthetic world)."""

from __future__ import annotations

import numpy as np

from sal_adapters.camera import Camera
from sal_adapters.sequence import Frame, Sequence
from sal_modules.depth.base import DepthProvider, fill_holes

__all__ = ["NativeDepth", "left_depth_to_right"]


class NativeDepth(DepthProvider):
    """Depth maps stored with the frames. The right stream of a stereo pair gets the left
    map re-projected into the right camera (``left_depth_to_right``)."""

    name = "native"
    cached = False

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

    A left pixel (u, v) at depth Z lands at u_r = u - fx B / Z; where several land on the same
    right pixel the nearest wins (z-buffer), and narrow occlusion holes take the background.
    """
    if camera.baseline_m is None:
        raise ValueError("the camera has no stereo baseline")
    h, w = depth.shape
    v, u = np.nonzero(depth > 0)
    z = depth[v, u]
    ur = np.rint(u - camera.fx * camera.baseline_m / z).astype(np.int64)
    inside = (ur >= 0) & (ur < w)
    v, ur, z = v[inside], ur[inside], z[inside]
    order = np.argsort(-z, kind="stable")  # far first, so nearer points overwrite them
    out = np.zeros_like(depth, dtype=np.float32)
    out[v[order], ur[order]] = z[order]
    max_disparity = camera.fx * camera.baseline_m / max(float(z.min()), 1e-3) if z.size else 0.0
    return fill_holes(out, max_width=int(np.ceil(max_disparity)) + 1)
