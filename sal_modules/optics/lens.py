"""Shared machinery of lens effects: one static pattern per lens, and alpha compositing.

A lens effect (dirt, cracks) sits on the glass, so it does not move with the scene: its
pattern is built once per sequence for each lens, from ``self.rng("pattern", stream)``, which
makes the left and right lenses independent and every frame of one lens identical.
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from sal_modules.base import Perturbation
from sal_modules.context import ModuleContext

__all__ = ["LensEffect", "Overlay"]


class LensEffect(Perturbation):
    """A perturbation with a static per-lens pattern, built when the first frame needs it.

    Subclasses implement ``build(stream, height, width)`` (any object, built from
    ``self.rng("pattern", stream)`` only) and use ``self.pattern(stream, image)`` in ``apply``.
    ``setup`` builds nothing: a chain set up to be checked (``sal perturb --dry-run``, 255
    steps of ``cracked_lens``) holds no image-sized pattern.
    """

    def setup(self, context: ModuleContext) -> None:
        super().setup(context)
        self._patterns: dict[tuple[str, int, int], Any] = {}

    def cleanup(self) -> None:
        self._patterns = {}
        super().cleanup()

    @abstractmethod
    def build(self, stream: str, height: int, width: int) -> Any:
        """The static pattern of lens ``stream`` for ``height`` x ``width`` images."""

    def pattern(self, stream: str, image: np.ndarray) -> Any:
        """The pattern of lens ``stream`` at the size of ``image`` (built on first use)."""
        self.ready_context()
        return self._pattern(stream, image.shape[0], image.shape[1])

    def _pattern(self, stream: str, height: int, width: int) -> Any:
        key = (stream, int(height), int(width))
        if key not in self._patterns:
            self._patterns[key] = self.build(stream, int(height), int(width))
        return self._patterns[key]


@dataclass(frozen=True)
class Overlay:
    """A static alpha overlay: ``I_out = I (1 - alpha) + colour alpha``.

    Attributes:
        alpha: HxW float32 coverage in 0..1.
        colour: HxWx3 uint8 colour of what covers the scene (dirt, crack glints); ``None``
            when the colour changes per frame and is given to ``over``.
    """

    alpha: np.ndarray
    colour: np.ndarray | None = None
    keep: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "keep", (1.0 - self.alpha).astype(np.float32))

    @classmethod
    def uniform(cls, alpha: np.ndarray, rgb: tuple[float, ...]) -> Overlay:
        """An overlay of one colour."""
        colour = np.empty((*alpha.shape, 3), np.uint8)
        colour[:] = np.clip(np.round(rgb), 0, 255).astype(np.uint8)
        return cls(alpha.astype(np.float32), colour)

    def over(self, image: np.ndarray, colour: np.ndarray | None = None) -> np.ndarray:
        """The overlay (in ``colour``, default its own) over ``image`` (HxWx3 uint8), a new image."""
        top = self.colour if colour is None else colour
        if top is None:
            raise ValueError("this Overlay has no colour of its own: pass one to over()")
        return cv2.blendLinear(image, top, self.keep, self.alpha)
