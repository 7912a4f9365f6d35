"""A camera sensor model shared by ``night`` and ``sensor_noise`` (and the sRGB curve for ``sun_glare``).

Mathematical formulation
------------------------
Images are sRGB-encoded. Linear radiance, relative to the clean frame's white, is
``L = srgb_to_linear(I)`` (IEC 61966-2-1: L = I/12.92 for I <= 0.04045, else
((I + 0.055)/1.055)^2.4).

Reference exposure: the clean frames were taken in daylight at base gain, with their white
(L = 1) at the full well, so a pixel collected ``mu_0 = L * full_well_e`` electrons. A darker
scene, a shorter exposure or a higher ISO collects a share ``p`` of those photons
(mu = p * mu_0 electrons, Poisson shot noise: variance mu) and the camera amplifies by the
gain ``g``; the read noise (``read_noise_e``, e-, Gaussian) is added before the amplifier.
In output units (fraction of the white level) the frame's mean is ``m = f L`` with the
brightness factor f = g p, and its variance::

    var_target = (g / FW)^2 (mu + sigma_r^2) = (g / FW) m + (g sigma_r / FW)^2

The clean frame already carries the noise of its own exposure (p = g = 1), scaled by f:
f^2 (L / FW + sigma_r^2 / FW^2). Only the missing variance is added::

    var_add = a m + b,   a = (g - f) / FW,   b = (g^2 - f^2) sigma_r^2 / FW^2     (clipped at 0)

so the daylight exposure (p = g = f = 1) is the identity and the output follows Poisson
statistics: in electrons, var = mu + sigma_r^2 for the whole frame.

Noise draw: y = m + sqrt(var_add) z with a fixed standard-normal field z per frame and stream
(``standard_normals``; the Gaussian approximation of Poisson noise, exact in mean and variance; it loses the
discreteness of a few electrons). Because z does not depend on the parameters, a darker
scene or higher ISO scales the same noise pattern (common random numbers), and the output
changes monotonically with severity. Exact Poisson draws would need a different random
pattern per mean. Grey cameras get one field for all three channels (they stay grey); colour
cameras independent noise per channel (a Bayer sensor before demosaicing; the spatial
correlation demosaicing adds is not modelled).

ADC: y is clipped to [0, 1] (saturation, black clamp) and quantised to ``adc_bits`` bits,
DN = round(y (2^bits - 1)); the sRGB curve then maps DN to the 8-bit output through a table.
With 12 bits the daylight exposure round-trips every 8-bit value exactly.

Colour of the light: a black body of temperature T seen by a camera white-balanced for 6500 K
scales linear RGB by ``w(T) = rgb(T) / rgb(6500 K)`` (von Kries), with rgb from the Planckian
locus (Kim et al. 2002 cubic fit, 1667..25000 K) through the sRGB/XYZ matrix, normalised to
unit luminance (0.2126 R + 0.7152 G + 0.0722 B = 1).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from sal_modules.base import Perturbation
from sal_modules.colour import encode_table
from sal_modules.params import Param
from sal_modules.work_buffers import scratch

__all__ = [
    "LUMA",
    "Sensor",
    "SensorModule",
    "adc_bits_param",
    "full_well_param",
    "linear_to_srgb",
    "read_noise_param",
    "standard_normals",
    "white_balance",
]

#: Rec. 709 / sRGB luminance weights of linear R, G, B.
LUMA = np.array([0.2126, 0.7152, 0.0722])

#: XYZ -> linear sRGB (D65).
_XYZ_TO_RGB = np.array([[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]])


def quantise(linear: np.ndarray, bits: int) -> np.ndarray:
    """8-bit sRGB of linear light clipped to [0, 1] and quantised to ``bits`` (<= 16) bits;
    ``linear`` (float32) is overwritten."""
    top = float((1 << bits) - 1)
    linear *= np.float32(top)
    linear += np.float32(0.5)
    np.clip(linear, 0.0, top, out=linear)
    return encode_table(1 << bits)[linear.astype(np.uint16)]


def linear_to_srgb(linear: np.ndarray) -> np.ndarray:
    """8-bit sRGB of linear light (values outside [0, 1] clip); ``linear`` (float32) is overwritten."""
    return quantise(linear, 16)


def white_balance(kelvin: float) -> np.ndarray:
    """von Kries gains (float32 R, G, B; unit luminance) of black-body light at ``kelvin`` seen
    by a camera white-balanced for 6500 K."""
    gains = _planck_rgb(kelvin) / _planck_rgb(6500.0)
    return (gains / float(LUMA @ gains)).astype(np.float32)


def _planck_rgb(kelvin: float) -> np.ndarray:
    """Linear sRGB (Y = 1) of the Planckian locus at ``kelvin`` (Kim et al. 2002)."""
    t = float(kelvin)
    if t <= 4000.0:
        x = -0.2661239e9 / t**3 - 0.2343589e6 / t**2 + 0.8776956e3 / t + 0.179910
    else:
        x = -3.0258469e9 / t**3 + 2.1070379e6 / t**2 + 0.2226347e3 / t + 0.240390
    if t <= 2222.0:
        y = -1.1063814 * x**3 - 1.34811020 * x**2 + 2.18555832 * x - 0.20219683
    elif t <= 4000.0:
        y = -0.9549476 * x**3 - 1.37418593 * x**2 + 2.09137015 * x - 0.16748867
    else:
        y = 3.0817580 * x**3 - 5.87338670 * x**2 + 3.75112997 * x - 0.37001483
    rgb = _XYZ_TO_RGB @ np.array([x / y, 1.0, (1.0 - x - y) / y])
    return np.maximum(rgb, 1e-3)


@lru_cache(maxsize=1)
def _normal_quantiles() -> np.ndarray:
    """The 2^16 mid-point quantiles of N(0, 1), scaled to unit variance (float32)."""
    from scipy.special import ndtri

    table = ndtri((np.arange(65536) + 0.5) / 65536)
    return (table / table.std()).astype(np.float32)


def standard_normals(rng: np.random.Generator, height: int, width: int, grey: bool) -> np.ndarray:
    """A float32 N(0, 1) field, HxWx1 for a grey camera (the same noise in R, G, B), else HxWx3.

    Drawn by inverting the normal CDF on 16-bit uniform integers (a table of 2^16 quantiles,
    tails cut at 4.3 sigma): four times faster than ``standard_normal`` and as good for
    image noise.
    """
    uniform = rng.integers(0, 65536, (height, width, 1 if grey else 3), dtype=np.uint16)
    return np.take(_normal_quantiles(), uniform)


@dataclass(frozen=True)
class Sensor:
    """Pixel and read-out figures of the camera that took the clean frames.

    Attributes:
        full_well_e: electrons at the clean frame's white (saturation at base gain).
        read_noise_e: read noise (e- RMS) before the amplifier.
        adc_bits: resolution of the analogue-to-digital converter.
    """

    full_well_e: float
    read_noise_e: float
    adc_bits: int = 12

    def missing_variance(self, gain: float, brightness: float) -> tuple[float, float]:
        """``(a, b)`` of the variance ``a m + b`` (output units) to add to a frame of mean ``m``
        exposed at ``gain`` with brightness factor ``f = gain p`` (see the module docstring)."""
        fw = self.full_well_e
        a = (gain - brightness) / fw
        b = (gain**2 - brightness**2) * self.read_noise_e**2 / fw**2
        return max(a, 0.0), max(b, 0.0)

    def capture(self, mean: np.ndarray, gain: float, brightness: float, normals: np.ndarray | None) -> np.ndarray:
        """8-bit sRGB read out of linear ``mean`` (float32 HxWx3, overwritten) with the missing
        shot and read noise drawn from ``normals`` (``None`` when nothing is missing)."""
        a, b = self.missing_variance(gain, brightness)
        if normals is not None and (a > 0.0 or b > 0.0):
            noise = np.multiply(mean, np.float32(a), out=scratch("sensor.noise", mean.shape))
            noise += np.float32(b)
            np.maximum(noise, 0.0, out=noise)
            np.sqrt(noise, out=noise)
            noise *= normals
            mean += noise
        return quantise(mean, self.adc_bits)

    def needs_noise(self, gain: float, brightness: float) -> bool:
        """Whether this exposure adds any noise (the daylight exposure adds none)."""
        a, b = self.missing_variance(gain, brightness)
        return a > 0.0 or b > 0.0


def full_well_param() -> Param:
    """The ``full_well_e`` parameter every sensor-based module declares."""
    return Param(10_000.0, unit="e-", min=10.0, max=1e7, doc="electrons at the clean frame's white (full well at base gain)")


def read_noise_param() -> Param:
    """The ``read_noise_e`` parameter every sensor-based module declares."""
    return Param(2.5, unit="e-", min=0.0, max=1000.0, doc="read noise before the amplifier (e- RMS)")


def adc_bits_param() -> Param:
    """The ``adc_bits`` parameter every sensor-based module declares."""
    return Param(12, unit="bit", min=8, max=16, domain="integer", doc="resolution of the analogue-to-digital converter")


class SensorModule(Perturbation):
    """Base of modules that re-expose the clean frame on the ``Sensor``; subclasses declare
    ``full_well_e = full_well_param()``, ``read_noise_e = read_noise_param()`` and
    ``adc_bits = adc_bits_param()``."""

    @property
    def sensor(self) -> Sensor:
        return Sensor(self.params["full_well_e"], self.params["read_noise_e"], self.params["adc_bits"])

    def read_out(self, mean: np.ndarray, index: int, stream: str, gain: float, brightness: float) -> np.ndarray:
        """8-bit sRGB of linear ``mean`` (HxWx3 float32, overwritten) exposed at ``gain`` with
        brightness factor ``brightness``; the noise field comes from ``self.rng("shot", stream, index)``."""
        sensor = self.sensor
        normals = None
        if sensor.needs_noise(gain, brightness):
            grey = self.ready_context().sequence.grayscale
            normals = standard_normals(self.rng("shot", stream, index), mean.shape[0], mean.shape[1], grey)
        return sensor.capture(mean, gain, brightness, normals)
