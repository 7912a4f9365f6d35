"""Tiles of the urban street: sky, asphalt, road paint, paving, kerb, facades, shop fronts,
side walls, cars, poles and traffic signs (see ``textures`` for the primitives)."""

from __future__ import annotations

import cv2
import numpy as np

from sal_adapters.synthetic.atlas import TILE
from sal_adapters.synthetic.textures import (
    bricks,
    canvas,
    finish,
    grain,
    lettering,
    noise,
    planks,
    sky,
    speckle,
    vary,
    window,
    write,
)

__all__ = ["CAR_COLOURS", "FACADES", "SHOPS", "SIDES", "SIGNS", "URBAN_TILES", "paint_urban"]

FACADES = 8
SHOPS = 6
SIDES = 3
CAR_COLOURS = ((170, 30, 35), (35, 70, 150), (175, 178, 182), (30, 32, 36), (225, 225, 220))
SIGNS = 4

URBAN_TILES: tuple[str, ...] = (
    "sky",
    "asphalt0",
    "asphalt1",
    "paint",
    "paving",
    "kerb",
    *(f"facade{k}" for k in range(FACADES)),
    *(f"shop{k}" for k in range(SHOPS)),
    *(f"side{k}" for k in range(SIDES)),
    *(f"car_side{k}" for k in range(len(CAR_COLOURS))),
    *(f"car_top{k}" for k in range(len(CAR_COLOURS))),
    "car_end",
    "cabin_side",
    "cabin_end",
    "pole",
    *(f"sign{k}" for k in range(SIGNS)),
)

WALL_COLOURS = (
    (150, 70, 55),
    (205, 190, 160),
    (160, 160, 155),
    (215, 190, 120),
    (230, 228, 215),
    (120, 90, 70),
    (175, 120, 90),
    (140, 150, 160),
)
VIVID = ((200, 40, 40), (30, 110, 190), (30, 140, 70), (230, 170, 30), (120, 50, 140), (20, 20, 20))


