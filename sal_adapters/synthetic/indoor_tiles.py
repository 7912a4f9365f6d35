"""Tiles of the indoor room: walls, floor, ceiling, posters, pictures, whiteboard, door,
window, furniture surfaces (see ``textures`` for the primitives)."""

from __future__ import annotations

import cv2
import numpy as np

from sal_adapters.synthetic.atlas import TILE
from sal_adapters.synthetic.textures import (
    bricks,
    canvas,
    finish,
    grain,
    grid_lines,
    lettering,
    noise,
    planks,
    speckle,
    vary,
    window,
)

__all__ = ["CRATES", "INDOOR_TILES", "PICTURES", "POSTERS", "WALLS", "paint_indoor"]

WALLS = 4
POSTERS = 6
PICTURES = 2
CRATES = 2

INDOOR_TILES: tuple[str, ...] = (
    *(f"wall{k}" for k in range(WALLS)),
    "floor",
    "ceiling",
    "rug",
    *(f"poster{k}" for k in range(POSTERS)),
    *(f"picture{k}" for k in range(PICTURES)),
    "whiteboard",
    "door",
    "window",
    "books",
    "drawers",
    "wood",
    "fabric",
    *(f"crate{k}" for k in range(CRATES)),
    "metal",
    "screen",
)

BRIGHT = ((220, 60, 50), (40, 120, 200), (250, 190, 40), (60, 160, 90), (140, 70, 160), (240, 120, 40), (30, 30, 35), (235, 235, 230))


