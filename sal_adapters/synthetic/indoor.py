"""Indoor room, TUM-like: a hand-held RGB-D camera walking slowly in a furnished room.

Scene frame: x right, y down, z towards the front wall (m); the floor is ``y = 0``. The room
spans ``ROOM_LO .. ROOM_HI``; the camera wanders around ``HOME`` looking at the front wall
(``+z``), while the furniture stays out of its way (``|x| > 2``, ``z > 1.2``).
"""

from __future__ import annotations

import numpy as np

from sal_adapters.synthetic.atlas import TILE
from sal_adapters.synthetic.geometry import BoxBuilder, Face
from sal_adapters.synthetic.indoor_tiles import (
    CRATES,
    INDOOR_TILES,
    PICTURES,
    POSTERS,
    WALLS,
    paint_indoor,
)
from sal_adapters.synthetic.render import Stage
from sal_adapters.synthetic.world import World, rotation, wave

__all__ = ["IndoorWorld"]

ROOM_LO = (-3.2, -2.7, -3.0)
ROOM_HI = (3.2, 0.0, 4.0)
HOME = (0.0, -1.45, -0.9)  # centre of the camera's wandering (m)
PITCH = 0.1  # mean downward tilt of the camera (rad)
DECAL = 0.015  # thickness of posters, pictures, doors on the walls (m)


