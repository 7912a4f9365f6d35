"""Smooth 3-D gradient noise on a random lattice, for heterogeneous fog density.

Mathematical formulation
------------------------
Perlin gradient noise: the integer lattice Z^3 carries random unit gradients g_ijk (drawn once
from a generator, periodic with ``period`` cells per axis). At a point p (in lattice units) with
cell corner c = floor(p) and offset f = p - c::

    n(p) = sum over the 8 corners k of  w(f - k) (g_{c+k} . (f - k)),
    w(x) = prod_axes (1 - s(|x|)),   s(t) = 6 t^5 - 15 t^4 + 10 t^3   (quintic fade)

n is C2-smooth, zero at every lattice point and has zero mean. Its standard deviation over space
is ``RAW_STD`` (0.191, measured for unit gradients); ``__call__`` divides by it, so the noise has
unit standard deviation.
Features have about the lattice spacing; a field with feature size L (m) is ``noise(x / L)``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["RAW_STD", "GradientNoise"]

#: Standard deviation of 3-D gradient noise with unit gradients (empirical, 1e6 points, 3 seeds).
RAW_STD = 0.1909


class GradientNoise:
    """Vectorised 3-D gradient noise with zero mean and unit standard deviation.

    Args:
        rng: the generator that draws the gradients (the only randomness).
        period: lattice cells per axis before the pattern repeats.
    """

    def __init__(self, rng: np.random.Generator, period: int = 64):
        gradients = rng.normal(size=(period, period, period, 3))
        gradients /= np.linalg.norm(gradients, axis=-1, keepdims=True)
        # one wrapped layer on the high side, so the corner c + 1 needs no modulo
        padded = np.pad(gradients, ((0, 1), (0, 1), (0, 1), (0, 0)), mode="wrap").astype(np.float32)
        self._components = [np.ascontiguousarray(padded[..., axis]).ravel() for axis in range(3)]
        self._period = int(period)

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """Noise at ``points`` (..., 3), given in lattice units; float32 of shape (...)."""
        p = np.asarray(points)
        shape = p.shape[:-1]
        p = p.reshape(-1, 3)
        cell = np.floor(p)
        f = (p - cell).astype(np.float32)
        side = self._period + 1
        c = cell.astype(np.int64) % self._period
        base = ((c[:, 0] * side + c[:, 1]) * side + c[:, 2]).astype(np.int32)
        fx, fy, fz = (np.ascontiguousarray(f[:, axis]) for axis in range(3))
        gx, gy, gz = self._components
        dots = []
        for dx in (0, 1):
            for dy in (0, 1):
                for dz in (0, 1):
                    corner = base + (dx * side * side + dy * side + dz)
                    dots.append(np.take(gx, corner) * (fx - dx) + np.take(gy, corner) * (fy - dy) + np.take(gz, corner) * (fz - dz))
        u, v, w = (t * t * t * (t * (t * 6.0 - 15.0) + 10.0) for t in (fx, fy, fz))
        along_z = [a + w * (b - a) for a, b in zip(dots[0::2], dots[1::2])]
        along_y = [a + v * (b - a) for a, b in zip(along_z[0::2], along_z[1::2])]
        value = along_y[0] + u * (along_y[1] - along_y[0])
        return (value * np.float32(1.0 / RAW_STD)).reshape(shape)
