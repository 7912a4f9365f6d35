"""``fog``: Koschmieder's law with the scene's depth, homogeneous or in smooth 3-D patches.

Mathematical formulation
------------------------
Light from a surface at distance r (m, along the line of sight) reaches the camera attenuated
and mixed with airlight A (the colour of the fog at infinite distance)::

    beta = 3.912 / V          (1/m; V = meteorological visibility, m: contrast falls to 2 %)
    t    = exp(-beta r)       (transmission)
    I    = J t + A (1 - t)    (J: clear radiance, I: foggy radiance)

Blending happens in **linear light**: sRGB-encoded inputs are decoded to linear radiance in
[0, 1] (IEC 61966-2-1), blended in float32 and encoded back, rounding to the nearest code.
The contrast of two surfaces at distance V is therefore 2 % of their clear contrast in linear
radiance (``srgb_to_linear`` of the output), which is what Koschmieder's visibility means.
r is the Euclidean distance: a pixel (u, v) with depth Z (m, along the optical axis) is at
r = Z sqrt(1 + ((u - cx)/fx)^2 + ((v - cy)/fy)^2). Pixels without depth (0, e.g. sky) are at
``sky_distance_m``; by default infinitely far, so t = 0 and they show the airlight.

Atmospheric light: ``atmospheric_light`` (sRGB-encoded, 0..1) or, when null, estimated once per
sequence from the first clean frame (``estimate_atmospheric_light``): the mean colour of the
0.1 % pixels with the brightest dark channel (minimum over RGB and a 15x15 window), taken among
the sky pixels (no depth) when there are enough of them.

Heterogeneous fog (``heterogeneity`` k > 0): the extinction coefficient varies in space as
beta(x) = beta max(0, 1 + k n(x / L)) with n a smooth zero-mean, unit-deviation 3-D gradient
noise (``noise.GradientNoise``) of feature size L = ``noise_scale_m``. So k is the relative
standard deviation of the fog density. The optical depth is integrated along the ray:
tau = beta r m(r), m(r) = (1/r) int_0^r max(0, 1 + k n(o + s d)) ds, with camera centre o and
unit ray d in **world coordinates** when the sequence has per-frame ground-truth poses (the
fog patches stay fixed in the world while the camera moves), else in the (left) camera frame.
m is smooth, so it is evaluated on a coarse grid of rays (every ``GRID_PX`` px) at distance
shells s_j = (a / b)(exp(b j) - 1), a = L / 6, b = 0.06 (L / 6 apart near the camera, 6 %
of the distance far away, up to the farthest surface or 10 V), cumulated with the trapezoid
rule, and interpolated (bilinear across the grid, linear across shells) at the distances of a
4x reduced map, which is resized to full resolution. Against a dense per-pixel integration the
median error of tau is about 2 %.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from sal_adapters.camera import Camera
from sal_modules.base import Perturbation
from sal_modules.colour import DECODE_TABLE, encode_table, srgb_decode, srgb_to_linear
from sal_modules.context import ModuleContext
from sal_modules.params import Param
from sal_modules.weather.noise import GradientNoise
from sal_modules.work_buffers import scratch

__all__ = [
    "Fog",
    "blend_srgb",
    "camera_to_world",
    "estimate_atmospheric_light",
    "first_frame_airlight",
    "ray_lengths",
]

#: Spacing (px) of the coarse grid on which heterogeneous fog integrates its rays.
GRID_PX = 24
#: The mean density m(r) is interpolated per pixel of a map this many times smaller, then resized.
MEAN_SUBSAMPLE = 4
#: Beyond this many visibilities the transmission is below 1e-5 for any plausible density.
_MAX_DISTANCE_IN_V = 10.0
_SHELL_GROWTH = 0.06


def blend_srgb(image: np.ndarray, gain: np.ndarray, terms: list[tuple[np.ndarray, Any]]) -> np.ndarray:
    """Blend in linear light: ``encode(decode(image) * gain + sum(weight * colour))``.

    Args:
        image: HxWx3 uint8 sRGB.
        gain: HxW float32 factor on the scene radiance (e.g. the transmission).
        terms: (HxW float32 weight, linear RGB colour) pairs added on top (airlight, particles).

    Returns:
        A new HxWx3 uint8 sRGB image, rounded to the nearest code. Works plane by plane in
        reused buffers (cv2), several times faster than broadcasting over interleaved colour.
    """
    shape = gain.shape
    plane, value = scratch("blend.plane", shape, np.uint8), scratch("blend.value", shape)
    code, codes = scratch("blend.code", shape, np.uint16), scratch("blend.codes", shape + (3,), np.uint16)
    for c in range(3):
        cv2.extractChannel(image, c, dst=plane)
        cv2.LUT(plane, DECODE_TABLE, dst=value)
        cv2.multiply(value, gain, dst=value)
        for weight, colour in terms:
            cv2.scaleAdd(weight, float(colour[c]), value, dst=value)
        cv2.addWeighted(value, 65535.0, value, 0.0, 0.0, dst=code, dtype=cv2.CV_16U)
        cv2.insertChannel(code, codes, c)
    return np.take(encode_table(65536), codes, out=np.empty(shape + (3,), np.uint8))


def estimate_atmospheric_light(image: np.ndarray, depth: np.ndarray | None = None) -> np.ndarray:
    """Linear RGB airlight of a clear frame: mean colour of the 0.1 % pixels with the brightest
    dark channel, among the sky pixels (depth 0) when at least that many exist."""
    linear = srgb_to_linear(image)
    dark = cv2.erode(linear.min(axis=2), np.ones((15, 15), np.uint8)).ravel()
    count = max(1, int(round(1e-3 * dark.size)))
    candidates = np.arange(dark.size)
    if depth is not None:
        sky = np.flatnonzero(np.asarray(depth).ravel() <= 0)
        if sky.size >= count:
            candidates = sky
    brightest = candidates[np.argpartition(dark[candidates], candidates.size - count)[-count:]]
    return linear.reshape(-1, 3)[brightest].mean(axis=0).astype(np.float32)


def ray_lengths(camera: Camera, shape: tuple[int, int]) -> np.ndarray:
    """Per pixel, the distance (m) to a point at depth 1 m: sqrt(1 + x^2 + y^2) (float32 HxW)."""
    h, w = shape
    x = ((np.arange(w, dtype=np.float32) - camera.cx) / camera.fx) ** 2
    y = ((np.arange(h, dtype=np.float32) - camera.cy) / camera.fy) ** 2
    return np.sqrt(1.0 + x[None, :] + y[:, None]).astype(np.float32)


class _RayGrid:
    """Coarse grid of unit rays of one camera, and where the pixels of the reduced-resolution
    map (1 / ``MEAN_SUBSAMPLE``) on which m(r) is evaluated fall in that grid."""

    def __init__(self, camera: Camera, shape: tuple[int, int]):
        h, w = shape
        self.shape = (h, w)
        self.lengths = ray_lengths(camera, shape)
        self.gw, self.gh = int(np.ceil((w - 1) / GRID_PX)) + 1, int(np.ceil((h - 1) / GRID_PX)) + 1
        gu, gv = np.meshgrid(np.linspace(0, w - 1, self.gw), np.linspace(0, h - 1, self.gh))
        rays = np.stack([(gu - camera.cx) / camera.fx, (gv - camera.cy) / camera.fy, np.ones_like(gu)], axis=-1)
        self.directions = (rays / np.linalg.norm(rays, axis=-1, keepdims=True)).reshape(-1, 3)
        self.small = (int(np.ceil(w / MEAN_SUBSAMPLE)), int(np.ceil(h / MEAN_SUBSAMPLE)))  # cv2 (width, height)
        # centres of the reduced pixels in full-resolution pixels (cv2.resize convention), in grid units
        x = (np.arange(self.small[0]) + 0.5) * (w / self.small[0]) - 0.5
        y = (np.arange(self.small[1]) + 0.5) * (h / self.small[1]) - 0.5
        uc = np.clip(x * (self.gw - 1) / max(w - 1, 1), 0, self.gw - 1).astype(np.float32)
        vc = np.clip(y * (self.gh - 1) / max(h - 1, 1), 0, self.gh - 1).astype(np.float32)
        self.map_u = np.ascontiguousarray(np.broadcast_to(uc[None, :], self.small[::-1]))
        self.map_v = np.ascontiguousarray(np.broadcast_to(vc[:, None], self.small[::-1]))


class Fog(Perturbation):
    """Koschmieder fog from depth, in linear light; optional smooth heterogeneous density."""

    name = "fog"
    version = 1
    summary = "Fog by Koschmieder's law with depth (beta = 3.912 / visibility), optionally in smooth 3-D patches"
    needs_depth = True

    visibility_m = Param(
        50.0,
        unit="m",
        min=1.0,
        max=100_000.0,
        searchable=True,
        worse="lower",
        doc="meteorological visibility: distance at which contrast falls to 2 %",
    )
    atmospheric_light = Param(
        None,
        domain="vector",
        length=3,
        min=0.0,
        max=1.0,
        optional=True,
        doc="airlight colour, sRGB-encoded RGB in 0..1; null = estimated once from the first frame",
    )
    heterogeneity = Param(0.0, min=0.0, max=1.0, doc="relative standard deviation of the fog density (0 = homogeneous)")
    noise_scale_m = Param(20.0, unit="m", min=1.0, max=10_000.0, doc="feature size of the fog patches")
    sky_distance_m = Param(
        None,
        unit="m",
        min=0.0,
        max=1e7,
        optional=True,
        doc="distance of pixels without depth (sky); null = infinitely far (airlight only)",
    )

    def setup(self, context: ModuleContext) -> None:
        super().setup(context)
        if self.atmospheric_light is not None:
            self.airlight = srgb_decode(self.atmospheric_light).astype(np.float32)
        else:
            self.airlight = first_frame_airlight(context)
        self._grids: dict[tuple[str, tuple[int, int]], _RayGrid] = {}
        self._noise = GradientNoise(self.rng("density")) if self.heterogeneity > 0 else None

    def cleanup(self) -> None:
        self._grids = {}
        self._noise = None
        super().cleanup()

    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray:
        assert depth is not None
        t = self.transmission(depth, index, stream, out=scratch("fog.t", depth.shape))
        return blend_srgb(image, t, [(cv2.subtract(1.0, t, dst=scratch("fog.airlight", t.shape)), self.airlight)])  # type: ignore[call-overload]  # cv2 takes a number operand; its stubs want an array

    def transmission(self, depth: np.ndarray, index: int, stream: str, out: np.ndarray | None = None) -> np.ndarray:
        """t = exp(-tau) per pixel (float32 HxW) for the depth map of frame ``index``, written
        into ``out`` when given."""
        tau = self.optical_depth(depth, index, stream, out)
        np.minimum(tau, np.float32(80.0), out=tau)
        return cv2.exp(cv2.multiply(tau, -1.0, dst=tau), dst=tau)  # type: ignore[call-overload]  # cv2 takes a number operand; its stubs want an array

    def optical_depth(self, depth: np.ndarray, index: int, stream: str, out: np.ndarray | None = None) -> np.ndarray:
        """tau (float32 HxW) along each pixel's line of sight, written into ``out`` when given;
        +inf where the ray hits no surface and ``sky_distance_m`` is null."""
        grid = self._grid(stream, depth.shape)
        sky = depth <= 0
        distance = cv2.multiply(depth.astype(np.float32, copy=False), grid.lengths, dst=out)
        sky_distance = np.inf if self.sky_distance_m is None else self.sky_distance_m
        if np.isfinite(sky_distance):
            distance[sky] = sky_distance
        beta = 3.912 / self.visibility_m
        if self._noise is not None:
            cv2.multiply(distance, self._mean_density(distance, grid, index, stream), dst=distance, scale=beta)
        else:
            cv2.multiply(distance, beta, dst=distance)
        if not np.isfinite(sky_distance):
            distance[sky] = np.inf
        return distance

    # -- heterogeneous fog ---------------------------------------------------------------------
    def density(self, points: np.ndarray) -> np.ndarray:
        """Relative fog density max(0, 1 + k n(x / L)) at ``points`` (..., 3), in metres in the
        frame the rays are traced in (world with poses, else the left camera)."""
        if self._noise is None:
            return np.ones(np.shape(points)[:-1], dtype=np.float32)
        return np.maximum(0.0, 1.0 + self.heterogeneity * self._noise(np.asarray(points) / self.noise_scale_m))

    def _grid(self, stream: str, shape: tuple[int, int]) -> _RayGrid:
        key = (stream, (shape[0], shape[1]))
        if key not in self._grids:
            self._grids[key] = _RayGrid(self.ready_context().camera_for(stream), key[1])
        return self._grids[key]

    def _mean_density(self, distance: np.ndarray, grid: _RayGrid, index: int, stream: str) -> np.ndarray:
        """m(r) per pixel: the mean relative density along the ray up to the pixel's distance."""
        assert self._noise is not None
        scale = self.noise_scale_m
        a, b = scale / 6.0, _SHELL_GROWTH
        far = min(float(distance.max()), _MAX_DISTANCE_IN_V * self.visibility_m)
        count = max(2, int(np.ceil(np.log1p(b * max(far, a) / a) / b)) + 1)
        shells = (a / b) * np.expm1(b * np.arange(count))  # s_0 = 0
        to_world = camera_to_world(self.ready_context(), index, stream)
        rays = grid.directions @ to_world[:3, :3].T
        points = to_world[:3, 3] + shells[None, :, None] * rays[:, None, :]
        density = self.density(points)  # (rays, shells)
        steps = np.diff(shells)
        integral = np.concatenate([np.zeros((len(rays), 1)), np.cumsum(0.5 * (density[:, 1:] + density[:, :-1]) * steps, axis=1)], axis=1)
        mean = np.empty_like(density)
        mean[:, 0] = density[:, 0]
        mean[:, 1:] = integral[:, 1:] / shells[1:]
        # atlas (gh, count * gw): shell j occupies columns j * gw ... j * gw + gw - 1
        atlas = np.ascontiguousarray(mean.reshape(grid.gh, grid.gw, count).transpose(0, 2, 1).reshape(grid.gh, count * grid.gw)).astype(
            np.float32
        )
        small = cv2.resize(distance, grid.small, interpolation=cv2.INTER_AREA)
        shell = np.log1p(small * (b / a)) * (1.0 / b)
        shell = np.clip(shell, 0.0, count - 1.0001, out=shell)
        lower = np.floor(shell)
        weight = shell - lower
        map_u = lower * np.float32(grid.gw) + grid.map_u
        near = cv2.remap(atlas, map_u, grid.map_v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        far_side = cv2.remap(atlas, map_u + np.float32(grid.gw), grid.map_v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        mean_small = near + weight * (far_side - near)
        return cv2.resize(mean_small, grid.shape[::-1], interpolation=cv2.INTER_LINEAR)


def first_frame_airlight(context: ModuleContext) -> np.ndarray:
    """``estimate_atmospheric_light`` of the first clean frame of the sequence (left stream)."""
    first = context.sequence[0]
    depth = context.depth(first.index, "left") if context.depth is not None else None
    return estimate_atmospheric_light(first.image, depth)


def camera_to_world(context: ModuleContext, index: int, stream: str) -> np.ndarray:
    """Pose of ``stream``'s camera in frame ``index``: in the world with per-frame ground-truth
    poses (``context.pose``), else in the left camera's frame."""
    pose = context.pose(index)
    pose = np.eye(4) if pose is None else pose
    if stream == "right":
        stereo = context.camera.T_lr
        if stereo is not None:
            pose = pose @ stereo
    return pose
