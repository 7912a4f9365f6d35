"""The sequences (decoded once) and the image difference the transport tests share (test_transport_bandwidth.py,
test_transport_jpeg.py, test_transport_frame_drop.py)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from sal_adapters import (
    Sequence,
    open_dataset,
)

__all__ = ["cached", "kitti", "mad", "urban"]


# -- data ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def urban() -> Sequence:
    """36 mono frames (3.6 s at 10 Hz) of the synthetic street, decoded once."""
    return cached(open_dataset("synthetic", scene="urban", frames=36, sensor="mono"))


@pytest.fixture(scope="module")
def kitti(shared_data: Path) -> Sequence:
    """40 real KITTI 07 frames (1226x370 grey, 9.6 Hz), decoded once."""
    return cached(open_dataset("kitti", shared_data / "kitti" / "sequences" / "07", max_frames=40))


def cached(sequence: Sequence) -> Sequence:
    """``sequence`` with its left images decoded once and kept in memory."""
    images = [frame.image for frame in sequence]
    records = [dataclasses.replace(r, image=lambda image=image: image) for r, image in zip(sequence.records, images)]
    return sequence.replace(records=records)


def mad(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a.astype(np.float32) - b.astype(np.float32)).mean())
