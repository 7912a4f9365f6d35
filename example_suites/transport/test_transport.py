"""The video link between camera and SLAM: bit rate, lost frames, compression (indoor room,
90 RGB-D frames of 640x480 at 30 Hz; the depth stream is not compressed).

Transport modules default to the indoor room, with the camera tests' bar: 5 cm of ATE and
90 % of the frames tracked.
"""

import pytest_sal as sal
from pytest_sal import ate_rmse, tracking_rate
from sal_modules import bandwidth, frame_drop, jpeg

ROOM_ACCURACY = (ate_rmse < 0.05, tracking_rate >= 0.9)


@sal.require(*ROOM_ACCURACY, bandwidth.target_mbps >= 1)
def test_bandwidth(sal_outcome):
    """H.264 at a constant 1 Mbit/s (a congested Wi-Fi link) or more keeps the room mappable."""
    # Keep a safety factor: the system must still work at half the link's rated bit rate.
    assert sal_outcome.boundary.pass_value <= 0.5


@sal.require(*ROOM_ACCURACY, frame_drop.drop_rate <= 0.3, tolerance=0.05)
def test_frame_drop(sal_outcome):
    """Up to 30 % of the frames lost at random. ``drop_rate`` is a share of the frames (0..1),
    as in ``create("frame_drop", drop_rate=0.3)`` and YAML: so are the bound, tolerance and boundary."""


@sal.require(*ROOM_ACCURACY, jpeg.quality >= 20)
def test_jpeg(sal_outcome):
    """Frames sent as JPEG at quality 20 (4:2:0) or better."""
