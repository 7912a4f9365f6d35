"""``rolling_shutter``: rows exposed one after another while the image moves.

Mathematical formulation
------------------------
A rolling-shutter sensor reads its rows out top to bottom in ``readout`` (s): row ``r`` of an
``H``-row image is exposed at ``t_r = (r / H - 1/2) * readout`` relative to the frame time, so
the middle row is on time. With the image velocity ``v(x)`` (px/s) of the clean sequence at the
frame time, what row ``r`` sees is the clean image moved by ``v t_r``:

    I_rs(x) = I(x - v(x) t_r)          (one bilinear remap)

The velocity is the mean of ``F_{k->j} / (t_j - t_k)`` over the neighbours ``j = k - 1, k + 1``
that exist (one at the first and last frame), where ``F_{k->j}`` is the image motion from frame
``k`` to frame ``j``:

- ``poses`` (exact for a static scene): reprojection of the clean depth ``Z`` through the
  ground-truth camera motion ``M = T_j^-1 T_k`` (camera-to-world poses; for the right camera
  ``T T_lr``), see ``flow.reprojection_flow``;
- ``flow``: dense optical flow (DIS) between the clean frames ``k`` and ``j``.

``auto`` takes poses when the sequence has per-frame ground truth and depth (native maps, or
the chain's depth provider), else flow, so mono sequences without depth work too.
"""

from __future__ import annotations

import numpy as np

from sal_modules.base import Perturbation
from sal_modules.context import DepthLookup, ModuleContext
from sal_modules.depth import NativeDepth
from sal_modules.errors import ModuleError
from sal_modules.motion.flow import CleanFrames, reprojection_flow, warp
from sal_modules.params import Param

__all__ = ["RollingShutter"]


class RollingShutter(Perturbation):
    """Rolling-shutter skew from a top-to-bottom readout of ``readout_ms``."""

    name = "rolling_shutter"
    version = 1
    summary = "Rolling-shutter skew: row r exposed at (r/H - 1/2) * readout while the image moves"

    readout_ms = Param(30.0, unit="ms", min=0.0, max=200.0, searchable=True, worse="higher", doc="time to read the rows out, top to bottom")
    motion = Param(
        "auto",
        domain="choice",
        choices=("auto", "poses", "flow"),
        doc="image motion from ground-truth poses and depth, from optical flow, or poses when available (auto)",
    )

    def unchanged_reason(self) -> str | None:
        return "readout_ms = 0 ms reads every row at once (a global shutter)" if self.readout_ms == 0.0 else None

    def setup(self, context: ModuleContext) -> None:
        super().setup(context)
        sequence = context.sequence
        if len(sequence) < 2:
            raise ModuleError(f"{self.name} needs at least 2 frames to measure motion; {sequence.name!r} has {len(sequence)}")
        self._frames = CleanFrames(sequence)
        self._depth: DepthLookup | None = None
        if self.motion != "flow":
            self._depth = _depth_of(context)
            missing = [
                what
                for what, ok in (("per-frame ground-truth poses", sequence.groundtruth_is_per_frame), ("depth", self._depth is not None))
                if not ok
            ]
            if missing and self.motion == "poses":
                raise ModuleError(
                    f"{self.name}: motion='poses' needs {' and '.join(missing)}; {sequence.name!r} ({sequence.sensor}) has none; use motion='flow'"
                )
            if missing:
                self._depth = None
            elif sequence.groundtruth is not None:  # per-frame ground truth: pose p belongs to the frame at position p
                self._poses = sequence.groundtruth.matrices

    @property
    def uses_poses(self) -> bool:
        """Whether the image motion comes from ground-truth poses and depth (after ``setup``)."""
        self.ready_context()
        return self._depth is not None

    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray:
        if self.readout_ms == 0.0:
            return image.copy()
        position = self.ready_context().position(index)
        velocity = self.velocity(position, stream)
        h = image.shape[0]
        row_time = (np.arange(h, dtype=np.float32) / h - np.float32(0.5)) * np.float32(self.readout_ms / 1000.0)
        return warp(image, velocity, -row_time[:, None, None])

    def velocity(self, position: int, stream: str) -> np.ndarray:
        """Image velocity (HxWx2 float32, px/s) of the clean frame at ``position``."""
        times = self._frames.times
        neighbours = [j for j in (position - 1, position + 1) if 0 <= j < len(self._frames)]
        total = sum(
            (self._motion(position, j, stream) / np.float32(times[j] - times[position]) for j in neighbours), np.zeros((), np.float32)
        )
        return total / np.float32(len(neighbours))

    def _motion(self, source: int, target: int, stream: str) -> np.ndarray:
        """Image motion F (HxWx2 px) from clean frame ``source`` to ``target``."""
        if self._depth is None:
            return self._frames.flow(source, target, stream)
        context = self.ready_context()
        records = context.sequence.records
        poses = [self._poses[p] for p in (source, target)]
        T_lr = context.camera.T_lr
        if stream == "right" and T_lr is not None:
            poses = [pose @ T_lr for pose in poses]
        motion = np.linalg.inv(poses[1]) @ poses[0]
        return reprojection_flow(self._depth(records[source].index, stream), context.camera_for(stream), motion)


def _depth_of(context: ModuleContext) -> DepthLookup | None:
    """Depth of the clean frames: the chain's provider, else native maps, else ``None``."""
    if context.depth is not None:
        return context.depth
    native = NativeDepth()
    return native.lookup(context.sequence) if native.unavailable(context.sequence) is None else None
