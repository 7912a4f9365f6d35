"""A few real KITTI frames copied out of the shared data, for tests that change or remove them."""

from __future__ import annotations

import shutil
from pathlib import Path


def kitti_copy(shared_data: Path, root: Path, frames: int = 3) -> Path:
    """The first ``frames`` real KITTI 07 frames (left grey camera, calibration, times, no poses)
    as a sequence folder ``root/sequences/07``."""
    source, target = shared_data / "kitti" / "sequences" / "07", root / "sequences" / "07"
    (target / "image_0").mkdir(parents=True)
    for i in range(frames):
        shutil.copy(source / "image_0" / f"{i:06d}.png", target / "image_0")
    shutil.copy(source / "calib.txt", target)
    (target / "times.txt").write_text("".join((source / "times.txt").read_text().splitlines(True)[:frames]))
    return target
