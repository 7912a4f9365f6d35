"""Real KITTI 07 (mono, first $SAL_FRAMES frames, default 80) from $SAL_TEST_DATA or ../shared/data
beside the repository; ORB-SLAM3 with $SAL_FEATURES ORB features (default 2000, its default)."""

import os
from pathlib import Path

import pytest

import pytest_sal as sal

DATA = Path(os.environ.get("SAL_TEST_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
sal_dataset = sal.dataset_fixture("kitti", str(DATA / "kitti"), sequence="07", max_frames=int(os.environ.get("SAL_FRAMES", "80")))


@pytest.fixture
def sal_system():
    import sal_wrappers

    return sal_wrappers.create("orbslam3", features=int(os.environ.get("SAL_FEATURES", "2000")))