def paint_indoor(rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Every tile of ``INDOOR_TILES``."""
    tiles = {f"wall{k}": _wall(rng, k) for k in range(WALLS)}
    tiles["floor"] = _floor(rng)
    tiles["ceiling"] = _ceiling(rng)
    tiles["rug"] = _rug(rng)
    tiles.update({f"poster{k}": _poster(rng) for k in range(POSTERS)})
    tiles.update({f"picture{k}": _picture(rng) for k in range(PICTURES)})
    tiles["whiteboard"] = _whiteboard(rng)
    tiles["door"] = _door(rng)
    tiles["window"] = _window(rng)
    tiles["books"] = _books(rng)
    tiles["drawers"] = _drawers(rng)
    wood = canvas((0, 0, 0))
    planks(wood, rng, 4, vary(rng, (150, 105, 65), 20), 12)
    tiles["wood"] = finish(wood + grain(rng, 3))
    tiles["fabric"] = _fabric(rng)
    tiles.update({f"crate{k}": _crate(rng) for k in range(CRATES)})
    metal = canvas((150, 152, 158)) * (1.0 + 0.08 * noise(rng, (64, 2), 2))[..., None]
    tiles["metal"] = finish(metal + grain(rng, 4))
    tiles["screen"] = _screen(rng)
    return tiles


def _wall(rng: np.random.Generator, style: int) -> np.ndarray:
    """2 m of wall, floor to ceiling: patterned wallpaper, painted brick, panelling or tiles,
    above a skirting board."""
    colour = vary(rng, [(215, 205, 185), (190, 205, 215), (200, 215, 190), (225, 215, 200)][style], 12)
    tile = canvas(colour)
    if style == 0:
        motif = vary(rng, BRIGHT[int(rng.integers(len(BRIGHT)))], 20)
        for y in range(8, TILE, 32):
            for x in range(8 + (y // 32 % 2) * 16, TILE, 32):
                cv2.fillConvexPoly(tile, np.array([[x, y - 7], [x + 6, y], [x, y + 7], [x - 6, y]], np.int32), motif, cv2.LINE_AA)
    elif style == 1:
        bricks(tile, rng, 32, 8, colour, tuple(c * 0.8 for c in colour), 10)
    elif style == 2:
        panel = canvas((0, 0, 0))
        planks(panel, rng, 8, vary(rng, (140, 95, 60), 10), 8, vertical=True)
        tile[150:] = panel[150:]
        tile[146:152] = (110, 75, 45)
        stripe = tuple(0.5 * (a + b) for a, b in zip(colour, vary(rng, BRIGHT[int(rng.integers(len(BRIGHT)))], 20)))
        for x in range(0, TILE, 32):
            tile[:146, x + 12 : x + 20] = stripe
            for y in range(8, 140, 24):
                cv2.circle(tile, (x + 28, y + (x // 32 % 2) * 12), 3, stripe, -1, cv2.LINE_AA)
    else:
        grid_lines(tile, 16, tuple(c * 0.75 for c in colour), 2)
        for _ in range(30):
            x, y = (int(v) * 16 for v in rng.integers(0, 16, 2))
            tile[y + 2 : y + 16, x + 2 : x + 16] = vary(rng, BRIGHT[int(rng.integers(len(BRIGHT)))], 20)
    tile *= (1.0 + 0.03 * noise(rng, 8, 3))[..., None]
    tile[244:] = vary(rng, (90, 70, 55), 15)
    tile[244:246] *= 1.3
    return finish(tile + grain(rng, 3))


def _floor(rng: np.random.Generator) -> np.ndarray:
    """Oak planks (2 m per tile) or a checkerboard of 0.5 m tiles."""
    tile = canvas((0, 0, 0))
    if rng.random() < 0.6:
        planks(tile, rng, 8, vary(rng, (175, 128, 82), 20), 40, vertical=True, joints=3)
    else:
        a, b = vary(rng, (200, 195, 185), 10), vary(rng, (70, 75, 80), 10)
        for row in range(4):
            for col in range(4):
                tile[row * 64 : row * 64 + 64, col * 64 : col * 64 + 64] = a if (row + col) % 2 else b
        tile *= (1.0 + 0.05 * noise(rng, 16, 3))[..., None]
        speckle(tile, rng, 500, [(30, 30, 32), (235, 235, 230), (150, 60, 50)], (1, 2))
        grid_lines(tile, 4, (120, 120, 120), 2)
    return finish(tile + grain(rng, 4))


def _ceiling(rng: np.random.Generator) -> np.ndarray:
    """Suspended ceiling: 4 x 4 perforated panels in a dark metal grid, a light, a vent and
    sprinklers."""
    tile = canvas(vary(rng, (225, 225, 220), 5))
    speckle(tile, rng, 900, [(120, 120, 118), (160, 160, 155)], (1, 2))
    grid_lines(tile, 4, (110, 110, 115), 4)
    tile[70:122, 134:186] = (250, 250, 245)
    for x in range(140, 186, 10):
        tile[70:122, x : x + 2] = (170, 170, 175)
    for y in range(200, 244, 8):
        tile[y : y + 3, 140:180] = (90, 90, 95)
    for x, y in rng.integers(8, 248, (3, 2)).tolist():
        cv2.circle(tile, (x, y), 5, (140, 40, 40), -1, cv2.LINE_AA)
    return finish(tile + grain(rng, 2))


def _rug(rng: np.random.Generator) -> np.ndarray:
    """Patterned rug: borders, a field of diamonds, fringe."""
    ground, accent = vary(rng, (150, 40, 45), 25), vary(rng, (230, 200, 140), 20)
    tile = canvas(ground)
    cv2.rectangle(tile, (12, 12), (243, 243), accent, 6)
    cv2.rectangle(tile, (28, 28), (227, 227), accent, 2)
    for y in range(56, 220, 40):
        for x in range(56, 220, 40):
            cv2.fillConvexPoly(tile, np.array([[x, y - 14], [x + 14, y], [x, y + 14], [x - 14, y]], np.int32), accent, cv2.LINE_AA)
            cv2.circle(tile, (x, y), 4, ground, -1, cv2.LINE_AA)
    tile *= (1.0 + 0.05 * noise(rng, 64, 1))[..., None]
    return finish(tile + grain(rng, 6))


def _poster(rng: np.random.Generator) -> np.ndarray:
    """A poster: coloured ground, bold geometric shapes, a title and small print."""
    colours = [BRIGHT[int(k)] for k in rng.permutation(len(BRIGHT))]
    tile = canvas(vary(rng, colours[0], 20))
    for k in range(int(rng.integers(4, 8))):
        colour, kind = vary(rng, colours[1 + k % 5], 20), int(rng.integers(3))
        x, y, r = int(rng.integers(30, 226)), int(rng.integers(40, 180)), int(rng.integers(12, 50))
        if kind == 0:
            cv2.circle(tile, (x, y), r, colour, -1, cv2.LINE_AA)
        elif kind == 1:
            cv2.rectangle(tile, (x - r, y - r // 2), (x + r, y + r // 2), colour, -1)
        else:
            cv2.fillConvexPoly(tile, np.array([[x, y - r], [x + r, y + r], [x - r, y + r]], np.int32), colour, cv2.LINE_AA)
    ink = colours[-1]
    lettering(tile, rng, (16, 222), 26, ink, int(rng.integers(5, 9)), 3)
    lettering(tile, rng, (16, 244), 11, ink, 14, 1)
    cv2.rectangle(tile, (0, 0), (255, 255), (245, 245, 240), 6)
    return finish(tile + grain(rng, 2))


def _picture(rng: np.random.Generator) -> np.ndarray:
    """A framed landscape: sky, sun, hills, trees."""
    tile = canvas(vary(rng, (120, 170, 220), 20))
    cv2.circle(tile, (int(rng.integers(60, 200)), 70), 22, (250, 230, 150), -1, cv2.LINE_AA)
    for k, base in enumerate((140, 175)):
        xs = np.arange(0, 257, 16)
        ys = base + (20 * np.sin(xs / (30.0 + 15 * k) + rng.uniform(0, 6))).astype(int)
        hill = np.array([[0, 256], *zip(xs, ys), [256, 256]], np.int32)
        cv2.fillPoly(tile, [hill], vary(rng, (70, 130 - 30 * k, 60), 20), cv2.LINE_AA)
    for _ in range(5):
        x, y = int(rng.integers(20, 236)), int(rng.integers(180, 220))
        cv2.rectangle(tile, (x - 2, y), (x + 2, y + 16), (80, 55, 30), -1)
        cv2.circle(tile, (x, y - 6), 10, vary(rng, (40, 100, 40), 15), -1, cv2.LINE_AA)
    cv2.rectangle(tile, (0, 0), (255, 255), vary(rng, (110, 75, 40), 20), 16)
    return finish(tile + grain(rng, 2))


def _whiteboard(rng: np.random.Generator) -> np.ndarray:
    """Whiteboard with an aluminium frame, faded marker scribbles, boxes and words."""
    tile = canvas((240, 242, 240))
    pens = [(110, 130, 200), (205, 110, 110), (120, 120, 120), (110, 170, 125)]
    for _ in range(4):
        points = np.cumsum(rng.integers(-25, 26, (6, 2)), axis=0) + rng.integers(50, 200, 2)
        cv2.polylines(tile, [points.astype(np.int32)], False, pens[int(rng.integers(4))], 2, cv2.LINE_AA)
    for _ in range(2):
        x, y = (int(v) for v in rng.integers(20, 180, 2))
        cv2.rectangle(tile, (x, y), (x + 50, y + 30), pens[0], 2, cv2.LINE_AA)
    for y in (40, 220):
        lettering(tile, rng, (20, y), 18, pens[2], 8, 1)
    cv2.rectangle(tile, (0, 0), (255, 255), (170, 172, 178), 8)
    return finish(tile + grain(rng, 2))


def _door(rng: np.random.Generator) -> np.ndarray:
    """Panelled door (0.9 m x 2.1 m) with a frame and handle."""
    wood = vary(rng, (120, 80, 50), 25)
    tile = canvas(wood)
    planks(tile, rng, 1, wood, 0, vertical=True)
    for y0, y1 in ((30, 110), (140, 235)):
        cv2.rectangle(tile, (40, y0), (216, y1), tuple(c * 0.75 for c in wood), 5)
    cv2.rectangle(tile, (0, 0), (255, 255), (230, 228, 220), 10)
    cv2.circle(tile, (205, 128), 8, (210, 200, 160), -1, cv2.LINE_AA)
    cv2.rectangle(tile, (203, 126), (228, 131), (210, 200, 160), -1)
    return finish(tile + grain(rng, 2))


def _window(rng: np.random.Generator) -> np.ndarray:
    """A window with a bright view and a white frame."""
    tile = canvas((235, 235, 230))
    window(tile, rng, (24, 24, 232, 212), (240, 240, 235), (2, 2), lit=True)
    return finish(tile + grain(rng, 2))


def _books(rng: np.random.Generator) -> np.ndarray:
    """Front of a bookshelf: four shelves of coloured spines of varied height and width."""
    tile = canvas((95, 65, 40))
    for shelf in range(4):
        floor, x = shelf * 64 + 58, 8
        while x < 240:
            width, height = int(rng.integers(6, 16)), int(rng.integers(30, 50))
            spine = vary(rng, BRIGHT[int(rng.integers(len(BRIGHT)))], 40)
            cv2.rectangle(tile, (x, floor - height), (min(x + width, 246), floor), spine, -1)
            tile[floor - height + 6 : floor - height + 9, x + 1 : min(x + width, 246) - 1] *= 0.6
            x += width + 1
        tile[shelf * 64 + 58 : shelf * 64 + 64] = (120, 85, 55)
    tile[:, :6] = tile[:, 250:] = (110, 75, 45)
    return finish(tile + grain(rng, 2))


def _drawers(rng: np.random.Generator) -> np.ndarray:
    """Cabinet front: three drawers with handles and labels."""
    body = vary(rng, (200, 200, 195), 30)
    tile = canvas(body)
    for k in range(3):
        y0 = 12 + k * 82
        cv2.rectangle(tile, (12, y0), (244, y0 + 72), tuple(c * 0.8 for c in body), 3)
        cv2.rectangle(tile, (98, y0 + 20), (158, y0 + 28), (60, 60, 65), -1)
        cv2.rectangle(tile, (110, y0 + 40), (146, y0 + 58), (245, 245, 240), -1)
        lettering(tile, rng, (113, y0 + 54), 10, (20, 20, 20), 3, 1)
    return finish(tile + grain(rng, 2))


def _fabric(rng: np.random.Generator) -> np.ndarray:
    """Woven upholstery with piping seams."""
    tile = canvas(vary(rng, BRIGHT[int(rng.integers(len(BRIGHT) - 2))], 30)) * 0.7
    weave = np.indices((TILE, TILE)).sum(axis=0) % 4 < 2
    tile *= (1.0 + 0.08 * weave + 0.05 * noise(rng, 32, 2))[..., None]
    for y in (0, 128):
        tile[y : y + 3] *= 0.6
    return finish(tile + grain(rng, 4))


def _crate(rng: np.random.Generator) -> np.ndarray:
    """Cardboard box side: tape, printed arrows, logo and text."""
    tile = canvas(vary(rng, (185, 145, 95), 15))
    tile *= (1.0 + 0.05 * noise(rng, (64, 4), 2))[..., None]
    tile[:, 118:138] = (205, 180, 130)
    ink = (40, 40, 45)
    for x in (40, 200):
        cv2.arrowedLine(tile, (x, 90), (x, 40), ink, 5, cv2.LINE_AA, 0, 0.4)
    cv2.circle(tile, (60, 180), 28, ink, 3, cv2.LINE_AA)
    lettering(tile, rng, (140, 190), 20, ink, 4, 2)
    lettering(tile, rng, (30, 240), 12, ink, 12, 1)
    return finish(tile + grain(rng, 3))


def _screen(rng: np.random.Generator) -> np.ndarray:
    """Monitor: black bezel, desktop with windows, text lines and icons."""
    tile = canvas((20, 20, 24))
    tile[14:242, 14:242] = vary(rng, (40, 90, 150), 30)
    for _ in range(3):
        x, y = (int(v) for v in rng.integers(24, 140, 2))
        cv2.rectangle(tile, (x, y), (x + 90, y + 70), (235, 235, 235), -1)
        cv2.rectangle(tile, (x, y), (x + 90, y + 10), vary(rng, (60, 60, 70), 20), -1)
        for line in range(y + 20, y + 64, 9):
            cv2.line(tile, (x + 6, line), (x + int(rng.integers(30, 84)), line), (90, 90, 90), 2)
    for y in range(24, 200, 34):
        cv2.rectangle(tile, (222, y), (236, y + 14), vary(rng, (230, 200, 80), 40), -1)
    return finish(tile + grain(rng, 2))