class IndoorWorld(World):
    """Walls with posters, pictures, whiteboard, door and window; table, screen, bookshelf,
    cabinets, sofa, cardboard boxes and a rug."""

    name = "indoor"
    fps = 30.0
    intrinsics = (525.0, 525.0, 319.5, 239.5, 640, 480)
    baseline = 0.1
    depth_scale = 5000.0
    default_sensor = "rgbd"
    TILE_NAMES = INDOOR_TILES

    def __init__(self, seed: int):
        super().__init__(seed)
        rng = np.random.default_rng([self.seed, 0x1D0])
        phase = rng.uniform(0, 2 * np.pi, 12)
        # Rows (amplitude, period s, phase rad): about 0.45 m/s and +-0.45 rad of yaw.
        self._path = (
            np.array([[0.7, 9.0, phase[0]], [0.25, 4.1, phase[1]]]),
            np.array([[0.08, 6.0, phase[2]], [0.03, 2.3, phase[3]]]),
            np.array([[0.45, 11.0, phase[4]], [0.15, 3.7, phase[5]]]),
        )
        self._yaw = np.array([[0.35, 17.0, phase[6]], [0.1, 6.1, phase[7]]])
        self._pitch = np.array([[0.06, 9.0, phase[8]], [0.02, 3.1, phase[9]]])
        self._roll = np.array([[0.03, 8.0, phase[10]], [0.01, 2.9, phase[11]]])
        self._stage = self._furnish(np.random.default_rng([self.seed, 0x800]))

    def pose(self, t: float) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = rotation(wave(t, self._yaw), PITCH + wave(t, self._pitch), wave(t, self._roll))
        T[:3, 3] = [h + wave(t, terms) for h, terms in zip(HOME, self._path)]
        return T

    def stage(self, eye: np.ndarray) -> Stage:
        return self._stage

    def paint_tiles(self, rng: np.random.Generator) -> dict[str, np.ndarray]:
        return paint_indoor(rng)

    # -- the room ----------------------------------------------------------------------------
    def _furnish(self, rng: np.random.Generator) -> Stage:
        """The room (walls, floor, ceiling) and everything in it."""
        t = self.tiles
        walls = [t[f"wall{k}"] for k in rng.permutation(WALLS)]
        room = BoxBuilder()
        height = ROOM_HI[1] - ROOM_LO[1]
        faces: dict[str, Face] = {name: (wall, 128, TILE / height) for name, wall in zip(("-x", "+x", "-z", "+z"), walls)}
        faces["+y"] = (t["floor"], 128, 128)
        faces["-y"] = (t["ceiling"], TILE / 2.4, TILE / 2.4)
        room.add(ROOM_LO, ROOM_HI, faces)
        b = BoxBuilder()
        self._wall_decor(b, rng)
        self._table(b, rng)
        self._front_furniture(b, rng)
        self._side_furniture(b, rng)
        rug = rng.uniform(-0.3, 0.3)
        b.add((rug - 1.0, -0.004, -0.1), (rug + 1.0, -0.004, 1.1), {"-y": (t["rug"], TILE / 2.0, TILE / 1.2)})
        return Stage(groups=(b.build(),), room=room.build())

    def _decal(self, b: BoxBuilder, wall: str, along: tuple[float, float], y: tuple[float, float], tile: str) -> None:
        """A flat item on wall ``wall`` (``+z`` front, ``-x`` left, ``+x`` right), spanning
        ``along`` (x for the front wall, z for side walls) and heights ``y``, fitted texture."""
        spec = (self.tiles[tile], TILE / (along[1] - along[0]), TILE / (y[1] - y[0]))
        if wall == "+z":
            b.add((along[0], y[0], ROOM_HI[2] - DECAL), (along[1], y[1], ROOM_HI[2]), {"-z": spec})
        elif wall == "-x":
            b.add((ROOM_LO[0], y[0], along[0]), (ROOM_LO[0] + DECAL, y[1], along[1]), {"+x": spec})
        else:
            b.add((ROOM_HI[0] - DECAL, y[0], along[0]), (ROOM_HI[0], y[1], along[1]), {"-x": spec})

    def _wall_decor(self, b: BoxBuilder, rng: np.random.Generator) -> None:
        """Whiteboard and posters on the front wall, door, window and pictures on the sides."""
        left = rng.uniform(-2.9, -0.6)
        self._decal(b, "+z", (left, left + 1.8), (-2.05, -1.05), "whiteboard")
        posters = rng.permutation(POSTERS)
        x = left + 2.1
        for k in posters[:3]:
            if x + 0.6 > ROOM_HI[0] - 0.2:
                break
            top = rng.uniform(-2.1, -1.8)
            self._decal(b, "+z", (x, x + 0.6), (top, top + 0.85), f"poster{k}")
            x += 0.6 + rng.uniform(0.25, 0.6)
        door_wall, window_wall = ("-x", "+x") if rng.random() < 0.5 else ("+x", "-x")
        z = rng.uniform(-2.5, -1.5)
        self._decal(b, door_wall, (z, z + 0.9), (-2.1, 0.0), "door")
        self._decal(b, door_wall, (z + 1.4, z + 2.0), (-2.0, -1.15), f"poster{posters[3]}")
        z = rng.uniform(-2.0, -0.5)
        self._decal(b, window_wall, (z, z + 1.2), (-2.1, -0.9), "window")
        for k, wall in enumerate((door_wall, window_wall)):
            z = rng.uniform(1.0, 2.6)
            self._decal(b, wall, (z, z + 0.9), (-2.0, -1.3), f"picture{k % PICTURES}")

    def _table(self, b: BoxBuilder, rng: np.random.Generator) -> None:
        """A table with four legs, a monitor on a stand and a box on top."""
        t = self.tiles
        width, depth, height = rng.uniform(1.2, 1.6), rng.uniform(0.7, 0.9), rng.uniform(0.72, 0.78)
        x0, z0 = rng.uniform(-1.2, 1.2 - width), rng.uniform(1.3, 1.8)
        x1, z1 = x0 + width, z0 + depth
        wood = (t["wood"], 128, 128)
        b.add((x0, -height, z0), (x1, -height + 0.04, z1), {n: wood for n in ("-x", "+x", "-y", "-z", "+z")})
        metal: Face = (t["metal"], 128, 128)
        for x in (x0 + 0.05, x1 - 0.1):
            for z in (z0 + 0.05, z1 - 0.1):
                b.add((x, -height + 0.04, z), (x + 0.05, 0.0, z + 0.05), {n: metal for n in ("-x", "+x", "-z", "+z")})
        screen = x0 + rng.uniform(0.1, width - 0.7)
        zs = z0 + depth * 0.55
        b.add((screen + 0.25, -height - 0.12, zs), (screen + 0.35, -height, zs + 0.08), {n: metal for n in ("-x", "+x", "-y", "-z", "+z")})
        faces = {n: metal for n in ("-x", "+x", "-y", "+y", "+z")}
        faces["-z"] = (t["screen"], TILE / 0.6, TILE / 0.38)
        b.add((screen, -height - 0.5, zs - 0.04), (screen + 0.6, -height - 0.12, zs), faces)
        crate = (t[f"crate{rng.integers(CRATES)}"], TILE / 0.4, TILE / 0.3)
        box_x = screen + 0.65 if screen + 1.1 < x1 else x0 + 0.02
        b.add((box_x, -height - 0.3, z0 + 0.03), (box_x + 0.4, -height, z0 + 0.33), {n: crate for n in ("-x", "+x", "-y", "-z", "+z")})

    def _front_furniture(self, b: BoxBuilder, rng: np.random.Generator) -> None:
        """A bookshelf and a stack of cardboard boxes against the front wall."""
        t = self.tiles
        side = (t["wood"], 128, 128)
        width, height = rng.uniform(0.9, 1.3), rng.uniform(1.7, 2.0)
        x = rng.uniform(-2.9, 2.9 - width)
        faces = {"-x": side, "+x": side, "-y": side, "-z": (t["books"], TILE / width, TILE / height)}
        b.add((x, -height, ROOM_HI[2] - 0.4), (x + width, 0.0, ROOM_HI[2] - 0.02), faces)
        free = (x + width + 0.2, ROOM_HI[0] - 0.1) if x < 0 else (ROOM_LO[0] + 0.1, x - 0.2)
        base, size = 0.0, rng.uniform(0.5, 0.7)
        left = rng.uniform(free[0], max(free[0], free[1] - size))
        for k in range(int(rng.integers(1, 4))):
            crate = (t[f"crate{(k + rng.integers(2)) % CRATES}"], TILE / size, TILE / size)
            z1 = ROOM_HI[2] - 0.05
            b.add((left, base - size, z1 - size), (left + size, base, z1), {n: crate for n in ("-x", "+x", "-y", "-z")})
            base -= size
            left += rng.uniform(-0.05, 0.05)
            size *= rng.uniform(0.7, 0.9)

    def _side_furniture(self, b: BoxBuilder, rng: np.random.Generator) -> None:
        """A sofa along one side wall, a cabinet with drawers along the other."""
        t = self.tiles
        sofa_side = -1 if rng.random() < 0.5 else 1
        fabric = (t["fabric"], 128, 128)
        z, length = rng.uniform(0.0, 1.0), rng.uniform(1.8, 2.2)
        wall_x = ROOM_LO[0] if sofa_side < 0 else ROOM_HI[0]
        inner = wall_x - sofa_side * 0.9
        back = wall_x - sofa_side * 0.25
        lo, hi = sorted((inner, back))
        b.add((lo, -0.45, z), (hi, 0.0, z + length), {n: fabric for n in ("-x", "+x", "-y", "-z", "+z")})
        lo, hi = sorted((back, wall_x - sofa_side * 0.02))
        b.add((lo, -0.9, z), (hi, 0.0, z + length), {n: fabric for n in ("-x", "+x", "-y", "-z", "+z")})
        wall_x = ROOM_HI[0] if sofa_side < 0 else ROOM_LO[0]
        depth, height, length = 0.5, rng.uniform(0.8, 1.1), rng.uniform(0.8, 1.2)
        z = rng.uniform(-0.5, 2.8 - length)
        lo, hi = sorted((wall_x + sofa_side * 0.02, wall_x + sofa_side * (0.02 + depth)))
        front = "+x" if sofa_side > 0 else "-x"
        side: Face = (t["metal"], 128, 128)
        faces = {n: side for n in ("-x", "+x", "-y", "-z", "+z")}
        faces[front] = (t["drawers"], TILE / length, TILE / height)
        b.add((lo, -height, z), (hi, 0.0, z + length), faces)
