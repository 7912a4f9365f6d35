"""``sun_glare``: veiling glare, the sun's disc and lens-flare ghosts from a low sun, hidden
where the scene occludes the sun.

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

Occlusion (depth)
-----------------
The sun is seen only through open sky. A pixel is sky where the clean frame's z-depth is
unknown (0, inf, NaN: the synthetic world's and the stereo matcher's sky) or at least
``sky_depth_m``; any nearer surface (a facade, a tree, a car) stands in front of the sun.

* Disc: drawn only on sky pixels (coverage x sky mask), so a sun half behind a roof edge
  shows half a disc and a sun behind a facade shows none.
* Veil and ghosts: both are light of the direct beam scattered or reflected inside the lens,
  so they scale with the visible share V of the disc (coverage-weighted sky fraction over the
  disc, 0..1). An occluded sun (V = 0) adds nothing at all: the frame is returned unchanged;
  the light of the bright sky around it is already in the clean frame.
* A sun outside the image cannot be checked directly: V is measured on the disc moved to the
  nearest image position and trusted with weight w = max(0, 1 - outside angle / 10 deg) (the
  ghosts' fade), V = 1 - w (1 - V_border); far outside the view (w = 0) the sun counts as
  unoccluded, as before.

Depth comes from the sequence's depth provider (``needs_depth``: native maps, stereo
matching, or a monocular ONNX model via ``depth='model.onnx'`` / ``SAL_DEPTH_MODEL``).
There is deliberately no sky estimate from the image for mono frames without depth: in each
of six frames sampled over the real KITTI 07 excerpt (0, 30, 60, 90, 120, 139) the smooth
regions connected to the top border include facades, some brighter than the sky, and
saturated white walls are as bright as a saturated sky, so such an estimate would draw the
sun on facades (the bug this replaces).
A mono sequence without depth therefore fails in ``perturb`` with ``DepthUnavailable``,
which names each provider and why it does not apply.

The unoccluded glare depends on the sun direction only, so it is computed once per lens
(static per sequence, no jumping ghosts); its visibility is decided per frame from that
frame's depth. With ``follow_pose`` the sun is fixed in the world instead: its direction is
given for the first frame and rotated into each frame's camera with the ground-truth poses.
The right camera of a stereo pair sees the sun through its own rotation, intrinsics and depth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from sal_modules.base import Perturbation
from sal_modules.colour import srgb_to_linear
from sal_modules.context import ModuleContext
from sal_modules.errors import ModuleError
from sal_modules.light.sensor import LUMA, linear_to_srgb, white_balance
from sal_modules.params import Param

__all__ = ["GHOSTS", "SunGlare", "SunImage", "sky_mask", "sun_direction"]

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

#: Ghosts fade out, and the frame's depth stops deciding whether the sun is occluded, while
#: the sun moves this far (deg) outside the field of view.
GHOST_FADE_DEG = 10.0

#: Width (px) of the disc's anti-aliased edge.
DISC_EDGE_PX = 0.5

#: Disc coverage: rows, columns and coverage (0..1, float32) of the pixels it touches.
Footprint = tuple[slice, slice, np.ndarray]


def sun_direction(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit vector to the sun in the camera frame (x right, y down, z forward)."""
    a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
    return np.array([math.cos(e) * math.sin(a), -math.sin(e), math.cos(e) * math.cos(a)])


def sky_mask(depth: np.ndarray, sky_depth_m: float) -> np.ndarray:
    """Open sky (bool, same shape): z-depth unknown (0, inf, NaN) or at least ``sky_depth_m`` (m)."""
    return ~((depth > 0) & (depth < sky_depth_m))


@dataclass(frozen=True, eq=False)
class SunImage:
    """The sun as one lens sees it at one image size, before occlusion (linear light, in
    units of the clean white luminance).

    Attributes:
        glare: HxWx3 float32 veiling glare plus ghosts of the unoccluded sun.
        centre: the sun's image S (x, y px, may lie outside the image), or ``None`` when the
            sun is at or behind the camera's side (no disc, no ghosts).
        trust: weight (0..1) of the frame's depth in deciding whether the sun is occluded: 1
            with S in the image, falling to 0 at ``GHOST_FADE_DEG`` outside it.
        disc: footprint of the disc inside the image, or ``None`` when it falls outside.
        disc_rgb: the disc's value per channel (saturates any pixel it covers noticeably).
        probe: footprint of the disc moved to the nearest image position (where its
            visibility is measured), or ``None`` when ``trust`` is 0.
    """

    glare: np.ndarray
    centre: tuple[float, float] | None
    trust: float
    disc: Footprint | None
    disc_rgb: np.ndarray
    probe: Footprint | None

    def visibility(self, sky: np.ndarray) -> float:
        """Visible share V (0..1) of the sun's disc given the sky mask (HxW bool) of a frame:
        the coverage-weighted sky fraction over ``probe``, trusted with weight ``trust``
        (V = 1 - trust (1 - V_probe)); 1 when the frame cannot tell."""
        if self.probe is None or self.trust <= 0.0:
            return 1.0
        rows, cols, coverage = self.probe
        total = float(coverage.sum())
        seen = float((coverage * sky[rows, cols]).sum()) / total if total > 0.0 else 1.0
        return 1.0 - self.trust * (1.0 - seen)


