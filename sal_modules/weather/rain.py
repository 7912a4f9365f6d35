"""``rain``: Marshall-Palmer drops falling at terminal velocity, as streaks, with rain haze.

Mathematical formulation
------------------------
Drop sizes (Marshall & Palmer 1948), D in mm, R in mm/h::

    N(D) = N0 exp(-Lambda D),   N0 = 8000 m^-3 mm^-1,   Lambda = 4.1 R^-0.21 mm^-1

truncated at D = 6 mm (larger drops break up). Terminal velocity (Atlas et al. 1973)::

    v(D) = 9.65 - 10.3 exp(-0.6 D)   m/s   (floored at 0.1 m/s for D < 0.12 mm)

A drop at depth Z (m) leaves a streak v T f / Z px long (T = ``exposure_ms``, f in px) and
D f / Z px wide; it covers each pixel of its streak for about D / v of the exposure. A drop
refracts light from a ~165 degree field of view (Garg & Nayar 2004): half of it the scene in
front of the camera, half the sky, so its radiance is taken as the mean of the frame's linear
radiance and the airlight. Extinction by all drops (geometric optics, efficiency 2) gives
beta(R) within ~15 % of the empirical 0.312 R^0.67 km^-1. Streak rendering, defocus, occlusion,
stereo and the common random numbers are those of ``precipitation.Precipitation``.
"""

from __future__ import annotations

import numpy as np

from sal_modules.colour import srgb_to_linear
from sal_modules.params import Param
from sal_modules.weather.precipitation import Precipitation

__all__ = ["Rain"]


class Rain(Precipitation):
    """Rain streaks (Marshall-Palmer sizes, Atlas fall speed) and rain haze, from depth."""

    name = "rain"
    version = 1
    summary = "Rain: Marshall-Palmer drops as depth-aware streaks (exposure, defocus, stereo) plus rain extinction"

    intensity_mm_h = Param(25.0, unit="mm/h", min=0.1, max=300.0, searchable=True, worse="higher", doc="rain rate")

    size_ratio = 1.0
    max_diameter_mm = 6.0
    opacity = 1.0
    drift_mps = 0.0
    min_alpha = 0.02

    def size_distribution(self, rate: float) -> tuple[float, float]:
        return 8000.0, 4.1 * rate**-0.21

    def fall_speed(self, diameter_mm: np.ndarray) -> np.ndarray:
        return np.maximum(9.65 - 10.3 * np.exp(-0.6 * np.asarray(diameter_mm)), 0.1)

    def particle_radiance(self, image: np.ndarray, airlight: np.ndarray) -> np.ndarray:
        scene = srgb_to_linear(image[::4, ::4]).reshape(-1, 3).mean(axis=0)
        return 0.5 * (scene + airlight)
