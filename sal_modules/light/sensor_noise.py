"""``sensor_noise``: the shot and read noise of a high ISO setting at unchanged brightness.

Mathematical formulation
------------------------
The clean frames were taken at ``base_iso`` with their white at the full well. At ISO S the
same brightness comes from fewer photons and more gain::

    g = S / base_iso,    p = 1 / g     (photons collected / base photons),    f = g p = 1

so a pixel of linear value L (``srgb_to_linear``) collects mu = p L full_well_e electrons
(Poisson, variance mu) plus ``read_noise_e`` (Gaussian) before the amplifier. In output units
(fraction of white) the frame keeps its mean m = L and gets the variance
var = (g / FW) m + (g sigma_r / FW)^2; the clean frame already carries its base-ISO share
(m / FW + sigma_r^2 / FW^2), so the sensor model (``sal_modules.light.sensor``) adds::

    var_add = (g - 1) m / FW + (g^2 - 1) sigma_r^2 / FW^2

Relative noise therefore grows as sqrt(g) (shot) and g (read). S <= base_iso adds nothing.
The noise field comes from ``rng("shot", stream, index)``: a higher ISO scales the same
pattern (common random numbers). Grey cameras get the same noise in R, G and B.
"""

from __future__ import annotations

import numpy as np

from sal_modules.colour import srgb_to_linear
from sal_modules.light.sensor import (
    SensorModule,
    adc_bits_param,
    full_well_param,
    read_noise_param,
)
from sal_modules.params import Param
from sal_modules.work_buffers import scratch

__all__ = ["SensorNoise"]


class SensorNoise(SensorModule):
    """ISO noise: shot and read noise of gain ``iso / base_iso`` at the clean frame's brightness."""

    name = "sensor_noise"
    version = 1
    summary = "High-ISO sensor noise: Poisson shot + Gaussian read noise at gain iso/base_iso, brightness kept"

    iso = Param(
        800.0,
        unit="ISO",
        min=25.0,
        max=409_600.0,
        searchable=True,
        worse="higher",
        scale="log",
        search_range=(100.0, 25_600.0),
        doc="sensitivity setting",
    )
    base_iso = Param(100.0, unit="ISO", min=25.0, max=409_600.0, doc="ISO of the clean frames (unit gain)")
    full_well_e = full_well_param()
    read_noise_e = read_noise_param()
    adc_bits = adc_bits_param()

    @property
    def gain(self) -> float:
        """Analogue gain over the clean frames (1 at or below the base ISO)."""
        return max(self.iso / self.base_iso, 1.0)

    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray:
        self.ready_context()
        return self.read_out(srgb_to_linear(image, out=scratch("sensor_noise.linear", image.shape)), index, stream, self.gain, 1.0)
