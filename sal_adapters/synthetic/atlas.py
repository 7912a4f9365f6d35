"""Texture atlas: square periodic tiles with wrap-around gutters and a mip pyramid.

Every tile is ``TILE x TILE`` texels and is repeated (wrapped) over the faces it covers.
Level ``L`` of the pyramid holds each tile box-filtered to ``TILE / 2**L`` texels; a texture
coordinate ``s`` (level-0 texels, ``0 <= s < TILE``) of the tile whose level-0 slot starts at
``X0`` is sampled at atlas column ``x = RX[L] + (X0 + s) / 2**L`` (``RX`` holds the level's
offset and the half-texel shift to texel centres). The gutter of ``GUTTER / 2**L`` texels
around every tile repeats the opposite edge, so bilinear sampling never bleeds between tiles.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["LEVELS", "TILE", "Atlas", "build_atlas"]

#: Tile edge in level-0 texels.
TILE = 256
#: Number of mip levels (level ``LEVELS - 1`` has ``TILE / 2**(LEVELS - 1)`` texels per tile).
LEVELS = 6
#: Wrapped border around every level-0 tile (texels); level ``L`` keeps ``GUTTER / 2**L``.
GUTTER = 32
SLOT = TILE + 2 * GUTTER


@dataclass(frozen=True)
class Atlas:
    """The tiles of one world, packed for a single ``cv2.remap``.

    Attributes:
        image: ``H x W x 3`` uint8 RGB holding every level.
        names: tile names; a tile's number is its position here.
        origin: ``(n, 2)`` float32 level-0 atlas position ``(X0, Y0)`` of each tile's texel 0.
        level_scale: ``(LEVELS,)`` float32 ``2**-L``.
        level_offset: ``(LEVELS, 2)`` float32 ``(RX, RY)`` of each level, half-texel shift included.
    """

    image: np.ndarray
    names: tuple[str, ...]
    origin: np.ndarray
    level_scale: np.ndarray
    level_offset: np.ndarray

    def index(self, name: str) -> int:
        """Number of the tile called ``name``."""
        return self.names.index(name)

    def tile(self, name: str, level: int = 0) -> np.ndarray:
        """View of one tile (without gutter) at mip ``level``, for inspection."""
        scale = 2**level
        x0, y0 = self.origin[self.index(name)]
        rx, ry = self.level_offset[level] + 0.5
        x, y = int(rx + x0 / scale), int(ry + y0 / scale)
        return self.image[y : y + TILE // scale, x : x + TILE // scale]


def build_atlas(tiles: Sequence[tuple[str, np.ndarray]]) -> Atlas:
    """Pack named ``TILE x TILE x 3`` uint8 RGB tiles and their mip levels into one image.

    Levels are built by 2x2 box averaging of the level above; tiles must be periodic (their
    left edge continues their right edge) for the wrap-around gutters to be seamless.
    """
    names = tuple(name for name, _ in tiles)
    if len(set(names)) != len(names):
        raise ValueError("tile names must be unique")
    columns = math.ceil(math.sqrt(len(tiles)))
    rows = math.ceil(len(tiles) / columns)
    width, height = columns * SLOT, rows * SLOT
    image = np.zeros((height, width + width // 2, 3), np.uint8)
    offsets = np.zeros((LEVELS, 2), np.float32)
    for level in range(1, LEVELS):
        offsets[level] = (width, height * (1.0 - 2.0 ** (1 - level)))
    origin = np.zeros((len(tiles), 2), np.float32)
    for number, (name, texels) in enumerate(tiles):
        if texels.shape != (TILE, TILE, 3) or texels.dtype != np.uint8:
            raise ValueError(f"tile {name!r} must be {TILE}x{TILE}x3 uint8, got {texels.shape} {texels.dtype}")
        col, row = number % columns, number // columns
        origin[number] = (col * SLOT + GUTTER, row * SLOT + GUTTER)
        level_texels = texels
        for level in range(LEVELS):
            if level:
                level_texels = cv2.resize(level_texels, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)
            scale = 2**level
            gutter = GUTTER // scale
            padded = np.pad(level_texels, ((gutter, gutter), (gutter, gutter), (0, 0)), mode="wrap")
            x = int(offsets[level, 0]) + col * SLOT // scale
            y = int(offsets[level, 1]) + row * SLOT // scale
            image[y : y + padded.shape[0], x : x + padded.shape[1]] = padded
    scale = (2.0 ** -np.arange(LEVELS)).astype(np.float32)
    return Atlas(
        image=image,
        names=names,
        origin=origin,
        level_scale=scale,
        level_offset=offsets - np.float32(0.5),
    )
