"""Vectorised renderer: painter's rasterisation of face ids, then analytic depth and texture.

1. Camera-facing box faces are clipped (near plane, guard band), projected and filled into
   a ``uint16`` id image in painter's order (``cv2.fillConvexPoly``, 1/256 px vertices;
   pixels whose centre is within half a pixel of a face are filled).
2. For a plane ``X[a] = c`` seen from ``o`` with rotation ``R`` (camera to scene), the scene
   ray of pixel ``p = (u, v, 1)`` is ``X = o + Z G p`` with ``G = R K^-1`` and ``Z`` the
   z-depth, so ``1/Z = G[a] p / (c - o[a])`` and every texture coordinate times ``1/Z`` is
   linear in ``p``: each face is a 3x3 homography. Per pixel, the face's rows are gathered
   and evaluated: exact depth and perspective-correct texture coordinates.
3. The mip level comes from the texture footprint (texels per pixel): with ``J`` the
   Jacobian ``d(s,t)/d(u,v)``, major axis ``M = max(|J_u|, |J_v|)`` and minor axis
   ``m = |det J| / M``, ``rho = max(m, M / 2)`` (anisotropy up to 2:1 is kept sharp rather
   than blurred); level ``L`` when ``2**(L - 1/2) < rho <= 2**(L + 1/2)``. One ``cv2.remap``
   (bilinear) samples the atlas.
4. Light (outdoor stages): the atlas holds reflectance as sRGB values; a face of outward
   normal ``n`` receives ``E = ambient + sun * max(0, n . d)`` (``d`` towards the sun, relative
   to the exposure), the sky ``sky_light``. As sRGB is close to a 2.2 power of linear light,
   a linear gain ``E`` is an sRGB gain ``E ** (1 / 2.2)``; the result is clipped at 255
   (surfaces and sky brighter than the exposure's white saturate, as in a real camera).
5. Optics: the frame is blurred with a Gaussian point spread function of ``psf_sigma_px``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from sal_adapters.camera import Camera
from sal_adapters.synthetic.atlas import LEVELS, TILE, Atlas
from sal_adapters.synthetic.geometry import (
    Boxes,
    Faces,
    clip_polygon,
    paint_order,
    visible_faces,
)
from sal_adapters.synthetic.textures import SKY_HORIZON, SKY_SLOPE

__all__ = ["Renderer", "Stage", "sun_light"]

#: Fixed-point fraction bits of polygon vertices given to ``cv2.fillConvexPoly``.
SHIFT = 8
#: Polygons are clipped to the image grown by this many image sizes on every side.
GUARD = 2.0
#: Smallest inverse depth (1/m): depth is at most 10 km, even for edge-on slivers.
W_MIN = np.float32(1e-4)
#: Pixels shaded at a time: per-pixel temporaries stay small (cache-resident, and below
#: the allocator's mmap threshold, whose page faults would otherwise dominate).
STRIP_PIXELS = 12288
#: sRGB approximated as a power law: linear gain ``E`` is sRGB gain ``E ** (1 / GAMMA)``.
GAMMA = 2.2
#: ``rho**2`` thresholds between mip levels: ``2 * 4**L``.
LEVEL_THRESHOLDS = tuple(2.0 * 4.0**level for level in range(LEVELS - 1))


@dataclass(frozen=True)
class Stage:
    """What a camera at some place can see.

    Attributes:
        groups: solid boxes (disjoint) in groups drawn one after the other: no box of a group
            may hide a box of a later group (boxes within a group are put in painter's order).
        room: boxes seen from inside (walls, floor, ceiling), drawn before everything else.
        sky_tile: atlas tile of the sky gradient, or ``None`` (enclosed scenes).
        fog: ``(start_m, end_m)``: beyond ``start_m`` colours fade linearly into the horizon
            colour of the sky, fully at ``end_m``; ``None`` for no fog.
        light: linear irradiance (1 = the exposure's white on a white surface) of the six face
            numbers (``FACE_NAMES``) of solid boxes, or ``None`` for unlit texture colours.
        sky_light: linear gain of the sky tile under ``light``.
    """

    groups: tuple[Boxes, ...]
    room: Boxes | None = None
    sky_tile: int | None = None
    fog: tuple[float, float] | None = None
    light: tuple[float, float, float, float, float, float] | None = None
    sky_light: float = 1.0


def sun_light(towards_sun: tuple[float, float, float], sun: float, ambient: float) -> tuple[float, float, float, float, float, float]:
    """``Stage.light`` of a sun in direction ``towards_sun`` (scene frame, normalised here)
    of irradiance ``sun`` on a surface facing it, plus ``ambient`` (sky light) everywhere."""
    d = np.asarray(towards_sun, np.float64) / np.linalg.norm(towards_sun)
    normals = np.repeat(np.eye(3), 2, axis=0) * np.tile([-1.0, 1.0], 3)[:, None]
    e0, e1, e2, e3, e4, e5 = (float(ambient + sun * max(0.0, float(n @ d))) for n in normals)
    return e0, e1, e2, e3, e4, e5


class Renderer:
    """Renders RGB images and z-depth maps of stages for one pinhole camera (no distortion)
    whose optics blur with a Gaussian of ``psf_sigma_px`` pixels (0: none)."""

    def __init__(self, camera: Camera, atlas: Atlas, near: float = 0.05, psf_sigma_px: float = 0.0):
        self.camera = camera
        self.psf_sigma_px = float(psf_sigma_px)
        self.atlas = atlas
        self.width, self.height = int(camera.width), int(camera.height)
        self.K = camera.K
        self.K_inv = np.linalg.inv(self.K)
        self.u = np.arange(self.width, dtype=np.float32)[None, :]
        self.v = np.arange(self.height, dtype=np.float32)[:, None]
        fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
        gx0, gx1 = (-GUARD * self.width - cx) / fx, ((1 + GUARD) * self.width - cx) / fx
        gy0, gy1 = (-GUARD * self.height - cy) / fy, ((1 + GUARD) * self.height - cy) / fy
        #: ``cv2.LUT`` tables from mip level to ``2**-L``, ``RX[L]``, ``RY[L]``.
        self.level_luts = [np.zeros(256, np.float32) for _ in range(3)]
        for lut, values in zip(self.level_luts, (atlas.level_scale, *atlas.level_offset.T)):
            lut[:LEVELS] = values
        #: Half-spaces ``n . X + d >= 0`` in camera coordinates: near plane and guard band.
        self.planes = np.array(
            [[0, 0, 1, -near], [1, 0, -gx0, 0], [-1, 0, gx1, 0], [0, 1, -gy0, 0], [0, -1, gy1, 0]],
            dtype=np.float64,
        )

    def render(self, stage: Stage, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """RGB (``H x W x 3`` uint8) and z-depth (``H x W`` float32 m, 0 for sky) seen from
        ``pose`` (4x4 camera-to-scene)."""
        pose = np.asarray(pose, dtype=np.float64)
        R, eye = pose[:3, :3], pose[:3, 3]
        faces = self._ordered_faces(stage, R, eye)
        ids, faces, inverse_depth = self._rasterize(faces, R, eye)
        table = self._homographies(faces, inverse_depth, stage, R, eye)
        return self._shade(ids, table, stage)

    def _camera_points(self, faces: Faces, R: np.ndarray, eye: np.ndarray) -> np.ndarray:
        """Face corners in camera coordinates, ``R^T (X - eye)``: ``(F, 4, 3)``."""
        return (faces.corners - eye) @ R

    def _ordered_faces(self, stage: Stage, R: np.ndarray, eye: np.ndarray) -> Faces:
        """Faces in drawing order: rooms, then each group's boxes in painter's order; faces
        entirely off the guard band are dropped."""
        parts = [] if stage.room is None else [visible_faces(stage.room, eye, inside=True)]
        for boxes in stage.groups:
            faces = visible_faces(boxes, eye)
            signed = self._camera_points(faces, R, eye) @ self.planes[:, :3].T + self.planes[:, 3]
            faces = faces.take(~np.any(np.all(signed < 0, axis=1), axis=1))
            used = np.unique(faces.box)
            order = paint_order(boxes.lo[used], boxes.hi[used], eye)
            rank = np.empty(len(boxes), np.int64)
            rank[used[order]] = np.arange(len(order))
            parts.append(faces.take(np.argsort(rank[faces.box], kind="stable")))
        return Faces.concat(parts) if parts else visible_faces(Boxes.concat([]), eye)

    def _rasterize(self, faces: Faces, R: np.ndarray, eye: np.ndarray) -> tuple[np.ndarray, Faces, np.ndarray]:
        """Fill face ids ``1..F`` (0 = nothing); return them, the faces drawn and the range
        ``(F, 2)`` of inverse depth (1/m) over each drawn polygon (its vertices' extremes)."""
        if len(faces) >= 1 << 16:
            raise ValueError(f"{len(faces)} faces in view; the id image holds at most 65535")
        cam = self._camera_points(faces, R, eye)
        signed = cam @ self.planes[:, :3].T + self.planes[:, 3]
        outside = np.any(np.all(signed < 0, axis=1), axis=1)
        inside = np.all(signed >= 0, axis=(1, 2))
        fixed = np.zeros((len(faces), 4, 2), np.int32)
        inverse_depth = np.zeros((len(faces), 2))
        if inside.any():
            fixed[inside] = self._fixed_point(cam[inside].reshape(-1, 3)).reshape(-1, 4, 2)
            inverse_depth[inside] = 1.0 / np.stack([cam[inside, :, 2].max(axis=1), cam[inside, :, 2].min(axis=1)], axis=1)
        ids = np.zeros((self.height, self.width), np.uint16)
        drawn: list[int] = []
        for f in np.flatnonzero(~outside):
            if inside[f]:
                points = fixed[f]
            else:
                polygon = clip_polygon(cam[f], self.planes)
                if len(polygon) < 3:
                    continue
                points = self._fixed_point(polygon)
                inverse_depth[f] = 1.0 / polygon[:, 2].max(), 1.0 / polygon[:, 2].min()
            drawn.append(int(f))
            cv2.fillConvexPoly(ids, points, len(drawn), cv2.LINE_8, SHIFT)
        drawn_faces = np.asarray(drawn, np.int64)
        return ids, faces.take(drawn_faces), inverse_depth[drawn_faces]

    def _fixed_point(self, points: np.ndarray) -> np.ndarray:
        """Pixel coordinates of camera points (z > 0) in ``SHIFT`` fixed point, int32 ``(k, 2)``."""
        uv = points @ self.K.T
        return np.round(uv[:, :2] / uv[:, 2:] * (1 << SHIFT)).astype(np.int32)

    def _homographies(self, faces: Faces, inverse_depth: np.ndarray, stage: Stage, R: np.ndarray, eye: np.ndarray) -> np.ndarray:
        """``(14, F + 1)`` float32 table: rows ``1/Z``, ``s/Z``, ``t/Z`` as linear forms in
        ``(u, v, 1)`` (3 rows each), the tile's level-0 atlas origin ``X0``, ``Y0``, the
        bounds of ``1/Z`` (pixels filled just outside a polygon get its nearest valid depth)
        and the sRGB gain of the light. Column 0 is the sky (or zeros)."""
        G = R @ self.K_inv
        rows = np.arange(len(faces))
        A = G[faces.axis] / (faces.coord - eye[faces.axis])[:, None]
        st = []
        for k in range(2):
            axis = faces.axis_st[:, k]
            scale = faces.density[:, k] * faces.sign_st[:, k]
            st.append(scale[:, None] * ((eye[axis] - faces.origin_st[rows, k])[:, None] * A + G[axis]))
        table = np.zeros((len(faces) + 1, 14))
        table[1:, 0:3], table[1:, 3:6], table[1:, 6:9] = A, st[0], st[1]
        table[1:, 9:11] = self.atlas.origin[faces.tile]
        table[1:, 11:13] = inverse_depth
        table[0, 11:13] = W_MIN
        table[:, 13] = 1.0
        if stage.light is not None:
            table[1:, 13] = np.asarray(stage.light)[faces.number] ** (1 / GAMMA)
            table[0, 13] = stage.sky_light ** (1 / GAMMA)
        if stage.sky_tile is not None:
            table[0, 12] = np.inf
            # s = TILE/2, t = SKY_HORIZON + SKY_SLOPE * dy / dz (tangent of the depression angle).
            table[0, 0:3] = G[2]
            table[0, 3:6] = TILE / 2 * G[2]
            table[0, 6:9] = SKY_HORIZON * G[2] + SKY_SLOPE * G[1]
            table[0, 9:11] = self.atlas.origin[stage.sky_tile]
        return np.ascontiguousarray(table.T, dtype=np.float32)

    def _shade(self, ids: np.ndarray, table: np.ndarray, stage: Stage) -> tuple[np.ndarray, np.ndarray]:
        """Colour and depth, in strips of about ``STRIP_PIXELS`` pixels."""
        rgb = np.empty((self.height, self.width, 3), np.uint8)
        depth = np.empty((self.height, self.width), np.float32)
        strip = max(1, STRIP_PIXELS // self.width)
        for r0 in range(0, self.height, strip):
            rows = slice(r0, min(r0 + strip, self.height))
            rgb[rows], depth[rows] = self._shade_rows(ids[rows], table, self.v[rows], stage.light is not None)
        if stage.fog is not None and stage.sky_tile is not None:
            self._fog(rgb, depth, stage.fog, stage.sky_tile, float(table[13, 0]))
        if self.psf_sigma_px > 0:
            cv2.GaussianBlur(rgb, (0, 0), self.psf_sigma_px, dst=rgb)
        return rgb, depth

    def _shade_rows(self, ids: np.ndarray, table: np.ndarray, v: np.ndarray, lit: bool) -> tuple[np.ndarray, np.ndarray]:
        """RGB and depth of the rows with face ids ``ids`` and row coordinates ``v`` (with the
        light's gain when ``lit``)."""
        index = ids.astype(np.intp)
        a, b, c, sa, sb, sc, ta, tb, tc, x0, y0, w_lo, w_hi = (np.take(row, index) for row in table[:13])
        u = self.u
        w = a * u + b * v + c
        np.clip(w, w_lo, w_hi, out=w)
        z = 1.0 / w
        s = (sa * u + sb * v + sc) * z
        t = (ta * u + tb * v + tc) * z
        # Footprint: d(s/w)/du = (sa - s a) / w with w = 1/Z, likewise for v and t.
        su, sv, tu, tv = (sa - s * a) * z, (sb - s * b) * z, (ta - t * a) * z, (tb - t * b) * z
        major2 = np.maximum(su * su + tu * tu, sv * sv + tv * tv)
        det = su * tv - sv * tu
        rho2 = np.maximum(det * det / (major2 + np.float32(1e-12)), major2 * np.float32(0.25))
        level = np.zeros(ids.shape, np.uint8)
        for threshold in LEVEL_THRESHOLDS:
            level += rho2 > threshold
        scale, x_offset, y_offset = (cv2.LUT(level, lut) for lut in self.level_luts)
        s -= TILE * np.floor(s * (1.0 / TILE))
        t -= TILE * np.floor(t * (1.0 / TILE))
        x = (x0 + s) * scale + x_offset
        y = (y0 + t) * scale + y_offset
        rgb = cv2.remap(self.atlas.image, x, y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        if lit:
            gain = np.take(table[13], index)
            rgb = cv2.convertScaleAbs(rgb * gain[..., None])
        z[ids == 0] = 0.0
        return rgb, z

    def _fog(self, rgb: np.ndarray, depth: np.ndarray, fog: tuple[float, float], sky_tile: int, sky_gain: float) -> None:
        """Blend pixels beyond the fog start (``fog``: start and end, m) into the horizon
        colour of the sky tile (times its sRGB gain ``sky_gain``), in place (within the
        bounding box of those pixels only)."""
        start, end = fog
        far = depth > start
        rows, cols = np.flatnonzero(far.any(axis=1)), np.flatnonzero(far.any(axis=0))
        if len(rows) == 0:
            return
        box = np.s_[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]
        x0, y0 = self.atlas.origin[sky_tile]
        horizon = np.minimum(self.atlas.image[int(y0 + SKY_HORIZON), int(x0 + TILE // 2)] * sky_gain, 255)
        weight = np.clip((depth[box] - start) * np.float32(1.0 / (end - start)), 0.0, 1.0)
        haze = np.empty_like(rgb[box])
        haze[:] = horizon
        rgb[box] = cv2.blendLinear(rgb[box], haze, 1.0 - weight, weight)
