"""Axis-aligned boxes: their camera-facing faces, painter's order and polygon clipping.

Scene coordinates follow the camera convention: x right, y down, z forward (metres). A box
face is numbered ``2 * axis + side`` (side 0: the ``lo`` face, side 1: the ``hi`` face).
Each face carries a texture tile repeated over it: texture coordinates (level-0 texels)
``s = ds * sign_s * (X[axis_s] - origin_s)`` and ``t = dt * sign_t * (X[axis_t] - origin_t)``,
where, seen from outside, ``s`` runs to the viewer's right and ``t`` downwards (vertical
faces) or towards the viewer (horizontal faces).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

__all__ = ["FACE_NAMES", "BoxBuilder", "Boxes", "Face", "Faces", "clip_polygon", "paint_order", "visible_faces"]

#: Face names by number: ``-x`` is the face at ``lo[0]`` whose outward normal is -x, etc.
FACE_NAMES = ("-x", "+x", "-y", "+y", "-z", "+z")

#: How one face is drawn: ``(atlas tile, ds, dt)``, the densities in texels per metre.
Face = tuple[int, float, float]

#: Faces whose camera is closer than this to their plane are seen edge-on and skipped (m).
EDGE_ON = 1e-3


@dataclass(frozen=True)
class Boxes:
    """``N`` axis-aligned boxes with a texture per face.

    Attributes:
        lo, hi: ``(N, 3)`` min and max corners (m).
        tiles: ``(N, 6)`` atlas tile of each face, ``-1`` for a face that is never drawn.
        density: ``(N, 6, 2)`` texels per metre along ``s`` and ``t`` of each face.
    """

    lo: np.ndarray
    hi: np.ndarray
    tiles: np.ndarray
    density: np.ndarray

    def __len__(self) -> int:
        return len(self.lo)

    @classmethod
    def concat(cls, parts: Iterable[Boxes]) -> Boxes:
        """All boxes of ``parts``, in order."""
        parts = list(parts)
        if not parts:
            return BoxBuilder().build()
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("lo", "hi", "tiles", "density")))


class BoxBuilder:
    """Collects boxes one by one for ``Boxes``."""

    def __init__(self) -> None:
        self._lo: list[tuple[float, float, float]] = []
        self._hi: list[tuple[float, float, float]] = []
        self._tiles: list[list[int]] = []
        self._density: list[list[tuple[float, float]]] = []

    def add(self, lo: Iterable[float], hi: Iterable[float], faces: Mapping[str, Face]) -> None:
        """Add the box ``lo..hi`` (m, three coordinates each); ``faces`` maps face names
        (``FACE_NAMES``) to ``(tile, ds, dt)`` with densities in texels per metre; other faces
        are not drawn."""
        lo, hi = _corner(lo), _corner(hi)
        if any(a > b for a, b in zip(lo, hi)):
            raise ValueError(f"box lo {lo} exceeds hi {hi}")
        unknown = set(faces) - set(FACE_NAMES)
        if unknown:
            raise ValueError(f"unknown face names {sorted(unknown)}; use {FACE_NAMES}")
        self._lo.append(lo)
        self._hi.append(hi)
        self._tiles.append([faces[n][0] if n in faces else -1 for n in FACE_NAMES])
        self._density.append([(faces[n][1], faces[n][2]) if n in faces else (0.0, 0.0) for n in FACE_NAMES])

    def build(self) -> Boxes:
        """The boxes added so far."""
        n = len(self._lo)
        return Boxes(
            lo=np.asarray(self._lo, np.float64).reshape(n, 3),
            hi=np.asarray(self._hi, np.float64).reshape(n, 3),
            tiles=np.asarray(self._tiles, np.int32).reshape(n, 6),
            density=np.asarray(self._density, np.float64).reshape(n, 6, 2),
        )


@dataclass(frozen=True)
class Faces:
    """``F`` textured rectangles facing the camera (see the module docstring for ``s``, ``t``).

    Attributes:
        corners: ``(F, 4, 3)`` corners in cyclic order (m).
        axis, coord: the face plane ``X[axis] = coord``.
        axis_st, sign_st, origin_st: ``(F, 2)`` texture axes, their signs and origins (m).
        density: ``(F, 2)`` texels per metre along ``s`` and ``t``.
        tile: atlas tile. box: index of the box each face belongs to.
        number: face number ``2 * axis + side`` within its box (``FACE_NAMES``).
    """

    corners: np.ndarray
    axis: np.ndarray
    coord: np.ndarray
    axis_st: np.ndarray
    sign_st: np.ndarray
    origin_st: np.ndarray
    density: np.ndarray
    tile: np.ndarray
    box: np.ndarray
    number: np.ndarray

    def __len__(self) -> int:
        return len(self.axis)

    def take(self, order: np.ndarray) -> Faces:
        """The faces at positions ``order`` (indices or a boolean mask)."""
        return Faces(**{name: value[order] for name, value in vars(self).items()})

    @classmethod
    def concat(cls, parts: Iterable[Faces]) -> Faces:
        """All faces of ``parts``, in order."""
        parts = list(parts)
        return cls(**{name: np.concatenate([vars(p)[name] for p in parts]) for name in vars(parts[0])})


def _corner(values: Iterable[float]) -> tuple[float, float, float]:
    """A box corner as three floats (m)."""
    x, y, z = (float(v) for v in values)
    return x, y, z


def visible_faces(boxes: Boxes, eye: np.ndarray, inside: bool = False) -> Faces:
    """Drawn faces of ``boxes`` that face the point ``eye`` (m), grouped by box.

    With ``inside=True`` the boxes are rooms seen from within: normals point inwards and a
    face is visible when ``eye`` is inside the box.
    """
    n = len(boxes)
    axis = np.tile(np.repeat(np.arange(3), 2), n)
    side = np.tile([0, 1, 0, 1, 0, 1], n)
    box = np.repeat(np.arange(n), 6)
    lo, hi = boxes.lo[box], boxes.hi[box]
    coord = np.where(side == 1, hi[np.arange(len(axis)), axis], lo[np.arange(len(axis)), axis])
    normal = np.where(side == 1, 1.0, -1.0) * (-1.0 if inside else 1.0)
    offset = (eye[axis] - coord) * normal
    keep = (boxes.tiles.reshape(-1) >= 0) & (offset > EDGE_ON)
    if inside:
        keep &= np.all((eye > boxes.lo) & (eye < boxes.hi), axis=1)[box]
    axis, side, box = axis[keep], side[keep], box[keep]
    lo, hi, coord, normal = lo[keep], hi[keep], coord[keep], normal[keep]
    # Texture frame: vertical faces have s = n_out x down, t = down; horizontal ones s = +x, t = n_out_y * z.
    vertical = axis != 1
    axis_s = np.where(vertical, 2 - axis, 0)
    sign_s = np.where(axis == 0, normal, np.where(axis == 2, -normal, 1.0))
    axis_t = np.where(vertical, 1, 2)
    sign_t = np.where(vertical, 1.0, normal)
    axis_st = np.stack([axis_s, axis_t], axis=1)
    sign_st = np.stack([sign_s, sign_t], axis=1)
    rows = np.arange(len(axis))[:, None]
    origin_st = np.where(sign_st > 0, lo[rows, axis_st], hi[rows, axis_st])
    # Corners: the two in-plane axes (u, w) walked lo-lo, hi-lo, hi-hi, lo-hi.
    u_axis, w_axis = (axis + 1) % 3, (axis + 2) % 3
    corners = np.empty((len(axis), 4, 3))
    corners[:, :, :] = coord[:, None, None]
    for k, (use_hi_u, use_hi_w) in enumerate(((0, 0), (1, 0), (1, 1), (0, 1))):
        corners[rows[:, 0], k, u_axis] = (hi if use_hi_u else lo)[rows[:, 0], u_axis]
        corners[rows[:, 0], k, w_axis] = (hi if use_hi_w else lo)[rows[:, 0], w_axis]
    face = 2 * axis + side
    return Faces(
        corners=corners,
        axis=axis,
        coord=coord,
        axis_st=axis_st,
        sign_st=sign_st,
        origin_st=origin_st,
        density=boxes.density[box, face],
        tile=boxes.tiles[box, face],
        box=box,
        number=face,
    )


def paint_order(lo: np.ndarray, hi: np.ndarray, eye: np.ndarray) -> np.ndarray:
    """Order in which to draw disjoint boxes so that later ones are never hidden by earlier ones.

    Two disjoint axis-aligned boxes are split by a plane ``X[a] = const``; the box on the
    eye's side of that plane may hide the other, never the reverse. Boxes are emitted in
    topological order of these "may hide" relations (Kahn's algorithm, farthest box first
    should a cycle ever occur). Overlapping boxes get no relation.
    """
    n = len(lo)
    if n == 0:
        return np.zeros(0, np.int64)
    below = hi[:, None, :] <= lo[None, :, :]  # below[i, j, a]: i entirely under j along a
    # hides[i, j]: i may hide j. With i below j along a, only the one on the eye's side hides.
    eye_under = eye[None, None, :] < hi[:, None, :]  # eye on i's side of the gap
    eye_over = eye[None, None, :] > lo[None, :, :]  # eye on j's side of the gap
    cannot = np.any(below & ~eye_under, axis=2) | np.any(below.transpose(1, 0, 2) & ~eye_over.transpose(1, 0, 2), axis=2)
    separated = np.any(below | below.transpose(1, 0, 2), axis=2)
    hides = separated & ~cannot  # hides[i, j]: i may hide j, so j is drawn first
    waiting = hides.sum(axis=1)  # i waits until every box it may hide is drawn
    done = np.zeros(n, bool)
    order: list[np.ndarray] = []
    distance = np.linalg.norm(np.clip(eye, lo, hi) - eye, axis=1)
    while not done.all():
        ready = np.flatnonzero(~done & (waiting == 0))
        if len(ready) == 0:
            rest = np.flatnonzero(~done)
            ready = rest[[np.argmax(distance[rest])]]
        order.append(ready)
        done[ready] = True
        waiting -= hides[:, ready].sum(axis=1)
    return np.concatenate(order)


def clip_polygon(points: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman: the part of the convex polygon ``points`` (k, 3) where
    ``planes @ [X, 1] >= 0`` for every plane row ``(nx, ny, nz, d)``; may be empty."""
    for plane in planes:
        if len(points) == 0:
            break
        dist = points @ plane[:3] + plane[3]
        inside = dist >= 0
        if inside.all():
            continue
        out = []
        for k in range(len(points)):
            nxt = (k + 1) % len(points)
            if inside[k]:
                out.append(points[k])
            if inside[k] != inside[nxt]:
                f = dist[k] / (dist[k] - dist[nxt])
                out.append(points[k] + f * (points[nxt] - points[k]))
        points = np.asarray(out).reshape(-1, 3)
    return points
