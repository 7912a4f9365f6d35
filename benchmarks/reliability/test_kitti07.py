"""Issue 22's requirements on real KITTI 07 with ORB-SLAM3 (a noisy system): lens soiling,
where p(severity) has a plateau near 0.5 (80 frames), and night, a sharp cliff (60 frames)."""

import pytest_sal as sal
from pytest_sal import tracking_rate
from sal_modules import lens_soiling, night


@sal.require(tracking_rate >= 0.9, lens_soiling.particles <= 100)
def test_soiling_kitti07(sal_outcome):
    pass


@sal.require(tracking_rate >= 0.9, night.illuminance_lux >= 5)
def test_night_kitti07(sal_outcome):
    pass