class SunGlare(Perturbation):
    """A low sun near or in the view: veiling glare, saturated disc, flare ghosts; hidden
    behind whatever the depth says is nearer than the sky."""

    name = "sun_glare"
    version = 2
    summary = "Sun glare: Stiles-Holladay veiling glare, sun disc and lens-flare ghosts from the sun direction and illuminance, occluded by the scene's depth"
    needs_depth = True

    sun_illuminance_klux = Param(
        100.0,
        unit="klx",
        min=0.0,
        max=150.0,
        searchable=True,
        worse="higher",
        doc="illuminance of the sun normal to its rays (direct sun ~100 klx, low sun ~10-50 klx)",
    )
    sun_azimuth_deg = Param(
        0.0, unit="deg", min=-180.0, max=180.0, doc="sun direction right of the optical axis (default: straight ahead, over the road)"
    )
    sun_elevation_deg = Param(8.0, unit="deg", min=-90.0, max=90.0, doc="sun direction above the optical axis")
    daylight_lux = Param(
        10_000.0, unit="lx", min=1.0, max=150_000.0, doc="illuminance the clean frames were exposed for (white = daylight_lux/pi cd/m^2)"
    )
    veil_factor = Param(
        0.3,
        unit="",
        min=0.0,
        max=100.0,
        doc="lens scatter k in L = 10 k E / theta^2 (1 = the human eye; clean lenses < 1, dirty windscreens > 1)",
    )
    ghost_reflectance = Param(
        5e-5, unit="", min=0.0, max=0.05, doc="share of the light the strongest flare ghost returns (coated lens ~5e-5; 0: no ghosts)"
    )
    sky_depth_m = Param(
        1000.0,
        unit="m",
        min=1.0,
        max=1e7,
        doc="z-depth from which a pixel counts as open sky (pixels without depth are sky too); nearer surfaces hide the sun",
    )
    follow_pose = Param(
        False, domain="flag", doc="keep the sun fixed in the world with the ground-truth poses (direction given for the first frame)"
    )

    def setup(self, context: ModuleContext) -> None:
        super().setup(context)
        self._rays: dict[tuple[str, int, int], np.ndarray] = {}
        self._static: dict[tuple[str, int, int], SunImage] = {}
        self._grey = context.sequence.grayscale
        self._colour = np.ones(3, np.float32) if self._grey else white_balance(5800.0)
        self._world = None
        if self.follow_pose:
            first = context.sequence.records[0].index
            pose = context.pose(first)
            if pose is None:
                raise ModuleError(
                    f"{self.name}: follow_pose needs per-frame ground-truth poses, and sequence {context.sequence.name!r} has none"
                )
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

    def sun_image(self, index: int, stream: str, height: int, width: int) -> SunImage:
        """The unoccluded sun of frame ``index`` in ``stream`` (cached per lens unless it
        follows the pose)."""
        key = (stream, height, width)
        if self._world is None and key in self._static:
            return self._static[key]
        sun = self._render(self.direction(index, stream), stream, height, width)
        if self._world is None:
            self._static[key] = sun
        return sun

    def glare(self, index: int, stream: str, height: int, width: int) -> np.ndarray:
        """The added linear radiance (HxWx3 float32, in units of the clean white) of an
        unoccluded sun: veil, ghosts and disc, as on a frame that is all sky."""
        sun = self.sun_image(index, stream, height, width)
        glare = sun.glare.copy()
        if sun.disc is not None:
            rows, cols, coverage = sun.disc
            glare[rows, cols] += coverage[..., None] * sun.disc_rgb
        return glare

    def visibility(self, depth: np.ndarray, index: int, stream: str) -> float:
        """Visible share (0..1) of the sun's disc on frame ``index`` of ``stream`` with the
        clean frame's z-depth ``depth`` (m, HxW); see ``SunImage.visibility``."""
        return self.sun_image(index, stream, *depth.shape).visibility(sky_mask(depth, self.sky_depth_m))

    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray:
        self.ready_context()
        if depth is None:
            raise ModuleError(
                f"{self.name} needs the depth of each frame to hide a sun behind buildings; run it through sal_modules.perturb(), which picks a depth provider"
            )
        if depth.shape != image.shape[:2]:
            raise ModuleError(f"{self.name}: depth map {depth.shape} does not match the {stream} image {image.shape[:2]} of frame {index}")
        sun = self.sun_image(index, stream, image.shape[0], image.shape[1])
        sky = sky_mask(depth, self.sky_depth_m)
        visible = sun.visibility(sky)
        disc = None
        if sun.disc is not None:
            rows, cols, coverage = sun.disc
            shown = coverage * sky[rows, cols]
            disc = (rows, cols, shown) if shown.any() else None
        if visible <= 0.0 and disc is None:
            return image.copy()  # an occluded sun sends no light into the lens
        linear = srgb_to_linear(image)
        if visible > 0.0:
            cv2.scaleAdd(sun.glare, visible, linear, dst=linear)
        if disc is not None:
            rows, cols, shown = disc
            linear[rows, cols] += shown[..., None] * sun.disc_rgb
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

    def _render(self, d: np.ndarray, stream: str, height: int, width: int) -> SunImage:
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
        glare = np.ascontiguousarray(luminance[..., None] * self._colour, dtype=np.float32)
        if d[2] <= 1e-3:
            return SunImage(glare, None, 0.0, None, np.zeros(3, np.float32), None)
        return self._draw_sun(glare, d, e_sun / white, e_pupil / white, stream)

    def _draw_sun(self, glare: np.ndarray, d: np.ndarray, disc: float, pupil: float, stream: str) -> SunImage:
        """Add the ghosts (E in units of the white luminance) to ``glare`` and place the disc."""
        height, width = glare.shape[:2]
        fx, fy, cx, cy = self._camera(stream, height, width)
        sun = np.array([cx + fx * d[0] / d[2], cy + fy * d[1] / d[2]])
        omega_sun = 2.0 * math.pi * (1.0 - math.cos(math.radians(SUN_RADIUS_DEG)))
        radius = fx * math.tan(math.radians(SUN_RADIUS_DEG))
        outside = math.hypot(max(0.0, -sun[0], sun[0] - width), max(0.0, -sun[1], sun[1] - height))
        fade = max(0.0, 1.0 - math.degrees(math.atan(outside / fx)) / GHOST_FADE_DEG)
        nearest = np.array([min(max(sun[0], 0.0), width - 1.0), min(max(sun[1], 0.0), height - 1.0)])
        probe = _disc_footprint(nearest, radius, DISC_EDGE_PX, height, width) if fade > 0.0 else None
        result = SunImage(
            glare=glare,
            centre=(float(sun[0]), float(sun[1])),
            trust=fade,
            disc=_disc_footprint(sun, radius, DISC_EDGE_PX, height, width),
            disc_rgb=(disc / omega_sun * self._colour).astype(np.float32),
            probe=probe,
        )
        if fade <= 0.0 or self.ghost_reflectance <= 0.0:
            return result
        centre, diagonal = np.array([cx, cy]), math.hypot(width, height)
        for t, size, strength, tint in GHOSTS:
            rho = size * diagonal
            omega = math.pi * (rho / fx) ** 2
            rgb = self._colour if self._grey else np.asarray(tint) / float(LUMA @ np.asarray(tint)) * self._colour
            _add_disc(glare, centre + t * (sun - centre), rho, 0.15 * rho, fade * self.ghost_reflectance * strength * pupil / omega * rgb)
        return result


