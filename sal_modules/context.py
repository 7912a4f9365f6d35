"""What a perturbation module may know about the sequence it perturbs: ``ModuleContext``.

The pipeline builds one context per sequence and hands it to every module's ``setup``. Its
``rng`` is the only source of randomness a module may use: a generator derived from the
sequence seed and the keys given, never from parameter values (common random numbers).
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from sal_adapters.camera import Camera
from sal_adapters.sequence import Sequence
from sal_modules.errors import ModuleError

__all__ = ["STREAMS", "DepthLookup", "ModuleContext"]

#: Image streams of a sequence: the (left) camera and, for stereo, the right camera.
STREAMS: tuple[str, ...] = ("left", "right")

#: ``depth(index, stream) -> float32 HxW metres (0 = invalid)`` of the clean sequence.
DepthLookup = Callable[[int, str], np.ndarray]


@dataclass(frozen=True)
class ModuleContext:
    """What a module may know about the sequence it perturbs.

    Attributes:
        sequence: the clean input sequence (camera, fps, timestamps, ground truth, frames).
        seed: the perturbation seed; every random pattern derives from it.
        depth: depth of the clean frames by dataset index and stream, or ``None`` when the
            chain needs none.
    """

    sequence: Sequence
    seed: int = 0
    depth: DepthLookup | None = None
    _positions: dict[int, int] = field(default_factory=dict, repr=False, compare=False)

    @property
    def camera(self) -> Camera:
        return self.sequence.camera

    @property
    def fps(self) -> float:
        return self.sequence.fps

    @property
    def frame_count(self) -> int:
        return len(self.sequence)

    def camera_for(self, stream: str) -> Camera:
        """Intrinsics of ``stream`` (the right camera's when the sequence has one)."""
        if stream == "right" and self.camera.right is not None:
            return self.camera.right
        return self.camera

    def position(self, index: int) -> int:
        """Position in ``sequence`` of the frame with dataset index ``index``."""
        if not self._positions:
            self._positions.update({r.index: p for p, r in enumerate(self.sequence.records)})
        try:
            return self._positions[index]
        except KeyError:
            raise ModuleError(f"frame index {index} is not in sequence {self.sequence.name!r}") from None

    def pose(self, index: int) -> np.ndarray | None:
        """Camera-to-world 4x4 pose (m) of frame ``index`` from per-frame ground truth, else ``None``."""
        gt = self.sequence.groundtruth
        if gt is None or not self.sequence.groundtruth_is_per_frame:
            return None
        return gt.select([self.position(index)]).matrices[0]

    def rng(self, *keys: str | int) -> np.random.Generator:
        """A generator that depends only on ``seed`` and ``keys`` (strings hashed with CRC-32)."""
        words = [self.seed & 0xFFFFFFFF] + [zlib.crc32(k.encode()) if isinstance(k, str) else int(k) & 0xFFFFFFFF for k in keys]
        return np.random.default_rng(np.random.SeedSequence(words))
