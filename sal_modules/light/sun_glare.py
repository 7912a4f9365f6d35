"""``sun_glare``: veiling glare, the sun's disc and lens-flare ghosts from a low sun.

Mathematical formulation
------------------------
The sun's direction in the camera frame (x right, y down, z forward) from its azimuth a
(right of the optical axis) and elevation e (above it)::

    d = (cos e sin a, -sin e, cos e cos a)

The sun's illuminance on the lens (a plane normal to the optical axis) is
E_p = 1000 sun_illuminance_klux max(d_z, 0) lx: no light enters from behind the camera.

Veiling glare (Stiles-Holladay disability glare) at a pixel whose ray r makes the angle
theta = arccos(r . d) (degrees, from the intrinsics) with the sun::

    L_veil = 10 k E_p / max(theta, 1 deg)^2           (cd/m^2; k = ``veil_factor``, 1 = the eye)

The clean frames were exposed for ``daylight_lux``: a white surface has luminance
L_white = daylight_lux / pi, so the glare adds L_veil / L_white to the linear radiance
(``srgb_to_linear``). The sun's disc (angular radius 0.2665 deg, luminance E / Omega_sun,
Omega_sun = 6.8e-5 sr) is drawn where it falls on the image; it and everything within
theta < sqrt(10 k E_p / L_white) deg of it saturate (bloom). Lens-flare ghosts (double
reflections in the lens) lie on the line from the sun's image S through the principal point
C, at P_k = C + t_k (S - C), as soft discs of radius rho_k (fixed fractions of the image
diagonal). Ghost k returns a share R q_k of the light entering the lens
(R = ``ghost_reflectance``, q_k fixed relative strengths and tints), spread over its solid
angle Omega_k = pi (rho_k / f)^2, so its luminance is R q_k E_p / Omega_k; ghosts fade out
linearly while the sun moves up to 10 deg outside the field of view. All terms carry the
colour of sunlight (5800 K through a 6500 K white balance; grey cameras stay grey), are added
in linear light and clipped at the white level (the sensor saturates), then encoded back to
sRGB.

The glare depends on the sun direction only, so it is the same on every frame of a lens
(static per sequence, no jumping ghosts). With ``follow_pose`` the sun is fixed in the world
instead: its direction is given for the first frame and rotated into each frame's camera with
the ground-truth poses. The right camera of a stereo pair sees the sun through its own
rotation and intrinsics.
"""

from __future__ import annotations

import math

import numpy as np

from sal_modules.base import ModuleContext, Perturbation
from sal_modules.colour import srgb_to_linear
from sal_modules.errors import ModuleError
from sal_modules.light.sensor import LUMA, linear_to_srgb, white_balance
from sal_modules.params import Param

__all__ = ["GHOSTS", "SunGlare", "sun_direction"]

#: Angular radius of the sun (deg).
SUN_RADIUS_DEG = 0.2665

#: Smallest angle (deg) the Stiles-Holladay law is evaluated at.
MIN_ANGLE_DEG = 1.0

#: Ghosts: (t along S -> C, radius / image diagonal, relative strength q, RGB tint).
GHOSTS: tuple[tuple[float, float, float, tuple[float, float, float]], ...] = (
    (0.45, 0.020, 1.0, (1.0, 0.85, 0.60)),
    (-0.25, 0.035, 0.6, (0.60, 1.0, 0.70)),
    (-0.60, 0.070, 0.5, (0.70, 0.80, 1.0)),
    (-1.00, 0.045, 0.8, (1.0, 0.70, 0.90)),
    (-1.50, 0.110, 0.4, (0.80, 1.0, 0.85)),
)

#: Ghosts fade out while the sun moves this far (deg) outside the field of view.
GHOST_FADE_DEG = 10.0


