"""``stereo_desync``: the right camera of a stereo pair captures later than the left one.

Mathematical formulation
------------------------
The left image of frame ``k`` is taken at ``t_k``, the right one at ``T = t_k + delay``. The
right image at ``T`` is synthesised from the clean right frames ``j`` and ``j + 1`` around it
(``t_j <= T < t_{j+1}``, ``a = (T - t_j) / (t_{j+1} - t_j)``) by flow-based interpolation.
With the dense flows ``F = F_{j->j+1}`` and ``B = F_{j+1->j}`` (px) of the clean right stream,
content moves by ``a F`` from frame ``j`` and by ``-(1 - a) B`` from frame ``j + 1``:

    R(T) = (1 - a) R_j(x - a F(x)) + a R_{j+1}(x - (1 - a) B(x))

An integer number of frames is a plain frame shift (``a = 0``). Past the last frame the motion
of the last pair is extrapolated at constant velocity (``a > 1``, second term only). The left
stream, the timestamps and the ground truth stay as they are: the left camera defines time.

The right image is rebuilt from the clean sequence, so this module must come before modules
that change the right images in a chain; it refuses a right image that earlier steps changed.
"""

from __future__ import annotations

import cv2
import numpy as np

from sal_modules.base import Perturbation
from sal_modules.context import ModuleContext
from sal_modules.errors import ModuleError
from sal_modules.motion.flow import CleanFrames, warp
from sal_modules.params import Param

__all__ = ["StereoDesync"]

#: Interpolation weights within this fraction of the frame period of 0 or 1 are a plain frame
#: shift (absorbs the timestamp jitter of real datasets), so a delay of whole frame periods
#: gives the clean frames exactly.
FRAME_SNAP = 1e-3


class StereoDesync(Perturbation):
    """Right camera late by ``delay_ms``: right images re-timed from the clean right stream."""

    name = "stereo_desync"
    version = 1
    summary = "Right camera captures delay_ms after the left one (flow-interpolated right stream)"

    delay_ms = Param(50.0, unit="ms", min=0.0, max=1000.0, searchable=True, worse="higher", doc="how much later the right camera captures")

    def unchanged_reason(self) -> str | None:
        return "delay_ms = 0 ms captures both cameras at once" if self.delay_ms == 0.0 else None

    def setup(self, context: ModuleContext) -> None:
        super().setup(context)
        sequence = context.sequence
        if sequence.sensor != "stereo":
            raise ModuleError(
                f"{self.name} needs a stereo sequence; {sequence.name!r} is {sequence.sensor} (no right camera to desynchronise)"
            )
        if len(sequence) < 2:
            raise ModuleError(f"{self.name} needs at least 2 frames to interpolate in time; {sequence.name!r} has {len(sequence)}")
        self._frames = CleanFrames(sequence, keep=8 + int(np.ceil(self.delay_ms / 1000.0 * sequence.fps)))

    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray:
        if stream != "right" or self.delay_ms == 0.0:
            return image.copy()
        position = self.ready_context().position(index)
        frames = self._frames
        if not np.array_equal(image, frames.image(position, "right")):
            raise ModuleError(
                f"{self.name} rebuilds the right images from the clean sequence, but an earlier step changed the right image "
                f"of frame {index}; put {self.name} first in the chain (e.g. stereo_desync >> fog)"
            )
        j, a = self.bracket(position)
        if abs(a) < FRAME_SNAP:
            return frames.image(j, "right").copy()
        if abs(a - 1.0) < FRAME_SNAP:
            return frames.image(j + 1, "right").copy()
        late = warp(frames.image(j + 1, "right"), frames.flow(j + 1, j, "right"), a - 1.0)
        if a >= 1.0:
            return late
        early = warp(frames.image(j, "right"), frames.flow(j, j + 1, "right"), -a)
        return cv2.addWeighted(early, 1.0 - a, late, a, 0.0)

    def bracket(self, position: int) -> tuple[int, float]:
        """``(j, a)``: the right image of frame ``position`` is taken between clean frames ``j``
        and ``j + 1``, at the fraction ``a`` of that interval (``a > 1`` past the last frame)."""
        times = self._frames.times
        capture = times[position] + self.delay_ms / 1000.0
        j = int(np.clip(np.searchsorted(times, capture, side="right") - 1, 0, len(times) - 2))
        a = float((capture - times[j]) / (times[j + 1] - times[j]))
        if abs(a - 1.0) < FRAME_SNAP and j + 2 < len(times):
            j, a = j + 1, 0.0
        return j, a
