"""The sequences both depth test modules use (test_depth_stereo.py, test_depth_providers.py): small synthetic worlds opened once per scene and sensor, a real KITTI 07 frame turned into a stereo pair of a known planar world, and the real EuRoC stereo pair."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import cv2
import numpy as np
import pytest

from sal_adapters import DatasetWarning, Sequence, open_dataset
from sal_adapters.images import read_image
from sal_adapters.sequence import FrameRecord

__all__ = ["euroc", "planar_kitti", "synthetic"]


@cache
def synthetic(scene: str, sensor: str = "stereo") -> Sequence:
    return open_dataset("synthetic", scene=scene, frames=2, sensor=sensor)


# -- stereo on real frames -------------------------------------------------------------------
def planar_kitti(kitti07: Path, frames: int = 2, height_m: float = 1.65, wall_m: float = 25.0) -> tuple[Sequence, np.ndarray]:
    """Real KITTI 07 frames as the left views of a known world: the road plane ``height_m``
    below the camera up to a frontal wall at ``wall_m``. The right view is the left image
    shifted row by row by the disparity ``f B / Z`` of that world (exact for row-constant
    disparity), so matching works on real texture, grey levels, size and calibration."""
    seq = open_dataset("kitti", kitti07, max_frames=frames)
    cam = seq.camera
    T = np.eye(4)
    T[0, 3] = 0.5372  # the KITTI grey pair's baseline (m)
    camera = cam.with_stereo(T)
    rows = np.arange(cam.height, dtype=np.float32)
    disparity = np.maximum(camera.baseline_m * (rows - cam.cy) / height_m * cam.fx / cam.fy, cam.fx * camera.baseline_m / wall_m)
    truth = np.repeat((cam.fx * camera.baseline_m / disparity)[:, None], cam.width, axis=1).astype(np.float32)
    map_x = (np.arange(cam.width, dtype=np.float32)[None, :] + disparity[:, None]).astype(np.float32)
    map_y = np.repeat(rows[:, None], cam.width, axis=1)

    def right_view(path):
        return lambda: cv2.remap(read_image(path), map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)

    records = [FrameRecord(r.index, r.timestamp, r.stem, r.image, right=right_view(r.image)) for r in seq.records]
    return seq.replace(camera=camera, sensor="stereo", records=records), truth


@pytest.fixture(scope="module")
def euroc(shared_data) -> Sequence:
    path = shared_data / "euroc" / "V1_01_easy_micro"
    if not (path / "mav0").is_dir():
        pytest.skip(f"EuRoC excerpt not found at {path}")
    with pytest.warns(DatasetWarning, match="rows skipped"):
        return open_dataset("euroc", path, stereo=True, max_frames=2)
