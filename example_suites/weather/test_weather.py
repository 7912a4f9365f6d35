"""Weather and light on the synthetic urban street (60 stereo frames, 10 Hz, 4 m/s).

The default ``sal_dataset`` for fog, rain, snow and night is the urban street; the default
``sal_system`` is ORB-SLAM3 (stereo) when ``pyorbslam3`` is installed, else the built-in
reference VO. Each ``sal.require`` test is one boundary search: the envelope's edge (60 m of
visibility below) decides pass or fail, then the search locates where the system stops meeting
the criteria. ``pytest -v`` shows the boundary on the PASSED line.

Criteria in metres of ATE are for the whole 60-frame drive (about 24 m): 1.5 m is "still a
usable trajectory", 0.5 m with 90-95 % of the frames tracked is "no degradation a planner
would notice". (ORB-SLAM3 has about 1-5 cm of ATE on the clean street.) The street is made
to look to feature tracking as KITTI 07 does (the README's "What the embedded world tells
you"); its boundaries are first estimates, a team gates on its own recordings.
"""

import pytest_sal as sal
from pytest_sal import ate_rmse, tracking_rate
from sal_modules import fog, night, rain, snow


@sal.require(ate_rmse < 1.5, fog.visibility_m >= 60, tolerance=5, search_range=(10, 200))
def test_fog(sal_outcome):
    """Down to 60 m of visibility (fog; dense fog is below 50 m) the trajectory stays usable.
    The body runs after the search, on its outcome.

    ORB-SLAM3 is a noisy system, so the search fits its chance to hold over visibility, and
    what a search costs is set by how precisely it must place that curve: ``tolerance=5``
    (metres) and ``search_range`` between 10 and 200 m (where it fails) take about 20 runs;
    the module's whole 1..100000 m to the default 10 % take about 28."""
    # The requirement held at 60 m (else the test would already have failed); the body can
    # check more, here that the search did find a visibility at which the system fails.
    assert sal_outcome.boundary.fail_value < 60


@sal.require(ate_rmse < 1.5, (night(illuminance_lux=80) >> fog).visibility_m >= 120, tolerance=5, search_range=(20, 300))
def test_night_fog(sal_outcome):
    """Fog at dusk (80 lx: auto-exposure, gain and sensor noise first, then fog): a chain,
    searched on the fog's visibility and located within 5 m. ``search_range`` keeps the search
    between 20 and 300 m, where the boundary is. (Street lighting, 5-30 lx, is below what
    ORB-SLAM3 survives on this street at all, as on KITTI 07: see the README.)"""
    # At 80 lx exposure and gain still make up for the light: the fog boundary is the day's
    # (about 40 m, see test_fog), well inside the envelope's 120 m.
    fail_value = sal_outcome.boundary.fail_value
    assert fail_value is not None and 20 < fail_value < 60


@sal.sweep(rain.intensity_mm_h, L=3, M=10, H=50, S=200)
@sal.require(ate_rmse < 0.5, tracking_rate >= 0.95)
def test_rain(sal_trial):
    """Light, moderate, heavy and violent rain (mm/h): one test item per level,
    ``test_rain[H-rain.intensity_mm_h=50]``. A level that misses the criteria fails before the
    body runs; ``sal_trial.metrics`` holds that level's metrics."""
    # One map from start to end: the system never lost track and restarted.
    assert sal_trial.metrics["maps"] == 1


@sal.require(ate_rmse < 0.5, tracking_rate >= 0.9, snow.intensity_mm_h <= 5)
def test_snow(sal_outcome):
    """Moderate snowfall (5 mm/h water equivalent) without degradation. When the most severe
    value of the range passes too, the boundary reads ``> 30 mm/h (never failed)`` and the
    search stops after two trials.
    """
