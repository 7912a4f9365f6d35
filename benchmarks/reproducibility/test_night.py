"""The issue-11 reproducibility requirement: ORB-SLAM3 must keep tracking 90 % of the frames at
every illuminance of 5 lx or more (street lighting)."""

import pytest_sal as sal
from pytest_sal import tracking_rate
from sal_modules import night


@sal.require(tracking_rate >= 0.9, night.illuminance_lux >= 5)
def test_night_kitti07(sal_outcome):
    pass
