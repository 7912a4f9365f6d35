"""``snow``: Gunn-Marshall snowflakes drifting down slowly, soft and white, with snow haze.

Mathematical formulation
------------------------
Flake sizes (Gunn & Marshall 1958) as melted diameter D (mm) at water-equivalent rate R (mm/h)::

    N(D) = N0 exp(-Lambda D),   N0 = 3800 R^-0.87 m^-3 mm^-1,   Lambda = 2.55 R^-0.48 mm^-1

truncated at D = 5 mm. A flake is ``size_ratio`` = 3.5 times wider than its melted drop, falls
at v = 0.8 D_f^0.16 m/s (Locatelli & Hobbs 1974, aggregates; D_f = 3.5 D the flake diameter in
mm: about 1 to 1.2 m/s) and drifts sideways at a random speed within +-0.5 m/s on top of the
wind. Flakes are white (albedo 0.9) lit by the sky, so their radiance is 0.9 times the airlight,
and block 90 % of the light behind them. Extinction by all flakes (geometric optics, efficiency
2, flake cross-section) makes snow reduce visibility far more than rain of the same water
equivalent. Rendering and common random numbers: ``precipitation.Precipitation``. Unlike rain,
Gunn-Marshall has fewer small flakes at higher rates, so only flakes large enough to see over
the whole range are nested across rates; the number and size of visible flakes still grow.
"""

from __future__ import annotations

import numpy as np

from sal_modules.params import Param
from sal_modules.weather.precipitation import Precipitation

__all__ = ["Snow"]

#: Albedo of fresh snow flakes.
ALBEDO = 0.9


class Snow(Precipitation):
    """Snowflakes (Gunn-Marshall sizes, slow fall, sideways drift) and snow haze, from depth."""

    name = "snow"
    version = 1
    summary = "Snow: Gunn-Marshall flakes, slow fall with drift, soft white depth-aware flakes plus snow extinction"

    intensity_mm_h = Param(2.0, unit="mm/h", min=0.1, max=30.0, searchable=True, worse="higher", doc="snowfall rate, water equivalent")

    size_ratio = 3.5
    max_diameter_mm = 5.0
    opacity = 0.9
    drift_mps = 0.5
    min_alpha = 0.2

    def size_distribution(self, rate: float) -> tuple[float, float]:
        return 3800.0 * rate**-0.87, 2.55 * rate**-0.48

    def fall_speed(self, diameter_mm: np.ndarray) -> np.ndarray:
        return 0.8 * (self.size_ratio * np.maximum(np.asarray(diameter_mm), 1e-3)) ** 0.16

    def particle_radiance(self, image: np.ndarray, airlight: np.ndarray) -> np.ndarray:
        return ALBEDO * airlight