def sun_direction(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit vector to the sun in the camera frame (x right, y down, z forward)."""
    a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
    return np.array([math.cos(e) * math.sin(a), -math.sin(e), math.cos(e) * math.cos(a)])


class SunGlare(Perturbation):
    """A low sun near or in the view: veiling glare, saturated disc, flare ghosts."""

    name = "sun_glare"
    version = 1
    summary = "Sun glare: Stiles-Holladay veiling glare, sun disc and lens-flare ghosts from the sun direction and illuminance"

    sun_illuminance_klux = Param(
        100.0, unit="klx", min=0.0, max=150.0, searchable=True, worse="higher",
        doc="illuminance of the sun normal to its rays (direct sun ~100 klx, low sun ~10-50 klx)",
    )
    sun_azimuth_deg = Param(20.0, unit="deg", min=-180.0, max=180.0, doc="sun direction right of the optical axis")
    sun_elevation_deg = Param(8.0, unit="deg", min=-90.0, max=90.0, doc="sun direction above the optical axis")
    daylight_lux = Param(10_000.0, unit="lx", min=1.0, max=150_000.0, doc="illuminance the clean frames were exposed for (white = daylight_lux/pi cd/m^2)")
    veil_factor = Param(0.3, unit="", min=0.0, max=100.0, doc="lens scatter k in L = 10 k E / theta^2 (1 = the human eye; clean lenses < 1, dirty windscreens > 1)")
    ghost_reflectance = Param(5e-5, unit="", min=0.0, max=0.05, doc="share of the light the strongest flare ghost returns (coated lens ~5e-5; 0: no ghosts)")
    follow_pose = Param(False, domain="flag", doc="keep the sun fixed in the world with the ground-truth poses (direction given for the first frame)")

    def setup(self, context: ModuleContext) -> None:
        super().setup(context)
        self._rays: dict[tuple[str, int, int], np.ndarray] = {}
        self._static: dict[tuple[str, int, int], np.ndarray] = {}
        self._grey = context.sequence.grayscale
        self._colour = np.ones(3, np.float32) if self._grey else white_balance(5800.0)
        self._world = None
        if self.follow_pose:
            first = context.sequence.records[0].index
            pose = context.pose(first)
            if pose is None:
                raise ModuleError(f"{self.name}: follow_pose needs per-frame ground-truth poses, and sequence {context.sequence.name!r} has none")
            self._world = pose[:3, :3] @ sun_direction(self.sun_azimuth_deg, self.sun_elevation_deg)

    def cleanup(self) -> None:
        self._rays, self._static = {}, {}
        super().cleanup()

    def direction(self, index: int, stream: str) -> np.ndarray:
        """The sun's unit direction in the camera frame of ``stream`` at frame ``index``."""
        context = self.ready_context()
        if self._world is None:
            d = sun_direction(self.sun_azimuth_deg, self.sun_elevation_deg)
        else:
            pose = context.pose(index)
            assert pose is not None
            d = pose[:3, :3].T @ self._world
        T_lr = context.camera.T_lr
        if stream == "right" and T_lr is not None:
            d = T_lr[:3, :3].T @ d
        return d

    def glare(self, index: int, stream: str, height: int, width: int) -> np.ndarray:
        """The added linear radiance (HxWx3 float32, in units of the clean white) of a frame."""
        key = (stream, height, width)
        if self._world is None and key in self._static:
            return self._static[key]
        glare = self._render(self.direction(index, stream), stream, height, width)
        if self._world is None:
            self._static[key] = glare
        return glare

    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray:
        self.ready_context()
        glare = self.glare(index, stream, image.shape[0], image.shape[1])
        linear = srgb_to_linear(image)
        linear += glare
        return linear_to_srgb(linear)

    # -- rendering ---------------------------------------------------------------------------
    def _camera(self, stream: str, height: int, width: int) -> tuple[float, float, float, float]:
        """fx, fy, cx, cy of ``stream`` scaled to the image size."""
        camera = self.ready_context().camera_for(stream)
        sx, sy = width / camera.width, height / camera.height
        return camera.fx * sx, camera.fy * sy, camera.cx * sx, camera.cy * sy

    def _pixel_rays(self, stream: str, height: int, width: int) -> np.ndarray:
        """Unit viewing rays of the pixels, 3xHxW float32 (cached per stream and size)."""
        key = (stream, height, width)
        if key not in self._rays:
            fx, fy, cx, cy = self._camera(stream, height, width)
            x = ((np.arange(width, dtype=np.float32) - cx) / fx)[None, :]
            y = ((np.arange(height, dtype=np.float32) - cy) / fy)[:, None]
            inverse_norm = 1.0 / np.sqrt(x * x + y * y + 1.0)
            self._rays[key] = np.stack([x * inverse_norm, y * inverse_norm, inverse_norm])
        return self._rays[key]

    def _render(self, d: np.ndarray, stream: str, height: int, width: int) -> np.ndarray:
        white = self.daylight_lux / math.pi
        e_sun = 1000.0 * self.sun_illuminance_klux
        e_pupil = e_sun * max(float(d[2]), 0.0)
        luminance = np.zeros((height, width), np.float32)
        if e_pupil > 0.0:
            rays = self._pixel_rays(stream, height, width)
            cosine = rays[0] * np.float32(d[0]) + rays[1] * np.float32(d[1]) + rays[2] * np.float32(d[2])
            theta = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))
            np.maximum(theta, MIN_ANGLE_DEG, out=theta)
            luminance = np.float32(10.0 * self.veil_factor * e_pupil / white) / (theta * theta)
        glare = luminance[..., None] * self._colour
        if d[2] > 1e-3:
            self._draw_sun(glare, d, e_sun / white, e_pupil / white, stream)
        return glare.astype(np.float32, copy=False)

    def _draw_sun(self, glare: np.ndarray, d: np.ndarray, disc: float, pupil: float, stream: str) -> None:
        """Add the sun's disc and the ghosts (E in units of the white luminance) to ``glare``."""
        height, width = glare.shape[:2]
        fx, fy, cx, cy = self._camera(stream, height, width)
        sun = np.array([cx + fx * d[0] / d[2], cy + fy * d[1] / d[2]])
        omega_sun = 2.0 * math.pi * (1.0 - math.cos(math.radians(SUN_RADIUS_DEG)))
        radius = fx * math.tan(math.radians(SUN_RADIUS_DEG))
        _add_disc(glare, sun, radius, 0.5, disc / omega_sun * self._colour)
        outside = math.hypot(max(0.0, -sun[0], sun[0] - width), max(0.0, -sun[1], sun[1] - height))
        fade = max(0.0, 1.0 - math.degrees(math.atan(outside / fx)) / GHOST_FADE_DEG)
        if fade <= 0.0 or self.ghost_reflectance <= 0.0:
            return
        centre, diagonal = np.array([cx, cy]), math.hypot(width, height)
        for t, size, strength, tint in GHOSTS:
            rho = size * diagonal
            omega = math.pi * (rho / fx) ** 2
            rgb = self._colour if self._grey else np.asarray(tint) / float(LUMA @ np.asarray(tint)) * self._colour
            _add_disc(glare, centre + t * (sun - centre), rho, 0.15 * rho, fade * self.ghost_reflectance * strength * pupil / omega * rgb)


def _add_disc(glare: np.ndarray, centre: np.ndarray, radius: float, edge: float, rgb: np.ndarray) -> None:
    """Add a disc of value ``rgb`` with a linear edge ``edge`` px wide to ``glare`` in place."""
    height, width = glare.shape[:2]
    reach = radius + edge
    x0, x1 = max(int(math.floor(centre[0] - reach)), 0), min(int(math.ceil(centre[0] + reach)) + 1, width)
    y0, y1 = max(int(math.floor(centre[1] - reach)), 0), min(int(math.ceil(centre[1] + reach)) + 1, height)
    if x0 >= x1 or y0 >= y1:
        return
    x = np.arange(x0, x1, dtype=np.float32)[None, :] - np.float32(centre[0])
    y = np.arange(y0, y1, dtype=np.float32)[:, None] - np.float32(centre[1])
    coverage = np.clip((np.float32(radius + edge / 2) - np.sqrt(x * x + y * y)) / np.float32(edge), 0.0, 1.0)
    glare[y0:y1, x0:x1] += coverage[..., None] * rgb.astype(np.float32)
