"""``frame_drop``: frames lost between camera and SLAM, at random or periodically.

Random mode draws one uniform number u_i per dataset index from the seed and drops frame i
when u_i < drop_rate, so the frames dropped at 10 % are a subset of those dropped at 30 %
(nested drop sets). Periodic mode drops every ``period``-th frame (index + 1 divisible by it).
Dropped frames vanish from the sequence, its timestamps and its per-frame ground truth.
"""

from __future__ import annotations

import numpy as np

from sal_modules.base import Perturbation
from sal_modules.context import ModuleContext
from sal_modules.params import Param

__all__ = ["FrameDrop"]


class FrameDrop(Perturbation):
    """Drop frames at ``drop_rate`` (random, nested across rates) or every ``period``-th frame."""

    name = "frame_drop"
    version = 1
    summary = "Frames lost in transport: random (nested across rates) or periodic"
    drops_frames = True

    drop_rate = Param(
        0.1,
        unit="",
        min=0.0,
        max=1.0,
        searchable=True,
        worse="higher",
        doc="share of the frames dropped in random mode (0.3 drops 30 %)",
    )
    mode = Param("random", domain="choice", choices=("random", "periodic"), doc="random or periodic drops")
    period = Param(10, domain="integer", unit="frames", min=1, max=100_000, doc="periodic mode: drop every period-th frame")

    def unchanged_reason(self) -> str | None:
        if self.mode == "random" and self.drop_rate == 0.0:
            return "drop_rate = 0 drops no frame"
        return None

    def setup(self, context: ModuleContext) -> None:
        super().setup(context)
        self._uniform: dict[int, float] = {}

    def keep_frame(self, index: int) -> bool:
        if self.mode == "periodic":
            return (index + 1) % self.period != 0
        return self._draw(index) >= self.drop_rate

    def _draw(self, index: int) -> float:
        """u_index ~ U[0, 1), from the seed and the index only."""
        if index not in self._uniform:
            self._uniform[index] = float(self.rng(index).random())
        return self._uniform[index]

    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray | None:
        return image if self.keep_frame(index) else None
