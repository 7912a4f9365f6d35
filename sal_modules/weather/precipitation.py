"""The particle engine shared by ``rain`` and ``snow``: falling particles seen by the camera.

Mathematical formulation
------------------------
Sizes. A subclass gives an exponential size distribution of the melted (equivalent-volume)
diameter D (mm) at precipitation rate R (mm/h), truncated at D_max::

    N(D) = N0(R) exp(-Lambda(R) D)          (m^-3 mm^-1),   0 < D < D_max
    G_R(D) = int_D^Dmax N = N0 / Lambda (exp(-Lambda D) - exp(-Lambda D_max))   (m^-3)

A particle of visible diameter s D (s: ``size_ratio``, 1 for drops, ~3.5 for flakes) at depth Z
(m) falling at v(D) (m/s, subclass) during the exposure T (s) with focal length f (px) covers::

    w = s D f / Z  (px wide),   l = |v| T f / Z  (px long),   b = f a / Z  (defocus disk, px;
    entrance pupil a, focus at infinity)

Its exposure-integrated coverage ("ink", px^2) is opacity * pi/4 * w^2 whatever T (a drop covers
a pixel for w / (l / T) seconds of T), spread over about W (l + W) px with
W = sqrt(w^2 + b^2 + 1). Its peak coverage is ink / (W (l + W)). A particle is drawn when the
peak reaches ``min_alpha`` (per kind: faint rain streaks stay visible as coherent lines, a snow
flake must be a clear dot); that defines the smallest visible diameter D_vis(Z). Smaller or
farther particles are not drawn one by one: they form the haze term below.

Common random numbers. Particles are a Poisson process in the union of both cameras' view
frusta between ``Z_NEAR_M`` and ``Z_FAR_M``, marked with a rank y (m^-3): at rate R a particle
exists and is visible iff y < y_R(Z) = G_R(D_vis(Z)), and its size is D_R(y) = G_R^-1(y)
(the y-th largest per m^3). For rain G_R grows with R at every D, so the particles at 50 mm/h
are a subset of those at 200 mm/h and each is larger (longer, wider streak). The process is
drawn in bands of R (``BANDS`` log-spaced edges over the parameter's range), each from its own
generator keyed by frame index and band, so a rate only draws the bands up to itself and the
draws never depend on parameter values. Particles are drawn per frame index only, in the left
camera frame, and projected into each stream's camera (``camera_for`` and the stereo extrinsics):
both images of a stereo pair see the same particles.

Rendering. Each particle is a streak from P - V T/2 to P + V T/2 (V = fall speed plus wind and
drift), sampled every <= 0.75 px and splatted bilinearly with its ink into the level of an image
pyramid whose blur (sigma 0.6 px per level) matches its size and defocus (sigma ~ W / 4).
Samples behind the scene (Z > depth at that pixel) are dropped. Levels are blurred, resized up
and summed to a coverage density S; the coverage is alpha = 1 - exp(-S) (overlaps of a Poisson
field). Haze: the whole size distribution extinguishes light with efficiency 2 (geometric
optics): beta(R) = 2 (pi / 4) s^2 int N(D) D^2 dD (1/m); for Marshall-Palmer rain this matches
the empirical beta = 0.312 R^0.67 km^-1 (within ~15 % from 1 to 300 mm/h). In linear light::

    I = (J t + A (1 - t)) (1 - alpha) + L_p alpha,    t = exp(-beta r)

with A the airlight (estimated once per sequence, as for fog), L_p the particle radiance and r
the distance along the line of sight; pixels without depth (sky) are at ``sky_distance_m``,
by default the cloud base, ``SKY_DISTANCE_M`` = 1 km, where the precipitation comes from.
Indoors unknown depth is a window or a wall a few metres away: give the room's size there, or
those pixels turn to the airlight.
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import cv2
import numpy as np

from sal_modules.base import Perturbation
from sal_modules.context import ModuleContext
from sal_modules.params import Param
from sal_modules.weather.fog import (
    blend_srgb,
    first_frame_airlight,
    ray_lengths,
)
from sal_modules.work_buffers import scratch

__all__ = ["Particles", "Precipitation"]

#: Nearest particle distance (m): in front of the lens hood.
Z_NEAR_M = 0.1
#: Farthest particle distance drawn (m); beyond it particles are haze only.
Z_FAR_M = 200.0
#: Distance (m) of pixels without depth (sky): the cloud base the precipitation falls from.
SKY_DISTANCE_M = 1000.0
#: Number of intensity bands of the particle process.
BANDS = 24
#: Pyramid levels (blur sigma 0.6 .. 0.6 * 2^5 px).
LEVELS = 6
_SIGMA = 0.6
_STEP_PX = 0.75
_MAX_SAMPLES = 400


@dataclass(frozen=True)
class Particles:
    """The particles of one frame, in the left camera frame at mid-exposure.

    Attributes:
        ids: unique id per particle (band * 2^32 + number in band), stable across rates.
        position: (N, 3) metres (x right, y down, z forward).
        diameter_mm: melted (equivalent-volume) diameter at the module's rate.
        drift_mps: sideways speed of each particle on top of the wind (m/s).
    """

    ids: np.ndarray
    position: np.ndarray
    diameter_mm: np.ndarray
    drift_mps: np.ndarray

    def __len__(self) -> int:
        return len(self.ids)


class Precipitation(Perturbation):
    """Falling particles with streaks, defocus, occlusion by the scene and haze (rain, snow)."""

    needs_depth = True

    #: visible diameter / melted diameter
    size_ratio: ClassVar[float]
    #: largest melted diameter (mm)
    max_diameter_mm: ClassVar[float]
    #: share of the light behind a particle that it blocks while covering a pixel
    opacity: ClassVar[float]
    #: random sideways speed, uniform in +-drift (m/s)
    drift_mps: ClassVar[float]
    #: peak coverage from which a particle is drawn one by one (fainter ones are haze)
    min_alpha: ClassVar[float]

    exposure_ms = Param(5.0, unit="ms", min=0.1, max=100.0, doc="exposure time: streak length")
    wind_mps = Param(0.0, unit="m/s", min=-40.0, max=40.0, doc="wind speed along the camera's x axis (right = positive)")
    aperture_mm = Param(2.0, unit="mm", min=0.0, max=50.0, doc="entrance pupil diameter: defocus of near particles (focus at infinity)")
    sky_distance_m = Param(
        SKY_DISTANCE_M, unit="m", min=0.1, max=1e5, doc="distance of pixels without depth: the cloud base outdoors, the room's size indoors"
    )

    # -- particle physics, per subclass --------------------------------------------------------
    @abstractmethod
    def size_distribution(self, rate: float) -> tuple[float, float]:
        """(N0 in m^-3 mm^-1, Lambda in mm^-1) of the melted diameter at ``rate`` mm/h."""

    @abstractmethod
    def fall_speed(self, diameter_mm: np.ndarray) -> np.ndarray:
        """Terminal fall speed (m/s) of particles of melted diameter ``diameter_mm``."""

    @abstractmethod
    def particle_radiance(self, image: np.ndarray, airlight: np.ndarray) -> np.ndarray:
        """Linear RGB radiance of a particle in front of ``image`` (uint8 sRGB)."""

    @property
    def rate(self) -> float:
        """The precipitation rate (mm/h)."""
        return float(self.params["intensity_mm_h"])

    # -- size distribution ---------------------------------------------------------------------
    def number_above(self, rate: float, diameter_mm: np.ndarray) -> np.ndarray:
        """G_R(D): particles per m^3 with melted diameter above ``diameter_mm``."""
        n0, lam = self.size_distribution(rate)
        d = np.minimum(np.asarray(diameter_mm, dtype=np.float64), self.max_diameter_mm)
        return n0 / lam * (np.exp(-lam * d) - np.exp(-lam * self.max_diameter_mm))

    def diameter_of_rank(self, rate: float, rank: np.ndarray) -> np.ndarray:
        """D_R(y) = G_R^-1(y): the melted diameter (mm) of the particle of rank y (m^-3)."""
        n0, lam = self.size_distribution(rate)
        return -np.log(np.asarray(rank) * lam / n0 + np.exp(-lam * self.max_diameter_mm)) / lam

    def extinction(self, rate: float) -> float:
        """Extinction coefficient (1/m) of all particles: Q_ext = 2 times the cross-section."""
        n0, lam = self.size_distribution(rate)
        x = lam * self.max_diameter_mm
        second_moment = 2.0 / lam**3 * (1.0 - np.exp(-x) * (1.0 + x + 0.5 * x * x))  # int D^2 e^-lam D, mm^3
        return float(2.0 * np.pi / 4.0 * self.size_ratio**2 * n0 * second_moment * 1e-6)

    # -- life cycle ----------------------------------------------------------------------------
    def setup(self, context: ModuleContext) -> None:
        super().setup(context)
        self.airlight = first_frame_airlight(context)
        camera = context.camera
        stereo = camera.T_lr
        shift = 0.0 if stereo is None else float(stereo[0, 3])
        self._extrinsics = {"left": np.eye(4), "right": np.eye(4) if stereo is None else np.linalg.inv(stereo)}
        self._lengths: dict[tuple[str, tuple[int, int]], np.ndarray] = {}
        self._cache: tuple[int, Particles] | None = None
        spec = type(self).parameters()["intensity_mm_h"]
        assert spec.min is not None and spec.max is not None
        self._edges = np.geomspace(spec.min, spec.max, BANDS)
        z = np.geomspace(Z_NEAR_M, Z_FAR_M, 256)
        self._z = z
        self._d_vis = self._smallest_visible(z, camera.fx)
        # frustum cross-section (m) at depth z, widened by the baseline and the particles' travel
        exposure = self.exposure_ms / 1000.0
        speed = float(self.fall_speed(np.array([self.max_diameter_mm]))[0])
        margin_x = (abs(self.wind_mps) + self.drift_mps) * exposure / 2 + self.aperture_mm / 2000.0
        margin_y = speed * exposure / 2 + self.aperture_mm / 2000.0
        self._x_range = (
            -camera.cx / camera.fx * z + min(shift, 0.0) - margin_x,
            (camera.width - camera.cx) / camera.fx * z + max(shift, 0.0) + margin_x,
        )
        self._y_range = (-camera.cy / camera.fy * z - margin_y, (camera.height - camera.cy) / camera.fy * z + margin_y)
        area = (self._x_range[1] - self._x_range[0]) * (self._y_range[1] - self._y_range[0])
        # rank envelope: the largest y_R(z) over rates up to each band edge (fine grid in R)
        fine = np.geomspace(spec.min, spec.max, BANDS * 8 - 7)
        ranks = np.maximum.accumulate(np.array([self.number_above(r, self._d_vis) for r in fine]), axis=0)
        self._envelope = np.vstack([np.zeros_like(z), ranks[::8]])  # (BANDS + 1, len(z))
        density = area * np.diff(self._envelope, axis=0)  # particles per m of depth, per band
        cumulative = np.concatenate(
            [np.zeros((BANDS, 1)), np.cumsum(0.5 * (density[:, 1:] + density[:, :-1]) * np.diff(z), axis=1)], axis=1
        )
        self._expected = cumulative[:, -1]
        self._cdf = cumulative / np.maximum(self._expected[:, None], 1e-300)

    def cleanup(self) -> None:
        self._cache = None
        super().cleanup()

    def _smallest_visible(self, z: np.ndarray, focal_px: float) -> np.ndarray:
        """D_vis(z): smallest melted diameter (mm) whose peak coverage reaches ``min_alpha``."""
        d = np.linspace(0.0, self.max_diameter_mm, 512)[1:]
        peak = self.peak_coverage(d[None, :], z[:, None], focal_px)
        visible = np.maximum.accumulate(peak, axis=1) >= self.min_alpha
        first = np.argmax(visible, axis=1)
        return np.where(visible.any(axis=1), d[first], np.inf)

    def peak_coverage(self, diameter_mm: np.ndarray, z: np.ndarray, focal_px: float) -> np.ndarray:
        """Peak exposure-integrated coverage of a particle at depth ``z`` (m)."""
        w = self.size_ratio * diameter_mm * 1e-3 * focal_px / z
        speed = np.hypot(self.fall_speed(diameter_mm), abs(self.wind_mps) + self.drift_mps / 2)
        length = speed * self.exposure_ms * 1e-3 * focal_px / z
        blur = self.aperture_mm * 1e-3 * focal_px / z
        width = np.sqrt(w * w + blur * blur + 1.0)
        return np.minimum(self.opacity, self.opacity * np.pi / 4 * w * w / (width * (length + width)))

    # -- particles -----------------------------------------------------------------------------
    def particles(self, index: int) -> Particles:
        """The visible particles of frame ``index`` at the module's rate (cached per frame)."""
        if self._cache is not None and self._cache[0] == index:
            return self._cache[1]
        rate = self.rate
        z_grid = self._z
        needed = int(np.searchsorted(self._edges, rate, side="left")) + 1  # bands up to the one holding rate
        parts = []
        for band in range(min(needed, BANDS)):
            rng = self.rng("particles", index, band)
            count = int(rng.poisson(self._expected[band]))
            u = rng.random((5, count))
            z = np.interp(u[0], self._cdf[band], z_grid)
            low = np.interp(z, z_grid, self._envelope[band])
            rank = low + u[1] * (np.interp(z, z_grid, self._envelope[band + 1]) - low)
            x = np.interp(z, z_grid, self._x_range[0]) + u[2] * np.interp(z, z_grid, self._x_range[1] - self._x_range[0])
            y = np.interp(z, z_grid, self._y_range[0]) + u[3] * np.interp(z, z_grid, self._y_range[1] - self._y_range[0])
            ids = np.int64(band) << 32 | np.arange(count, dtype=np.int64)
            parts.append((ids, np.stack([x, y, z], axis=1), rank, (2.0 * u[4] - 1.0) * self.drift_mps))
        ids, position, rank, drift = (np.concatenate(column) for column in zip(*parts))
        keep = rank < np.interp(position[:, 2], z_grid, self.number_above(rate, self._d_vis))
        result = Particles(ids[keep], position[keep], self.diameter_of_rank(rate, rank[keep]), drift[keep])
        self._cache = (index, result)
        return result

    # -- rendering -----------------------------------------------------------------------------
    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray:
        assert depth is not None
        alpha = self.coverage(self.particles(index), depth, stream)
        key = (stream, depth.shape)
        if key not in self._lengths:
            self._lengths[key] = ray_lengths(self.ready_context().camera_for(stream), depth.shape)
        distance = cv2.multiply(depth.astype(np.float32, copy=False), self._lengths[key], dst=scratch("precipitation.t", depth.shape))
        distance[depth <= 0] = self.sky_distance_m
        t = cv2.exp(cv2.multiply(distance, -self.extinction(self.rate), dst=distance), dst=distance)  # type: ignore[call-overload]  # cv2 takes a number operand; its stubs want an array
        clear = cv2.subtract(1.0, alpha, dst=scratch("precipitation.clear", depth.shape))  # type: ignore[call-overload]  # cv2 takes a number operand; its stubs want an array
        gain = cv2.multiply(t, clear, dst=t)
        haze = cv2.subtract(clear, gain, dst=clear)  # (1 - t)(1 - alpha)
        return blend_srgb(image, gain, [(haze, self.airlight), (alpha, self.particle_radiance(image, self.airlight))])

    def coverage(self, particles: Particles, depth: np.ndarray, stream: str) -> np.ndarray:
        """alpha (float32 HxW): the share of the exposure particles cover each pixel of ``stream``."""
        camera = self.ready_context().camera_for(stream)
        h, w = depth.shape
        to_stream = self._extrinsics[stream]
        exposure = self.exposure_ms / 1000.0
        d = particles.diameter_mm
        velocity = np.stack([self.wind_mps + particles.drift_mps, self.fall_speed(d), np.zeros_like(d)], axis=1) @ to_stream[:3, :3].T
        centre = particles.position @ to_stream[:3, :3].T + to_stream[:3, 3]
        z = np.maximum(centre[:, 2], 1e-3)
        ends = [centre - velocity * exposure / 2, centre + velocity * exposure / 2]
        (u0, v0), (u1, v1) = (
            (camera.fx * e[:, 0] / np.maximum(e[:, 2], 1e-3) + camera.cx, camera.fy * e[:, 1] / np.maximum(e[:, 2], 1e-3) + camera.cy)
            for e in ends
        )
        size = self.size_ratio * d * 1e-3 * camera.fx / z
        blur = self.aperture_mm * 1e-3 * camera.fx / z
        sigma = np.sqrt(size * size + blur * blur) / 4.0
        level = np.clip(np.rint(np.log2(np.maximum(sigma, _SIGMA) / _SIGMA)), 0, LEVELS - 1).astype(np.int64)
        reach = 3.0 * _SIGMA * 2.0**level + 1.0
        inside = (
            (np.maximum(u0, u1) > -reach)
            & (np.minimum(u0, u1) < w + reach)
            & (np.maximum(v0, v1) > -reach)
            & (np.minimum(v0, v1) < h + reach)
            & (centre[:, 2] > 0)
        )
        ink = self.opacity * np.pi / 4.0 * size * size
        u0, v0, u1, v1, z, level, ink = (a[inside] for a in (u0, v0, u1, v1, z, level, ink))
        # samples along every streak
        scale = 0.5**level
        count = np.minimum(np.ceil(np.hypot(u1 - u0, v1 - v0) * scale / _STEP_PX), _MAX_SAMPLES).astype(np.int64) + 1
        owner = np.repeat(np.arange(len(count)), count)
        start = np.cumsum(count) - count
        frac = (np.arange(owner.size) - start[owner] + 0.5) / count[owner]
        su = u0[owner] + frac * (u1 - u0)[owner]
        sv = v0[owner] + frac * (v1 - v0)[owner]
        # occlusion by the scene: the sample's pixel has a surface nearer than the particle
        pu = np.clip(np.rint(su), 0, w - 1).astype(np.int64)
        pv = np.clip(np.rint(sv), 0, h - 1).astype(np.int64)
        surface = depth.ravel().take(pv * w + pu)
        seen = z[owner] <= np.where(surface > 0, surface, self.sky_distance_m)
        owner, su, sv = owner[seen], su[seen], sv[seen]
        weight = (ink * scale * scale / count)[owner]
        density = self._splat(su, sv, weight, level[owner], (h, w))
        return cv2.subtract(1.0, cv2.exp(cv2.multiply(density, -1.0, dst=density), dst=density), dst=density)  # type: ignore[call-overload]  # cv2 takes a number operand; its stubs want an array

    @staticmethod
    def _splat(u: np.ndarray, v: np.ndarray, weight: np.ndarray, level: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
        """Coverage density (float32 HxW): bilinear splats into pyramid levels, blurred, summed.

        Each level is stored with a one-pixel border, so the four corners of a splat are
        ``i, i + 1, i + W, i + W + 1`` without bounds tests; the border is dropped afterwards."""
        h, w = shape
        sizes = [(int(np.ceil(h / 2**k)), int(np.ceil(w / 2**k))) for k in range(LEVELS)]
        padded = np.array([(a + 2) * (b + 2) for a, b in sizes])
        offsets = np.concatenate([[0], np.cumsum(padded)])
        lh = np.array([s[0] for s in sizes])[level]
        lw = np.array([s[1] for s in sizes])[level]
        x = (u + 0.5) * (lw / w) - 0.5
        y = (v + 0.5) * (lh / h) - 0.5
        inside = (x > -1.0) & (x < lw) & (y > -1.0) & (y < lh)
        x, y, weight, level, lw = x[inside], y[inside], weight[inside], level[inside], lw[inside]
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = x - x0, y - y0
        stride = lw + 2
        first = offsets[level] + (y0.astype(np.int64) + 1) * stride + (x0.astype(np.int64) + 1)
        index = np.concatenate([first, first + 1, first + stride, first + stride + 1])
        wx0, wx1 = weight * (1.0 - fx), weight * fx
        value = np.concatenate([wx0 * (1.0 - fy), wx1 * (1.0 - fy), wx0 * fy, wx1 * fy])
        flat = scratch("precipitation.splat", (int(offsets[-1]),))
        flat.fill(0.0)
        np.add.at(flat, index, value.astype(np.float32))
        total = None
        for k in reversed(range(LEVELS)):
            lh_k, lw_k = sizes[k]
            plane = flat[offsets[k] : offsets[k + 1]].reshape(lh_k + 2, lw_k + 2)[1:-1, 1:-1]
            layer = cv2.GaussianBlur(plane, (0, 0), _SIGMA)
            total = layer if total is None else cv2.add(cv2.resize(total, (lw_k, lh_k), interpolation=cv2.INTER_LINEAR), layer)
        assert total is not None
        return total
