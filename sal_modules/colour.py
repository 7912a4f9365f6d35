"""sRGB transfer functions (IEC 61966-2-1) and the tables modules decode and encode with.

Perturbations work in linear light (radiance) and go back to 8-bit sRGB at the end::

    L = I / 12.92                      for I <= 0.04045
    L = ((I + 0.055) / 1.055) ^ 2.4    otherwise          (I, L in 0..1)
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import cv2
import numpy as np

__all__ = ["DECODE_TABLE", "encode_table", "srgb_decode", "srgb_encode", "srgb_to_linear"]


def srgb_decode(values: Any) -> np.ndarray:
    """sRGB-encoded values in [0, 1] -> linear radiance (float64)."""
    v = np.asarray(values, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def srgb_encode(linear: Any) -> np.ndarray:
    """Linear radiance (clipped to [0, 1]) -> sRGB-encoded values in [0, 1] (float64)."""
    v = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


#: 8-bit sRGB code -> linear radiance (float32, 0..1).
DECODE_TABLE = srgb_decode(np.arange(256) / 255.0).astype(np.float32)


@lru_cache(maxsize=8)
def encode_table(levels: int) -> np.ndarray:
    """Nearest 8-bit sRGB code (uint8) of each of ``levels`` evenly spaced linear values 0..1."""
    return np.rint(255.0 * srgb_encode(np.arange(levels) / (levels - 1))).astype(np.uint8)


def srgb_to_linear(image: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Linear radiance (float32, 0..1) of an sRGB image: uint8 through ``DECODE_TABLE``
    (into ``out`` when given), or float in 0..1."""
    if image.dtype == np.uint8:
        return cv2.LUT(image, DECODE_TABLE, dst=out)
    return srgb_decode(np.clip(image, 0.0, 1.0)).astype(np.float32)
