"""The scenes and image helpers the weather tests share (test_weather_fog.py,
test_weather_precipitation.py, test_weather_real_frames.py)."""

from __future__ import annotations

from functools import cache

import numpy as np

from sal_adapters import Sequence, open_dataset
from sal_modules import ModuleContext
from sal_modules.colour import srgb_decode
from sal_modules.depth import NativeDepth
from sal_modules.weather.precipitation import Particles

__all__ = ["linear", "one_particle", "ready", "streak_extent", "urban"]


@cache
def urban(frames: int = 3) -> Sequence:
    return open_dataset("synthetic", scene="urban", frames=frames, sensor="stereo")


def ready(module, sequence: Sequence, seed: int = 1, depth=None):  # type: ignore[no-untyped-def]
    """``module`` set up on ``sequence`` as the pipeline would (native depth by default)."""
    module.setup(ModuleContext(sequence=sequence, seed=seed, depth=depth or NativeDepth().lookup(sequence)))
    return module


def linear(image: np.ndarray) -> np.ndarray:
    return srgb_decode(np.asarray(image) / 255.0)


# -- rain and snow: one particle at a known place -----------------------------------------------
def one_particle(z: float, diameter_mm: float, x: float = 0.0, y: float = 0.0) -> Particles:
    return Particles(ids=np.zeros(1, np.int64), position=np.array([[x, y, z]]), diameter_mm=np.array([diameter_mm]), drift_mps=np.zeros(1))


def streak_extent(alpha: np.ndarray) -> tuple[float, float, float]:
    """Length (px, rows above half the plateau), centroid column and row of one vertical streak."""
    rows = alpha.sum(axis=1)
    length = float((rows > 0.5 * rows.max()).sum())
    v, u = np.mgrid[: alpha.shape[0], : alpha.shape[1]]
    return length, float((alpha * u).sum() / alpha.sum()), float((alpha * v).sum() / alpha.sum())
