"""The five boundaries of issue 25 on one clean sequence, chosen by $SAL_WORLD: ``kitti`` (the
KITTI 07 excerpt, left grey camera) or ``urban`` (the embedded urban street, left camera);
first 60 frames, mono, ORB-SLAM3 with its defaults. KITTI comes from $SAL_TEST_DATA or
../shared/data beside the repository."""

import os
from pathlib import Path

import pytest_sal as sal

DATA = Path(os.environ.get("SAL_TEST_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
WORLD = os.environ.get("SAL_WORLD", "urban")

if WORLD == "kitti":
    sal_dataset = sal.dataset_fixture("kitti", str(DATA / "kitti"), sequence="07", max_frames=60)
else:
    sal_dataset = sal.dataset_fixture("synthetic", scene=WORLD, frames=60, sensor="mono")
