"""Procedural texture primitives: periodic noise, bricks, planks, windows, lettering, sky.

Every function works on ``TILE x TILE`` RGB tiles (uint8, or float32 while painting) and
keeps them periodic (what leaves one edge re-enters the opposite one), as the atlas wraps
tiles over faces. Randomness comes from the ``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from sal_adapters.synthetic.atlas import TILE

__all__ = [
    "SKY_HORIZON",
    "SKY_SLOPE",
    "Colour",
    "bricks",
    "canvas",
    "finish",
    "grain",
    "grid_lines",
    "lettering",
    "noise",
    "planks",
    "sky",
    "speckle",
    "vary",
    "window",
    "write",
]

#: Sky tile row of the horizon, and rows per unit of ``tan(depression angle)``: the sky is
#: sampled at ``t = SKY_HORIZON + SKY_SLOPE * dy / dz`` (rows < SKY_HORIZON are above it).
SKY_HORIZON = 232.0
SKY_SLOPE = 560.0

Colour = Sequence[float]


def canvas(colour: Colour) -> np.ndarray:
    """A float32 tile filled with ``colour`` (RGB, 0..255)."""
    return np.tile(np.asarray(colour, np.float32), (TILE, TILE, 1))


def finish(tile: np.ndarray) -> np.ndarray:
    """Round and clip a float tile to uint8."""
    return np.clip(tile + 0.5, 0, 255).astype(np.uint8)


def noise(rng: np.random.Generator, cells: int | tuple[int, int], octaves: int = 1) -> np.ndarray:
    """Smooth periodic noise (``TILE x TILE`` float32, unit standard deviation): random values
    on a grid of ``cells`` (or ``(rows, columns)``, powers of two), bicubically interpolated,
    summed over ``octaves`` doublings of the grid with halving weights."""
    rows, columns = (cells, cells) if isinstance(cells, int) else cells
    total = np.zeros((TILE, TILE), np.float32)
    for octave in range(octaves):
        ny, nx = min(rows * 2**octave, TILE), min(columns * 2**octave, TILE)
        sy, sx = TILE // ny, TILE // nx
        padded = np.pad(rng.standard_normal((ny, nx)).astype(np.float32), 2, mode="wrap")
        big = cv2.resize(padded, (padded.shape[1] * sx, padded.shape[0] * sy), interpolation=cv2.INTER_CUBIC)
        total += big[2 * sy : 2 * sy + TILE, 2 * sx : 2 * sx + TILE] * np.float32(0.5**octave)
    return total / np.float32(max(float(total.std()), 1e-6))


def grain(rng: np.random.Generator, amplitude: float) -> np.ndarray:
    """Per-texel Gaussian noise of standard deviation ``amplitude`` (``TILE x TILE x 1``)."""
    return rng.normal(0.0, amplitude, (TILE, TILE, 1)).astype(np.float32)


def speckle(tile: np.ndarray, rng: np.random.Generator, count: int, colours: Sequence[Colour], radius: tuple[int, int] = (1, 2)) -> None:
    """Scatter ``count`` small discs (stones, flecks) of random ``colours``, wrapping at edges."""
    centres = rng.integers(0, TILE, (count, 2))
    radii = rng.integers(radius[0], radius[1] + 1, count)
    picks = rng.integers(0, len(colours), count)
    palette = [_floats(c) for c in colours]
    for (x, y), r, pick in zip(centres.tolist(), radii.tolist(), picks.tolist()):
        xs = [x] + ([x - TILE] if x + r >= TILE else []) + ([x + TILE] if x - r < 0 else [])
        ys = [y] + ([y - TILE] if y + r >= TILE else []) + ([y + TILE] if y - r < 0 else [])
        for cx in xs:
            for cy in ys:
                cv2.circle(tile, (cx, cy), r, palette[pick], -1, cv2.LINE_AA)


def vary(rng: np.random.Generator, colour: Colour, spread: float) -> tuple[float, float, float]:
    """``colour`` with each channel moved by up to ``spread`` and the brightness by up to ``spread``."""
    base = np.asarray(colour, np.float64) + rng.uniform(-spread, spread) + rng.uniform(-spread / 2, spread / 2, 3)
    r, g, b = np.clip(base, 0, 255)
    return float(r), float(g), float(b)


def bricks(
    tile: np.ndarray, rng: np.random.Generator, rows: int, columns: int, colour: Colour, mortar: Colour, spread: float = 18.0
) -> None:
    """Running-bond brickwork: ``rows`` courses of ``columns`` bricks, half-brick offset
    every other course (``rows`` even keeps it periodic), mortar joints 2 texels."""
    h, w = TILE // rows, TILE // columns
    tile[:] = np.asarray(mortar, np.float32)
    for row in range(rows):
        shift = (w // 2) * (row % 2)
        for col in range(columns + 1):
            x0 = col * w - shift
            brick = vary(rng, colour, spread)
            for x in (x0, x0 + TILE):
                cv2.rectangle(tile, (x + 1, row * h + 1), (x + w - 2, row * h + h - 2), brick, -1)


def planks(
    tile: np.ndarray, rng: np.random.Generator, count: int, colour: Colour, spread: float = 20.0, vertical: bool = False, joints: int = 1
) -> None:
    """``count`` wooden boards with long grain and dark seams (horizontal boards unless
    ``vertical``); each board has its own shade and ``joints`` butt joints with nail holes."""
    size = TILE // count
    board = np.zeros_like(tile)
    for k in range(count):
        rows = slice(k * size, (k + 1) * size)
        board[rows] = vary(rng, colour, spread)
        for joint in rng.integers(0, TILE - 2, joints):
            board[rows, joint : joint + 2] *= 0.4
            if size >= 16:
                for y in (k * size + size // 4, k * size + 3 * size // 4):
                    board[y : y + 3, joint + 4 : joint + 7] *= 0.25
        if size >= 16 and rng.random() < 0.7:
            x, y = int(rng.integers(8, TILE - 8)), k * size + int(rng.integers(size // 4, 3 * size // 4))
            cv2.ellipse(board, (x, y), (7, 3), 0, 0, 360, _floats(np.asarray(board[y, x]) * 0.45), -1, cv2.LINE_AA)
        board[k * size : k * size + 2] *= 0.4
    board *= (1.0 + 0.1 * noise(rng, (64, 2), 2) + 0.03 * noise(rng, 64))[..., None]
    tile[:] = board.transpose(1, 0, 2) if vertical else board


def grid_lines(tile: np.ndarray, count: int, colour: Colour, width: int = 2) -> None:
    """A square grid of ``count x count`` cells drawn with ``width``-texel lines (tiles, panels)."""
    step = TILE // count
    for k in range(count):
        tile[k * step : k * step + width, :] = colour
        tile[:, k * step : k * step + width] = colour


def window(
    tile: np.ndarray,
    rng: np.random.Generator,
    rect: tuple[int, int, int, int],
    frame: Colour,
    panes: tuple[int, int] = (2, 2),
    lit: bool = False,
) -> None:
    """A framed window ``rect = (x0, y0, x1, y1)``: glass with a sky reflection gradient,
    ``panes`` (columns, rows) separated by mullions, a sill and an inner shadow."""
    x0, y0, x1, y1 = rect
    cv2.rectangle(tile, (x0 - 4, y0 - 4), (x1 + 4, y1 + 4), frame, -1)
    glass_top = np.asarray((210, 190, 120) if lit else vary(rng, (95, 120, 145), 25), np.float32)
    glass_bottom = glass_top * 0.45
    ramp = np.linspace(0.0, 1.0, y1 - y0, dtype=np.float32)[:, None, None]
    tile[y0:y1, x0:x1] = glass_top + ramp * (glass_bottom - glass_top)
    lean = (y1 - y0) // 3
    if x1 - x0 > lean + 2:
        x = x0 + int(rng.integers(lean + 1, x1 - x0))
        cv2.line(tile, (x, y0), (x - lean, y1 - 1), _floats(glass_top * 1.15), 5, cv2.LINE_AA)
    cols, rows = panes
    for k in range(1, cols):
        x = x0 + (x1 - x0) * k // cols
        cv2.rectangle(tile, (x - 2, y0), (x + 2, y1), frame, -1)
    for k in range(1, rows):
        y = y0 + (y1 - y0) * k // rows
        cv2.rectangle(tile, (x0, y - 2), (x1, y + 2), frame, -1)
    tile[y0 : y0 + 5, x0:x1] *= 0.7
    sill = _floats(np.asarray(frame, np.float32) * 0.8)
    cv2.rectangle(tile, (x0 - 8, y1 + 4), (x1 + 8, y1 + 10), sill, -1)


def lettering(
    tile: np.ndarray, rng: np.random.Generator, origin: tuple[int, int], height: float, colour: Colour, count: int, thickness: int = 2
) -> None:
    """``count`` random capital letters and digits starting at ``origin`` (text baseline),
    about ``height`` texels tall."""
    text = "".join(rng.choice(list("ABCDEFGHJKLMNPRSTUVWXYZ0123456789"), count))
    write(tile, text, origin, height / 22.0, colour, thickness)


def write(tile: np.ndarray, text: str, origin: tuple[int, int], scale: float, colour: Colour, thickness: int) -> None:
    """Anti-aliased Hershey ``text`` at ``origin`` (baseline), blended into the float tile."""
    mask = np.zeros(tile.shape[:2], np.uint8)
    cv2.putText(mask, text, origin, cv2.FONT_HERSHEY_SIMPLEX, scale, 255, thickness, cv2.LINE_AA)
    alpha = mask[..., None].astype(np.float32) / 255.0
    tile += alpha * (np.asarray(colour, np.float32) - tile)


def _floats(colour: Colour | np.ndarray) -> tuple[float, ...]:
    """A colour as plain floats (OpenCV drawing rejects numpy float32 scalars)."""
    return tuple(float(c) for c in colour)


def sky(zenith: Colour, horizon: Colour) -> np.ndarray:
    """Smooth vertical gradient: ``zenith`` colour at row 0, ``horizon`` at ``SKY_HORIZON``
    and below; no texture (so no image features)."""
    rows = np.arange(TILE, dtype=np.float32)
    f = np.clip(rows / SKY_HORIZON, 0.0, 1.0) ** 1.6
    column = np.asarray(zenith, np.float32) + f[:, None] * (np.asarray(horizon, np.float32) - np.asarray(zenith, np.float32))
    return finish(np.broadcast_to(column[:, None, :], (TILE, TILE, 3)).copy())
