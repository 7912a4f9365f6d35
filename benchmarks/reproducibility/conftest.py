"""Real KITTI 07 (first 60 frames, mono) from $SAL_TEST_DATA or ../shared/data beside the repository."""

import os
from pathlib import Path

import pytest_sal as sal

DATA = Path(os.environ.get("SAL_TEST_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
sal_dataset = sal.dataset_fixture("kitti", str(DATA / "kitti"), sequence="07", max_frames=60)