def paint_urban(rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Every tile of ``URBAN_TILES``."""
    tiles = {
        "sky": sky(vary(rng, (62, 112, 190), 10), vary(rng, (196, 212, 228), 6)),
        "asphalt0": _asphalt(rng),
        "asphalt1": _asphalt(rng),
        "paint": _paint(rng),
        "paving": _paving(rng),
        "kerb": _kerb(rng),
    }
    tiles.update({f"facade{k}": _facade(rng) for k in range(FACADES)})
    tiles.update({f"shop{k}": _shop(rng) for k in range(SHOPS)})
    tiles.update({f"side{k}": _side(rng) for k in range(SIDES)})
    for k, colour in enumerate(CAR_COLOURS):
        tiles[f"car_side{k}"] = _car_side(rng, colour)
        tiles[f"car_top{k}"] = _car_top(rng, colour)
    tiles["car_end"] = _car_end(rng)
    tiles["cabin_side"] = _cabin(rng, pillars=3)
    tiles["cabin_end"] = _cabin(rng, pillars=2)
    tiles["pole"] = _pole(rng)
    tiles.update({f"sign{k}": _sign(rng, k) for k in range(SIGNS)})
    return tiles


def _asphalt(rng: np.random.Generator) -> np.ndarray:
    """Grey asphalt, 4 m per tile: faint mottling and stones (worn fine aggregate), a repaired
    patch and a few tar-sealed cracks, all of low contrast, as on a real road in daylight."""
    tile = canvas(vary(rng, (95, 95, 98), 8))
    tile *= (1.0 + 0.05 * noise(rng, 8, 4))[..., None]
    corners = rng.integers(10, 246, (2, 2))
    x0, x1 = sorted(int(v) for v in corners[:, 0])
    y0, y1 = sorted(int(v) for v in corners[:, 1])
    tile[y0:y1, x0:x1] *= rng.choice([0.85, 1.12])
    speckle(tile, rng, 700, [(112, 111, 108), (104, 103, 100), (82, 82, 85), (76, 76, 79)], (1, 2))
    for _ in range(2):
        steps = rng.integers(-28, 29, (7, 2))
        points = np.cumsum(steps, axis=0) + rng.integers(30, 226, 2)
        cv2.polylines(tile, [points.astype(np.int32)], False, (62, 62, 64), 2, cv2.LINE_AA)
    return finish(tile + grain(rng, 3))


def _paint(rng: np.random.Generator) -> np.ndarray:
    """Worn white road paint."""
    tile = canvas((228, 228, 222))
    wear = noise(rng, 16, 2)
    tile -= np.clip(wear - 1.0, 0, None)[..., None] * 60
    return finish(tile + grain(rng, 6))


def _paving(rng: np.random.Generator) -> np.ndarray:
    """Concrete slabs of 0.5 m (4 x 4 per 2 m tile) with dark joints."""
    tile = canvas((0, 0, 0))
    base = np.asarray(vary(rng, (170, 165, 155), 15))
    step = TILE // 4
    for row in range(4):
        for col in range(4):
            tile[row * step + 2 : (row + 1) * step - 1, col * step + 2 : (col + 1) * step - 1] = base + rng.uniform(-16, 16)
    tile[tile.sum(axis=2) == 0] = (55, 54, 52)
    tile *= (1.0 + 0.06 * noise(rng, 16, 3))[..., None]
    speckle(tile, rng, 300, [(110, 108, 102), (215, 212, 205)], (1, 2))
    return finish(tile + grain(rng, 5))


def _kerb(rng: np.random.Generator) -> np.ndarray:
    """Granite kerb stones of 1 m with joints and a light top edge."""
    tile = canvas(vary(rng, (150, 150, 148), 10))
    speckle(tile, rng, 900, [(90, 90, 92), (205, 205, 200), (60, 60, 62)], (1, 2))
    tile[:30] *= 1.2
    for x in (0, TILE // 2):
        tile[:, x : x + 3] = (60, 60, 60)
    return finish(tile + grain(rng, 8))


def _wall(rng: np.random.Generator, colour: tuple[float, float, float]) -> np.ndarray:
    """Brickwork (half of the walls) or rendered ashlar blocks with joints, in ``colour``,
    speckled and weathered."""
    tile = canvas(colour)
    light = sum(colour) > 480
    if rng.random() < 0.5:
        mortar = tuple(0.5 * c for c in colour) if light else vary(rng, (200, 196, 186), 10)
        bricks(tile, rng, 32, 16, colour, mortar)
    else:
        bricks(tile, rng, 8, 4, colour, tuple(0.5 * c for c in colour), 10)
        speckle(tile, rng, 250, [tuple(0.75 * c for c in colour), tuple(min(255.0, 1.15 * c) for c in colour)], (1, 1))
    tile *= (1.0 + 0.03 * noise(rng, 4, 2))[..., None]
    return tile


def _facade(rng: np.random.Generator) -> np.ndarray:
    """One bay of one storey: wall, a framed window, optional shutters, balcony and cornice."""
    colour = vary(rng, WALL_COLOURS[int(rng.integers(len(WALL_COLOURS)))], 15)
    tile = _wall(rng, colour)
    half_w = int(rng.integers(50, 72))
    y0, y1 = int(rng.integers(55, 80)), int(rng.integers(180, 205))
    frame = (235, 232, 225) if rng.random() < 0.6 else vary(rng, (60, 55, 50), 15)
    if rng.random() < 0.3:
        shutter = vary(rng, VIVID[int(rng.integers(len(VIVID)))], 20)
        for x in (TILE // 2 - half_w - 44, TILE // 2 + half_w + 8):
            cv2.rectangle(tile, (x, y0 - 4), (x + 36, y1 + 4), shutter, -1)
            for y in range(y0, y1, 9):
                cv2.line(tile, (x, y), (x + 36, y), tuple(0.7 * np.asarray(shutter, np.float64)), 2)
    panes = [(2, 2), (2, 1), (1, 2), (3, 2)][int(rng.integers(4))]
    window(tile, rng, (TILE // 2 - half_w, y0, TILE // 2 + half_w, y1), frame, panes, lit=rng.random() < 0.15)
    if rng.random() < 0.35:
        rail = vary(rng, (40, 40, 45), 10)
        cv2.rectangle(tile, (TILE // 2 - half_w - 20, y1 + 12), (TILE // 2 + half_w + 20, y1 + 16), rail, -1)
        for x in range(TILE // 2 - half_w - 20, TILE // 2 + half_w + 21, 10):
            cv2.line(tile, (x, y1 + 16), (x, y1 + 48), rail, 2)
        cv2.rectangle(tile, (TILE // 2 - half_w - 20, y1 + 46), (TILE // 2 + half_w + 20, y1 + 52), rail, -1)
    if rng.random() < 0.5:
        tile[: int(rng.integers(8, 16))] *= 0.75
    return finish(tile + grain(rng, 3))


def _shop(rng: np.random.Generator) -> np.ndarray:
    """Ground floor of two bays: sign band with lettering, shop window with goods, door, plinth."""
    tile = _wall(rng, vary(rng, WALL_COLOURS[int(rng.integers(len(WALL_COLOURS)))], 15))
    band = vary(rng, VIVID[int(rng.integers(len(VIVID)))], 20)
    cv2.rectangle(tile, (8, 22), (248, 70), band, -1)
    ink = tuple(c + 0.45 * (255 - c) for c in band) if sum(band) < 400 else tuple(0.55 * c for c in band)
    lettering(tile, rng, (18, 60), 28, ink, int(rng.integers(5, 9)), 2)
    window(tile, rng, (22, 96, 168, 228), (40, 40, 42), (int(rng.integers(1, 4)), 1), lit=rng.random() < 0.4)
    for shelf in (140, 184, 226):
        cv2.rectangle(tile, (22, shelf), (168, shelf + 3), (150, 150, 150), -1)
        x = 26 + int(rng.integers(0, 12))
        while x < 150:
            w, h = int(rng.integers(6, 18)), int(rng.integers(10, 34))
            cv2.rectangle(tile, (x, shelf - h), (min(x + w, 166), shelf), vary(rng, VIVID[int(rng.integers(len(VIVID)))], 50), -1)
            x += w + int(rng.integers(3, 14))
    if rng.random() < 0.5:
        stripes = [vary(rng, VIVID[int(rng.integers(len(VIVID)))], 10), (240, 240, 235)]
        for k, x in enumerate(range(8, 176, 14)):
            cv2.rectangle(tile, (x, 74), (x + 13, 90), stripes[k % 2], -1)
    door = vary(rng, (90, 60, 40), 30)
    cv2.rectangle(tile, (184, 96), (240, 250), door, -1)
    cv2.rectangle(tile, (192, 104), (232, 170), (70, 85, 100), -1)
    cv2.circle(tile, (230, 190), 4, (200, 190, 150), -1, cv2.LINE_AA)
    tile[244:] *= 0.6
    return finish(tile + grain(rng, 3))


def _side(rng: np.random.Generator) -> np.ndarray:
    """Side (gable) wall: darker wall with a small window now and then."""
    tile = _wall(rng, vary(rng, WALL_COLOURS[int(rng.integers(len(WALL_COLOURS)))], 15)) * 0.75
    if rng.random() < 0.6:
        window(tile, rng, (100, 80, 156, 160), (200, 200, 195), (1, 2))
    return finish(tile + grain(rng, 3))


def _car_side(rng: np.random.Generator, colour: tuple[int, int, int]) -> np.ndarray:
    """Car body side (4.2 m x 1 m): paint with a highlight, door seams, handles, wheels."""
    tile = canvas(vary(rng, colour, 6))
    tile[40:70] *= 1.15
    tile[118:126] *= 0.45
    for x in rng.integers(0, 200, 2):
        glare = np.array([[x, 10], [x + 30, 10], [x + 10, 110], [x - 20, 110]], np.int32)
        cv2.fillConvexPoly(tile, glare, _floats_scaled(colour, 1.35), cv2.LINE_AA)
    speckle(tile, rng, 60, [(90, 80, 70), (60, 55, 50)], (1, 2))
    tile[180:] = (25, 25, 27)
    for x in (98, 166):
        cv2.line(tile, (x, 10), (x - 6, 190), (20, 20, 20), 2, cv2.LINE_AA)
        cv2.rectangle(tile, (x + 10, 70), (x + 30, 78), (30, 30, 30), -1)
    for x in (46, 210):
        cv2.circle(tile, (x, 206), 52, (40, 40, 44), -1, cv2.LINE_AA)
        cv2.circle(tile, (x, 206), 44, (18, 18, 20), -1, cv2.LINE_AA)
        cv2.circle(tile, (x, 206), 26, (150, 150, 155), -1, cv2.LINE_AA)
        for angle in np.arange(0, 2 * np.pi, 2 * np.pi / 5):
            cv2.line(tile, (x, 206), (int(x + 24 * np.cos(angle)), int(206 + 24 * np.sin(angle))), (70, 70, 75), 4, cv2.LINE_AA)
    return finish(tile + grain(rng, 2))


def _floats_scaled(colour: tuple[int, int, int], factor: float) -> tuple[float, ...]:
    """A brighter ``colour``: ``factor * c + 20`` per channel, at most 255 (glare)."""
    return tuple(min(255.0, factor * c + 20.0) for c in colour)


def _car_top(rng: np.random.Generator, colour: tuple[int, int, int]) -> np.ndarray:
    """Bonnet and boot seen from above: paint with seams."""
    tile = canvas(vary(rng, colour, 6)) * 1.05
    for y in (70, 190):
        cv2.line(tile, (10, y), (246, y), (25, 25, 25), 2, cv2.LINE_AA)
    tile *= (1.0 + 0.04 * noise(rng, 4, 2))[..., None]
    return finish(tile + grain(rng, 2))


def _car_end(rng: np.random.Generator) -> np.ndarray:
    """Front or back of a car: lamps, grille, number plate, black bumper."""
    tile = canvas((60, 60, 64))
    for x in (20, 176):
        cv2.rectangle(tile, (x, 40), (x + 60, 90), (210, 40, 30), -1)
        cv2.rectangle(tile, (x + 8, 48), (x + 30, 82), (240, 160, 60), -1)
    for y in range(100, 150, 8):
        cv2.line(tile, (90, y), (166, y), (25, 25, 25), 3)
    cv2.rectangle(tile, (80, 160), (176, 190), (235, 235, 230), -1)
    lettering(tile, rng, (88, 184), 18, (20, 20, 20), 5, 2)
    tile[200:] = (25, 25, 27)
    return finish(tile + grain(rng, 2))


def _cabin(rng: np.random.Generator, pillars: int) -> np.ndarray:
    """Cabin glass with a sky reflection between black pillars."""
    tile = canvas((40, 40, 44))
    edges = np.linspace(0, TILE, pillars, dtype=int)
    for x0, x1 in zip(edges[:-1], edges[1:]):
        window(tile, rng, (x0 + 14, 24, x1 - 14, 240), (30, 30, 32), (1, 1))
    return finish(tile + grain(rng, 2))


def _pole(rng: np.random.Generator) -> np.ndarray:
    """Galvanised metal: vertical streaks and bands."""
    tile = canvas((140, 145, 150))
    tile *= (1.0 + 0.12 * noise(rng, (2, 32), 2))[..., None]
    for y in range(0, TILE, 64):
        tile[y : y + 6] *= 0.7
    return finish(tile + grain(rng, 4))


def _sign(rng: np.random.Generator, kind: int) -> np.ndarray:
    """Traffic signs: speed limit, blue arrow, warning triangle, street name."""
    tile = canvas((150, 150, 155))
    c = (TILE // 2, TILE // 2)
    if kind == 0:
        cv2.circle(tile, c, 120, (200, 30, 30), -1, cv2.LINE_AA)
        cv2.circle(tile, c, 92, (245, 245, 240), -1, cv2.LINE_AA)
        write(tile, str(int(rng.choice([30, 50, 70]))), (58, 160), 3.2, (10, 10, 10), 10)
    elif kind == 1:
        cv2.circle(tile, c, 120, (30, 80, 180), -1, cv2.LINE_AA)
        cv2.arrowedLine(tile, (128, 200), (128, 60), (245, 245, 240), 22, cv2.LINE_AA, 0, 0.45)
    elif kind == 2:
        triangle = np.array([[128, 10], [250, 230], [6, 230]], np.int32)
        cv2.fillConvexPoly(tile, triangle, (200, 30, 30), cv2.LINE_AA)
        cv2.fillConvexPoly(tile, np.array([[128, 50], [215, 210], [41, 210]], np.int32), (245, 245, 240), cv2.LINE_AA)
        cv2.rectangle(tile, (118, 90), (138, 165), (10, 10, 10), -1)
        cv2.circle(tile, (128, 188), 11, (10, 10, 10), -1, cv2.LINE_AA)
    else:
        planks(tile, rng, 1, (30, 120, 70), 0)
        cv2.rectangle(tile, (8, 60), (248, 196), (245, 245, 240), 5)
        lettering(tile, rng, (22, 148), 52, (245, 245, 240), 5, 5)
    return finish(tile + grain(rng, 2))