def _disc_footprint(centre: np.ndarray, radius: float, edge: float, height: int, width: int) -> Footprint | None:
    """Coverage (0..1, linear edge ``edge`` px wide) of a disc on an HxW image, or ``None``
    when it misses the image."""
    reach = radius + edge
    x0, x1 = max(int(math.floor(centre[0] - reach)), 0), min(int(math.ceil(centre[0] + reach)) + 1, width)
    y0, y1 = max(int(math.floor(centre[1] - reach)), 0), min(int(math.ceil(centre[1] + reach)) + 1, height)
    if x0 >= x1 or y0 >= y1:
        return None
    x = np.arange(x0, x1, dtype=np.float32)[None, :] - np.float32(centre[0])
    y = np.arange(y0, y1, dtype=np.float32)[:, None] - np.float32(centre[1])
    coverage = np.clip((np.float32(radius + edge / 2) - np.sqrt(x * x + y * y)) / np.float32(edge), 0.0, 1.0)
    return slice(y0, y1), slice(x0, x1), coverage


def _add_disc(glare: np.ndarray, centre: np.ndarray, radius: float, edge: float, rgb: np.ndarray) -> None:
    """Add a disc of value ``rgb`` with a linear edge ``edge`` px wide to ``glare`` in place."""
    footprint = _disc_footprint(centre, radius, edge, glare.shape[0], glare.shape[1])
    if footprint is not None:
        rows, cols, coverage = footprint
        glare[rows, cols] += coverage[..., None] * rgb.astype(np.float32)
