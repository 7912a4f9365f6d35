"""Fog, rain and snow on the real KITTI 07 and EuRoC V1_01 excerpts (the EuRoC stereo pair
with stereo depth)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from weather_scenes import one_particle, ready, streak_extent

from sal_adapters import DatasetWarning, Sequence, open_dataset
from sal_modules import create, perturb
from sal_modules.depth import DepthProvider, select_depth_provider
from sal_modules.weather.rain import Rain


# -- real data --------------------------------------------------------------------------------
class FlatWorldDepth(DepthProvider):
    """Depth of a flat road 1.65 m below the camera up to 40 m, and a wall at 40 m above it
    (the KITTI excerpt is monocular: no stereo depth)."""

    name = "test_flat_world"

    def caches(self, stream: str) -> bool:
        return False

    def unavailable(self, sequence: Sequence) -> str | None:
        return None

    def compute(self, sequence: Sequence, position: int, stream: str) -> np.ndarray:
        cam = sequence.camera
        v = np.arange(cam.height, dtype=np.float32)[:, None] - cam.cy
        road = np.where(v > 0, 1.65 * cam.fy / np.maximum(v, 1e-3), np.inf)
        return np.broadcast_to(np.minimum(road, 40.0), (cam.height, cam.width)).astype(np.float32)


@pytest.fixture(scope="module")
def kitti(shared_data: Path) -> Sequence:
    return open_dataset("kitti", shared_data / "kitti" / "sequences" / "07", max_frames=2)


@pytest.fixture(scope="module")
def euroc(shared_data: Path) -> Sequence:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DatasetWarning)  # cam1 lists 4 missing files (known)
        return open_dataset("euroc", shared_data / "euroc" / "V1_01_easy_micro", stereo=True, start=40, max_frames=1)


@pytest.mark.parametrize(
    ("name", "params"), [("fog", {"visibility_m": 40.0}), ("rain", {"intensity_mm_h": 100.0}), ("snow", {"intensity_mm_h": 3.0})]
)
def test_weather_on_real_kitti_frames(kitti: Sequence, name: str, params) -> None:
    out = perturb(kitti, create(name, **params), seed=1, depth=FlatWorldDepth())
    clean = kitti[1].image
    image = out[1].image
    assert image.shape == clean.shape and image.dtype == np.uint8
    assert np.array_equal(image[..., 0], image[..., 2])  # grey in, grey out
    change = np.abs(image.astype(int) - clean)
    far, near = change[: int(kitti.camera.cy)].mean(), change[-60:].mean()
    assert far > near > 0  # the wall at 40 m fades more than the road a few metres away


def test_weather_on_the_real_euroc_stereo_pair_with_stereo_depth(euroc: Sequence) -> None:
    """Unrectified real stereo (rotation between the cameras): depth from semi-global matching,
    and one drop lands in the right image where the calibration projects it."""
    out = perturb(euroc, create("fog", visibility_m=8.0), seed=1, depth="stereo")
    frame, clean = out[0], euroc[0]
    for image, original in ((frame.image, clean.image), (frame.right, clean.right)):
        assert image.shape == original.shape and np.abs(image.astype(int) - original).mean() > 5
    rain = ready(Rain(aperture_mm=0.0), euroc, depth=select_depth_provider(euroc, "stereo").lookup(euroc))
    sky = np.zeros((euroc.camera.height, euroc.camera.width), np.float32)
    point = np.array([0.2, -0.1, 1.5])
    _, ur, vr = streak_extent(rain.coverage(one_particle(point[2], 3.0, x=point[0], y=point[1]), sky, "right"))
    right = euroc.camera.right
    in_right = np.linalg.inv(euroc.camera.T_lr) @ np.append(point, 1.0)
    assert ur == pytest.approx(right.fx * in_right[0] / in_right[2] + right.cx, abs=0.6)
    assert vr == pytest.approx(right.fy * in_right[1] / in_right[2] + right.cy, abs=0.6)
    rainy = perturb(euroc, create("rain", intensity_mm_h=100.0), seed=1, depth="stereo")[0]
    assert np.abs(rainy.right.astype(int) - clean.right).mean() > 0.2
