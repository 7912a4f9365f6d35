"""Stereo depth (placeholder until semi-global matching lands)."""

from __future__ import annotations

import numpy as np

from sal_adapters.sequence import Sequence
from sal_modules.depth.base import DepthProvider

__all__ = ["StereoDepth"]


class StereoDepth(DepthProvider):
    name = "stereo"

    def unavailable(self, sequence: Sequence) -> str | None:
        return "not implemented yet"

    def compute(self, sequence: Sequence, position: int, stream: str) -> np.ndarray:
        raise NotImplementedError
