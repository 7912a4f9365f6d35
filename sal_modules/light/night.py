"""``night``: physically based low light: less light, auto-exposure, sensor noise, colour of the lamps.

Mathematical formulation
------------------------
The clean frames were taken at ``daylight_lux`` (lx) with a base exposure and unit gain. At
``illuminance_lux`` E the scene sends s = E / daylight_lux of the photons. The camera's
auto-exposure wants the compensation k = 1 / s; it lengthens the exposure first, then raises
the gain::

    t = min(k, max_exposure_factor)           exposure time / daylight exposure time
    g = clip(k / t, 1, max_gain)              analogue gain
    p = s t                                   photons collected / daylight photons
    f = g p = min(1, E / E_min),              E_min = daylight_lux / (max_exposure_factor max_gain)

(a) From daylight down to daylight_lux / max_exposure_factor the longer exposure makes up for
everything (p = 1: the image is unchanged; the motion blur of the longer exposure is left to
``motion_blur``). (b) Down to E_min the mean brightness is kept (f = 1) while the collected
photons fall (p < 1) and the gain rises, so the relative noise grows as 1 / sqrt(p).
(c) Below E_min the frame also darkens, linearly in E (f = E / E_min).

The lamps' colour: linear radiance ``L = srgb_to_linear(I)`` is scaled by the von Kries gains
w(T) of black-body light at ``colour_temperature_k`` for a camera white-balanced for 6500 K
(6500 K: no shift; grey cameras ignore it). The mean of the new frame is ``m = f w L``; the
sensor (``sal_modules.light.sensor``) adds the missing Poisson shot and Gaussian read noise
of collecting p L full_well_e electrons at gain g, clips, quantises to ``adc_bits`` and
encodes sRGB. The noise field is drawn per frame and stream from
``rng("shot", stream, index)`` and scaled by the parameters, so darker settings give a
stronger version of the same noise.

ONNX backend
------------
With ``model`` (a user-supplied day-to-night image-translation network, e.g. a CycleGAN
exported to ONNX: input and output NCHW float32 RGB, values in ``model_range``), the
network's output replaces the darkening and colour shift f w L: the network decides how the
night looks (a grey camera records its luminance). The sensor noise that ``illuminance_lux`` implies (same g, p, f) is still added,
so ``illuminance_lux`` still sets the severity. The frame is resized to a multiple of 8 (or
the model's fixed input size), normalised to x = 2 I - 1 ("-1..1") or x = I ("0..1"), and the
output is denormalised as I = 0.5 y + 0.5 (resp. y), clipped to 0..1 and resized back.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from sal_modules.colour import srgb_to_linear
from sal_modules.context import ModuleContext
from sal_modules.errors import ModuleError
from sal_modules.light.sensor import (
    LUMA,
    SensorModule,
    adc_bits_param,
    full_well_param,
    read_noise_param,
    white_balance,
)
from sal_modules.params import Param
from sal_modules.work_buffers import scratch

__all__ = ["Exposure", "ImageTranslator", "Night", "auto_exposure"]


@dataclass(frozen=True)
class Exposure:
    """The auto-exposure's answer to a light level (see the module docstring).

    Attributes:
        time: exposure time / daylight exposure time (t).
        gain: analogue gain (g).
        photons: photons collected / daylight photons (p = s t).
        brightness: mean brightness / clean brightness (f = g p).
    """

    time: float
    gain: float
    photons: float
    brightness: float


def auto_exposure(lux: float, daylight_lux: float, max_exposure_factor: float, max_gain: float) -> Exposure:
    """Exposure time and gain a camera picks at ``lux`` when ``daylight_lux`` needs factor 1."""
    share = lux / daylight_lux
    time = min(1.0 / share, max_exposure_factor)
    gain = min(max(1.0 / (share * time), 1.0), max_gain)
    photons = share * time
    return Exposure(time, gain, photons, gain * photons)


class Night(SensorModule):
    """Low light: auto-exposure at ``illuminance_lux``, shot and read noise, warm lamp light."""

    name = "night"
    version = 1
    summary = "Low light in lux: auto-exposure and gain, Poisson shot + read noise, lamp colour; optional ONNX day-to-night model"

    illuminance_lux = Param(
        5.0,
        unit="lx",
        min=0.01,
        max=150_000.0,
        searchable=True,
        worse="lower",
        scale="log",
        search_range=(0.01, 100_000.0),
        doc="scene illuminance (street lighting ~5-20 lx, full moon ~0.2 lx); unchanged frames from daylight_lux / max_exposure_factor up",
    )
    daylight_lux = Param(10_000.0, unit="lx", min=1.0, max=150_000.0, doc="illuminance the clean frames were taken at")
    max_exposure_factor = Param(
        8.0,
        unit="x",
        min=1.0,
        max=10_000.0,
        doc="longest exposure time the auto-exposure allows, over the daylight exposure",
    )
    max_gain = Param(64.0, unit="x", min=1.0, max=100_000.0, doc="highest analogue gain the auto-exposure allows")
    colour_temperature_k = Param(
        3000.0,
        unit="K",
        min=2000.0,
        max=15_000.0,
        doc="colour temperature of the lighting (sodium ~2000 K, warm LED ~3000 K, 6500 K = no shift)",
    )
    full_well_e = full_well_param()
    read_noise_e = read_noise_param()
    adc_bits = adc_bits_param()
    model = Param(None, domain="text", optional=True, doc="ONNX day-to-night image-translation model file (replaces the darkening)")
    model_range = Param("-1..1", domain="choice", choices=("-1..1", "0..1"), doc="value range of the model's input and output")

    def setup(self, context: ModuleContext) -> None:
        super().setup(context)
        self._exposure = self.exposure()
        grey = context.sequence.grayscale
        gains = np.ones(3, np.float32) if grey else white_balance(self.colour_temperature_k)
        self._scale = (gains * np.float32(self._exposure.brightness)).astype(np.float32)
        self._translator = ImageTranslator(self.model, self.model_range, self.name) if self.model is not None else None

    def cleanup(self) -> None:
        self._translator = None
        super().cleanup()

    def unchanged_reason(self) -> str | None:
        """Down to daylight_lux / max_exposure_factor the longer exposure makes up for all the
        light lost: brightness and noise stay those of the clean frames."""
        full = self.daylight_lux / self.max_exposure_factor
        if self.model is None and self.illuminance_lux >= full:
            return (
                f"at illuminance_lux = {self.illuminance_lux:g} lx the auto-exposure makes up for all the light lost "
                f"(down to daylight_lux / max_exposure_factor = {self.daylight_lux:g} / {self.max_exposure_factor:g} = {full:g} lx "
                f"the frames keep their brightness and noise; only the lamp colour changes)"
            )
        return None

    def exposure(self) -> Exposure:
        """The auto-exposure at the configured light level."""
        return auto_exposure(self.illuminance_lux, self.daylight_lux, self.max_exposure_factor, self.max_gain)

    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray:
        self.ready_context()
        if self._translator is not None:
            mean = srgb_to_linear(self._translator(image))
            if self.ready_context().sequence.grayscale:  # a grey camera sees the network's night in grey
                mean[:] = (mean @ LUMA.astype(np.float32))[..., None]
        else:
            mean = srgb_to_linear(image, out=scratch("night.linear", image.shape))
            mean *= self._scale
        return self.read_out(mean, index, stream, self._exposure.gain, self._exposure.brightness)


class ImageTranslator:
    """An ONNX image-to-image network on 8-bit RGB frames (onnxruntime, loaded once).

    Args:
        path: the model file.
        value_range: ``"-1..1"`` or ``"0..1"``, the range of the network's input and output.
        owner: module name for error messages.
    """

    def __init__(self, path: str, value_range: str, owner: str = "night"):
        self.path = Path(path).expanduser()
        self.value_range = value_range
        if not self.path.is_file():
            raise ModuleError(f"{owner}: model file {self.path} does not exist")
        try:
            import onnxruntime as ort
        except ImportError:
            raise ModuleError(f"{owner}: the ONNX backend needs onnxruntime; install it with pip install 'pytest-sal[onnx]'") from None
        try:
            self.session = ort.InferenceSession(str(self.path), providers=ort.get_available_providers())
        except Exception as exc:  # onnxruntime raises its own exception types for bad files
            raise ModuleError(f"{owner}: cannot load ONNX model {self.path}: {exc}") from None
        model_input = self.session.get_inputs()[0]
        self.input_name = model_input.name
        shape = list(model_input.shape)
        if len(shape) != 4 or (isinstance(shape[1], int) and shape[1] != 3):
            raise ModuleError(f"{owner}: model {self.path} must take an NCHW RGB image, its input is {shape}")
        self.fixed_size = (shape[2], shape[3]) if isinstance(shape[2], int) and isinstance(shape[3], int) else None
        self.owner = owner

    def input_size(self, height: int, width: int) -> tuple[int, int]:
        """(height, width) fed to the network: its fixed size, else the nearest multiples of 8."""
        if self.fixed_size is not None:
            return self.fixed_size
        return max(8, int(round(height / 8.0)) * 8), max(8, int(round(width / 8.0)) * 8)

    def __call__(self, image: np.ndarray) -> np.ndarray:
        """The network's output for ``image`` (HxWx3 uint8) as float32 sRGB 0..1 at the input size."""
        height, width = image.shape[:2]
        h, w = self.input_size(height, width)
        x = image.astype(np.float32) * np.float32(1.0 / 255.0)
        if (h, w) != (height, width):
            x = _resize(x, h, w)
        if self.value_range == "-1..1":
            x = x * 2.0 - 1.0
        y: Any = self.session.run(None, {self.input_name: np.ascontiguousarray(x.transpose(2, 0, 1)[None])})[0]
        if y.ndim != 4 or y.shape[1] != 3:
            raise ModuleError(f"{self.owner}: model {self.path} must return an NCHW RGB image, it returned shape {list(y.shape)}")
        out = np.ascontiguousarray(y[0].transpose(1, 2, 0), dtype=np.float32)
        if self.value_range == "-1..1":
            out = out * np.float32(0.5) + np.float32(0.5)
        if out.shape[:2] != (height, width):
            out = _resize(out, height, width)
        return np.clip(out, 0.0, 1.0, out=out)


def _resize(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """``image`` resampled to ``height`` x ``width``: bicubic, area averaging when it shrinks by more than 1.5."""
    shrink = image.shape[0] * image.shape[1] > 2.25 * height * width
    return cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_CUBIC)
