"""``lens_soiling``: dirt particles on the lens, out of focus, static per sequence and per lens.

Mathematical formulation
------------------------
Particle p has a centre c_p (px), a radius r_p (px) and an opacity o_p (0..1). Dirt on the
front glass is far inside the near limit of the depth of field, so it images as a soft blob;
its coverage is Gaussian::

    alpha_p(x) = o_p exp(-|x - c_p|^2 / (2 sigma_p^2)),   sigma_p = blur r_p        (px)

``blur = 0.5`` is the classic sigma = r / 2. Overlapping particles do not add up (a thicker
smear does not become more opaque than its densest particle), so the coverage is the maximum,
and the dirt colour is alpha-blended over the scene::

    alpha = max_p alpha_p,      I_out = I (1 - alpha) + colour alpha

Common random numbers: each lens draws a pool of ``MAX_PARTICLES`` particles (uniform centre,
radius fraction u_r and opacity fraction u_o, mapped to the configured ranges as
r = r_min + u_r (r_max - r_min)) and uses the first ``particles`` of it, so 40 particles are a
subset of 80. The left and right lenses draw independent pools (``rng("pattern", stream)``).
The coverage map is built once per lens in ``setup``; a frame costs one blend.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sal_modules.optics.lens import LensEffect, Overlay
from sal_modules.params import Param

__all__ = ["LensSoiling"]

#: Size of the particle pool each lens draws (the maximum of ``particles``).
MAX_PARTICLES = 1000

#: A particle's Gaussian is evaluated within this many sigmas of its centre (e^-8 ~ 3e-4).
SUPPORT_SIGMAS = 4.0


class LensSoiling(LensEffect):
    """Soft dirt particles on each lens (nested across particle counts, independent per lens)."""

    name = "lens_soiling"
    version = 1
    summary = "Out-of-focus dirt particles on the lens, static per sequence, independent per lens"

    particles = Param(
        40,
        domain="integer",
        unit="particles",
        min=0,
        max=MAX_PARTICLES,
        searchable=True,
        worse="higher",
        doc="number of dirt particles on each lens (the first of a fixed pool)",
    )
    radius_px = Param((12.0, 40.0), domain="vector", length=2, unit="px", min=1.0, max=500.0, doc="particle radius range (min, max)")
    opacity = Param((0.3, 0.55), domain="vector", length=2, min=0.0, max=1.0, doc="particle peak opacity range (min, max)")
    colour = Param((40.0, 35.0, 30.0), domain="vector", length=3, unit="RGB", min=0.0, max=255.0, doc="dirt colour")
    blur = Param(0.5, min=0.05, max=3.0, doc="Gaussian sigma of a particle as a fraction of its radius (defocus of the dirt)")

    def check_params(self, params: dict[str, Any]) -> None:
        for key in ("radius_px", "opacity"):
            low, high = params[key]
            if low > high:
                raise self.param_error(f"{key} = {list(params[key])}: the minimum must not exceed the maximum")

    def build(self, stream: str, height: int, width: int) -> Overlay:
        """The dirt overlay of lens ``stream``: coverage alpha (0..1) in the dirt colour."""
        pool = self.rng("pattern", stream).random((MAX_PARTICLES, 4))
        cx, cy, u_r, u_o = pool[: self.particles].T
        (r_min, r_max), (o_min, o_max) = self.radius_px, self.opacity
        sigmas = self.blur * (r_min + u_r * (r_max - r_min))
        opacities = o_min + u_o * (o_max - o_min)
        alpha = np.zeros((height, width), np.float32)
        for x0, y0, sigma, o in zip(cx * width, cy * height, sigmas, opacities):
            reach = SUPPORT_SIGMAS * sigma
            x_lo, x_hi = max(int(x0 - reach), 0), min(int(x0 + reach) + 1, width)
            y_lo, y_hi = max(int(y0 - reach), 0), min(int(y0 + reach) + 1, height)
            if x_lo >= x_hi or y_lo >= y_hi:
                continue
            gx = np.exp(-((np.arange(x_lo, x_hi) + 0.5 - x0) ** 2) / (2 * sigma**2))
            gy = np.exp(-((np.arange(y_lo, y_hi) + 0.5 - y0) ** 2) / (2 * sigma**2))
            window = alpha[y_lo:y_hi, x_lo:x_hi]
            np.maximum(window, (o * gy[:, None] * gx[None, :]).astype(np.float32), out=window)
        return Overlay.uniform(alpha, self.colour)

    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray:
        return self.pattern(stream, image).over(image)
