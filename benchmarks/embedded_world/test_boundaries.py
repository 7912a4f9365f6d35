"""The five requirements whose boundaries issue 25 compares between the embedded urban street
and real KITTI 07 (edges at about KITTI's boundaries, so a verdict says on which side a world
falls). Run per world: ``SAL_WORLD=kitti|urban run_sessions.sh`` (see RESULTS.md)."""

import pytest_sal as sal
from pytest_sal import tracking_rate
from sal_modules import bandwidth, jpeg, lens_soiling, night, sensor_noise


@sal.require(tracking_rate >= 0.9, night.illuminance_lux >= 25)
def test_night(sal_outcome):
    pass


@sal.require(tracking_rate >= 0.9, sensor_noise.iso <= 4600)
def test_sensor_noise(sal_outcome):
    pass


@sal.require(tracking_rate >= 0.9, lens_soiling.particles <= 780)
def test_lens_soiling(sal_outcome):
    pass


@sal.require(tracking_rate >= 0.9, jpeg.quality >= 2)
def test_jpeg(sal_outcome):
    pass


@sal.require(tracking_rate >= 0.9, bandwidth.target_mbps >= 0.08)
def test_bandwidth(sal_outcome):
    pass
