"""Urban street, KITTI-like: a car-mounted stereo camera driving at about 4 m/s (14 km/h).

It is made to look to feature tracking as the KITTI 07 excerpt does (benchmarks/RESULTS.md,
issue 25): low buildings of 1-3 storeys, many set back, so the sky fills about 7 % of the
frame; the sun from the left and behind, so the left side of the street lies in shade; the
exposure is set for the sunlit road, so the sky saturates; a smooth road; and a lens whose
point spread function is a Gaussian of 0.8 px.

Scene frame: x right, y down, z along the street (m); the road surface is ``y = 0`` and the
centre line ``x = 0``. The street is cut into blocks of ``BLOCK`` metres; block ``k`` is
generated from ``(seed, k)`` alone (buildings, parked cars, poles, signs, road paint), so
the street is endless and not periodic, and a frame depends only on its time.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from sal_adapters.synthetic.atlas import TILE
from sal_adapters.synthetic.geometry import BoxBuilder, Boxes, Face
from sal_adapters.synthetic.render import Stage, sun_light
from sal_adapters.synthetic.urban_tiles import (
    CAR_COLOURS,
    FACADES,
    SHOPS,
    SIDES,
    SIGNS,
    URBAN_TILES,
    paint_urban,
)
from sal_adapters.synthetic.world import World, rotation, wave

__all__ = ["UrbanWorld"]

BLOCK = 32.0  # length of a generated block along the street (m)
ROAD = 5.7  # half width of the carriageway, parking strips included (m)
LANE_LINE = 3.5  # solid line between driving lane and parking strip (m from the centre)
FACADE = 8.7  # building line (m from the centre): carriageway plus a 3 m pavement
KERB = 0.12  # kerb height (m)
GROUND_FLOOR = 4.0  # height of shop fronts (m)
LANE_X = 1.75  # centre of the right-hand driving lane (m)
CAMERA_HEIGHT = 1.65  # camera above the road (m)
SPEED = 4.0  # mean driving speed (m/s)
AHEAD, BEHIND = 300.0, 2.0  # generated street around the camera (m)
FOG = (90.0, 290.0)  # fog from ... to ... (m): hides where the street ends
#: Sunlight: direction towards the sun (scene frame: from the left, behind, 40 deg high),
#: irradiance on a surface facing it and sky light everywhere, relative to the exposure's
#: white; the exposure is set for the sunlit road, so the sky saturates.
SUN = sun_light((-0.6, -0.64, -0.45), sun=0.7, ambient=0.04)
SKY_LIGHT = 12.0


class UrbanWorld(World):
    """Street with facades, shops, pavements, parked cars, poles and signs under a clear sky."""

    name = "urban"
    fps = 10.0
    intrinsics = (718.856, 718.856, 607.1928, 185.2157, 1240, 376)
    baseline = 0.54
    default_sensor = "stereo"
    psf_sigma_px = 0.8
    TILE_NAMES = URBAN_TILES

    def __init__(self, seed: int):
        super().__init__(seed)
        rng = np.random.default_rng([self.seed, 0x0A7])
        phase = rng.uniform(0, 2 * np.pi, 8)
        # Rows (amplitude, period s, phase rad). Yaw follows the heading of the lateral sway.
        self._sway = np.array([[0.22, 9.0, phase[0]], [0.06, 3.7, phase[1]]])
        heading = [[a * 2 * np.pi / p / SPEED, p, f + np.pi / 2] for a, p, f in self._sway]
        self._yaw = np.array([*heading, [0.004, 2.3, phase[2]]])
        self._bob = np.array([[0.012, 1.1, phase[3]], [0.008, 0.43, phase[4]]])
        self._surge = np.array([[0.4, 13.0, phase[5]]])
        self._pitch = np.array([[0.005, 1.1, phase[3]], [0.003, 2.9, phase[6]]])
        self._roll = np.array([[0.004, 2.3, phase[7]]])
        self._block = lru_cache(maxsize=64)(self._make_block)

    def pose(self, t: float) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = rotation(wave(t, self._yaw), wave(t, self._pitch), wave(t, self._roll))
        T[:3, 3] = (LANE_X + wave(t, self._sway), -CAMERA_HEIGHT + wave(t, self._bob), SPEED * t + wave(t, self._surge))
        return T

    def stage(self, eye: np.ndarray) -> Stage:
        """Blocks from just behind ``eye`` to ``AHEAD`` metres on, farthest first: blocks are
        split by planes z = const, so a nearer block can hide a farther one, never the reverse."""
        here = math.floor(eye[2] / BLOCK)
        blocks = range(math.floor((eye[2] - BEHIND) / BLOCK), math.floor((eye[2] + AHEAD) / BLOCK) + 1)
        order = sorted(blocks, key=lambda k: -abs(k - here))
        return Stage(groups=tuple(self._block(k) for k in order), sky_tile=self.tiles["sky"], fog=FOG, light=SUN, sky_light=SKY_LIGHT)

    def paint_tiles(self, rng: np.random.Generator) -> dict[str, np.ndarray]:
        return paint_urban(rng)

    # -- one block ---------------------------------------------------------------------------
    def _make_block(self, k: int) -> Boxes:
        """Block ``k`` (``k * BLOCK <= z < (k + 1) * BLOCK``): road, paint, pavements,
        buildings, parked cars and poles on both sides."""
        rng = np.random.default_rng([self.seed, 0xB10C, k + (1 << 40)])
        z0, z1 = k * BLOCK, (k + 1) * BLOCK
        b = BoxBuilder()
        b.add((-ROAD, 0, z0), (ROAD, 0.2, z1), {"-y": (self.tiles[f"asphalt{rng.integers(2)}"], 64, 16)})
        self._road_paint(b, rng, z0, z1)
        for side in (-1, 1):
            paving, kerb = self.tiles["paving"], self.tiles["kerb"]
            _side_box(b, side, ROAD, 40.0, -KERB, 0.0, z0, z1, {"-y": (paving, 128, 128), "street": (kerb, 128, TILE / KERB)})
            self._buildings(b, rng, side, z0, z1)
            self._parked_cars(b, rng, side, z0, z1)
            self._pole(b, rng, side, z0, z1)
        return b.build()

    def _road_paint(self, b: BoxBuilder, rng: np.random.Generator, z0: float, z1: float) -> None:
        """Dashed centre line (3 m dash, 8 m period), solid lines at the parking strips and,
        in some blocks, a zebra crossing. Paint is a zero-thickness box on the road."""
        paint = {"-y": (self.tiles["paint"], 64, 64)}
        for z in np.arange(z0 + 1.0, z1, 8.0):
            b.add((-0.06, 0, z), (0.06, 0, z + 3.0), paint)
        for x in (-LANE_LINE, LANE_LINE):
            b.add((x - 0.06, 0, z0), (x + 0.06, 0, z1), paint)
        if rng.random() < 0.15:
            z = z0 + 20.0
            for x in np.arange(-ROAD + 0.2, ROAD - 0.5, 1.0):
                b.add((x, 0, z), (x + 0.5, 0, z + 3.0), paint)

    def _buildings(self, b: BoxBuilder, rng: np.random.Generator, side: int, z0: float, z1: float) -> None:
        """Buildings of 2-5 bays side by side: a shop-front storey and 2-7 upper storeys;
        most stand on the building line, some are set back, a few behind a forecourt."""
        z = z0
        while z < z1 - 1e-6:
            bay = rng.uniform(3.2, 4.4)
            width = int(rng.integers(2, 6)) * bay
            if z1 - (z + width) < 3.0:
                width = z1 - z
            r = rng.random()
            setback = rng.uniform(12.0, 18.0) if r < 0.3 else rng.uniform(0.6, 2.5) if r < 0.6 else 0.0
            storeys, storey = int(rng.integers(1, 4)), rng.uniform(3.0, 3.4)
            facade = self.tiles[f"facade{rng.integers(FACADES)}"]
            shop = self.tiles[f"shop{rng.integers(SHOPS)}"]
            gable = self.tiles[f"side{rng.integers(SIDES)}"]
            near, far = FACADE + setback, FACADE + setback + 14.0
            top = -KERB - GROUND_FLOOR
            ends = (gable, 64, TILE / GROUND_FLOOR)
            _side_box(
                b,
                side,
                near,
                far,
                top,
                -KERB,
                z,
                z + width,
                {"street": (shop, TILE / (2 * bay), TILE / GROUND_FLOOR), "-z": ends, "+z": ends},
            )
            ends = (gable, 64, TILE / storey)
            _side_box(
                b,
                side,
                near,
                far,
                top - storeys * storey,
                top,
                z,
                z + width,
                {"street": (facade, TILE / bay, TILE / storey), "-z": ends, "+z": ends},
            )
            z += width

    def _parked_cars(self, b: BoxBuilder, rng: np.random.Generator, side: int, z0: float, z1: float) -> None:
        """Cars in the parking strip: body box (1 m) and a narrower cabin box (0.5 m) on top."""
        z = z0 + rng.uniform(0.3, 3.0)
        while True:
            length = rng.uniform(3.9, 4.6)
            if z + length > z1 - 0.1:
                return
            if rng.random() < 0.6:
                colour = int(rng.integers(len(CAR_COLOURS)))
                body, top = self.tiles[f"car_side{colour}"], self.tiles[f"car_top{colour}"]
                end, glass, screen = self.tiles["car_end"], self.tiles["cabin_side"], self.tiles["cabin_end"]
                near, far = ROAD - 1.85, ROAD - 0.05
                sides: Face = (body, TILE / length, TILE)
                ends: Face = (end, TILE / 1.8, TILE)
                _side_box(
                    b,
                    side,
                    near,
                    far,
                    -1.0,
                    0.0,
                    z,
                    z + length,
                    {"street": sides, "back": sides, "-z": ends, "+z": ends, "-y": (top, TILE / 1.8, TILE / length)},
                )
                cabin = length - 2.0
                sides, ends = (glass, TILE / cabin, TILE / 0.5), (screen, TILE / 1.56, TILE / 0.5)
                _side_box(
                    b,
                    side,
                    near + 0.12,
                    far - 0.12,
                    -1.5,
                    -1.0,
                    z + 0.9,
                    z + 0.9 + cabin,
                    {"street": sides, "back": sides, "-z": ends, "+z": ends, "-y": (top, TILE / 1.56, TILE / cabin)},
                )
            z += length + rng.uniform(0.8, 4.0)

    def _pole(self, b: BoxBuilder, rng: np.random.Generator, side: int, z0: float, z1: float) -> None:
        """A lamp post on the pavement, often carrying a traffic sign facing the traffic."""
        if rng.random() > 0.8:
            return
        z = z0 + rng.uniform(2.0, BLOCK - 2.0)
        metal = (self.tiles["pole"], TILE / 0.6, TILE / 2.0)
        near = ROAD + 0.35
        _side_box(b, side, near, near + 0.15, -5.2, -KERB, z, z + 0.15, {"street": metal, "back": metal, "-z": metal, "+z": metal})
        if rng.random() < 0.7:
            sign = (self.tiles[f"sign{rng.integers(SIGNS)}"], TILE / 0.65, TILE / 0.65)
            centre = near + 0.075
            _side_box(
                b,
                side,
                centre - 0.325,
                centre + 0.325,
                -3.0,
                -2.35,
                z - 0.03,
                z,
                {"-z": sign, "+z": metal, "street": metal, "back": metal, "+y": metal},
            )


def _side_box(
    b: BoxBuilder,
    side: int,
    near: float,
    far: float,
    y0: float,
    y1: float,
    z0: float,
    z1: float,
    faces: dict[str, Face],
) -> None:
    """Add a box between ``near`` and ``far`` metres from the centre line on ``side`` (-1 left,
    +1 right); face names ``street`` (towards the road) and ``back`` are mapped to x faces."""
    street, back = ("-x", "+x") if side > 0 else ("+x", "-x")
    names = {"street": street, "back": back}
    x0, x1 = (near, far) if side > 0 else (-far, -near)
    b.add((x0, y0, z0), (x1, y1, z1), {names.get(name, name): spec for name, spec in faces.items()})
