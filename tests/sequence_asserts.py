"""Assertions shared by the adapter tests."""

from __future__ import annotations

import numpy as np

from sal_adapters import Sequence


def assert_same_frames(a: Sequence, b: Sequence) -> None:
    """Same frame count, timestamps, file stems and pixels (and depth for RGB-D)."""
    assert len(a) == len(b)
    assert np.array_equal(a.timestamps, b.timestamps)
    assert [r.stem for r in a.records] == [r.stem for r in b.records]
    for fa, fb in zip(a, b):
        assert np.array_equal(fa.image, fb.image)
        if a.sensor == "rgbd":
            assert fa.depth.dtype == fb.depth.dtype == np.float32
            assert np.array_equal(fa.depth, fb.depth)
