"""The jpeg module: quality against difference, quality 100, chroma subsampling, determinism."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from transport_sequences import mad

from sal_adapters import (
    Sequence,
)
from sal_modules import (
    ModuleContext,
    create,
)
from sal_modules.transport.jpeg import Jpeg

#: the shared fixtures (kitti, urban)
pytest_plugins = ["transport_sequences"]


# -- jpeg ----------------------------------------------------------------------------------
def jpeg_of(sequence: Sequence, image: np.ndarray, **params: Any) -> np.ndarray:
    module = create("jpeg", **params)
    module.setup(ModuleContext(sequence=sequence))
    return module.apply(image, None, 0, "left")


def test_jpeg_lower_quality_gives_larger_difference(urban: Sequence) -> None:
    image = urban[3].image
    errors = [mad(jpeg_of(urban, image, quality=q), image) for q in (95, 75, 50, 25, 5)]
    assert all(later > earlier for earlier, later in zip(errors, errors[1:])), errors
    assert errors[-1] > 3 * errors[0]


def test_jpeg_quality_100_is_nearly_identical(urban: Sequence, kitti: Sequence) -> None:
    image = urban[3].image
    assert cv2.PSNR(jpeg_of(urban, image, quality=100, chroma_subsampling="4:4:4"), image) > 45.0
    grey = kitti[5].image
    out = jpeg_of(kitti, grey, quality=100)
    assert cv2.PSNR(out, grey) > 45.0 and np.array_equal(out[..., 0], out[..., 2])  # grey stays grey


def test_jpeg_chroma_subsampling_is_honoured(urban: Sequence) -> None:
    """One-pixel red/blue stripes survive only where chroma keeps full resolution."""
    columns = np.zeros((64, 64, 3), np.uint8)
    columns[:, 0::2] = (200, 30, 30)
    columns[:, 1::2] = (30, 30, 200)
    rows = columns.transpose(1, 0, 2).copy()
    error = {
        (name, mode): mad(jpeg_of(urban, pattern, quality=95, chroma_subsampling=mode), pattern)
        for name, pattern in (("columns", columns), ("rows", rows))
        for mode in ("4:4:4", "4:2:2", "4:2:0")
    }
    assert error["columns", "4:4:4"] < 5 < error["columns", "4:2:2"] and error["columns", "4:2:0"] > 5  # halved width
    assert error["rows", "4:4:4"] < 5 and error["rows", "4:2:2"] < 5 < error["rows", "4:2:0"]  # 4:2:0 halves height


def test_jpeg_is_deterministic_and_leaves_its_input_alone(urban: Sequence) -> None:
    image = urban[0].image.copy()
    first, second = jpeg_of(urban, image, quality=20), jpeg_of(urban, image, quality=20)
    np.testing.assert_array_equal(first, second)
    np.testing.assert_array_equal(image, urban[0].image)
    assert isinstance(create("jpeg"), Jpeg)
