"""Monocular depth (placeholder until the ONNX provider lands)."""

from __future__ import annotations

import numpy as np

from sal_adapters.sequence import Sequence
from sal_modules.depth.base import DepthProvider

__all__ = ["MonoDepth"]


class MonoDepth(DepthProvider):
    name = "mono"

    def __init__(self, model: object):
        self.model = model

    def unavailable(self, sequence: Sequence) -> str | None:
        return "not implemented yet"

    def compute(self, sequence: Sequence, position: int, stream: str) -> np.ndarray:
        raise NotImplementedError
