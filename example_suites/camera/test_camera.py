"""Camera and lens faults on the synthetic indoor room (90 RGB-D frames, 30 Hz, hand-held).

Lens and sensor modules default to the indoor room. ORB-SLAM3 has about 1 cm of ATE on the
clean 3 s walk (1 m); 5 cm with 90 % of the frames tracked is the bar for "still good enough to map
the room".
"""

import pytest_sal as sal
from pytest_sal import ate_rmse, tracking_rate
from sal_modules import cracked_lens, defocus, lens_soiling

#: The bar every camera test applies (criteria are plain values: share them).
ROOM_ACCURACY = (ate_rmse < 0.05, tracking_rate >= 0.9)


@sal.require(*ROOM_ACCURACY, lens_soiling.particles <= 200)
def test_lens_soiling(sal_outcome):
    """Up to 200 out-of-focus dirt particles on the lens. The dirt is static in the image;
    when the search finds no failure up to the end of the range (1000 particles), the summary
    says ``> 1000 (never failed)``."""


@sal.require(ate_rmse < 0.1, tracking_rate >= 0.9, cracked_lens.impact_force_n <= 350, search_range=(300, 1000), tolerance=50)
def test_cracked_lens(sal_outcome):
    """A lens cracked by a 350 N impact (the glass breaks above 300 N) still maps the room to
    10 cm: the crack lines sit still in the image while the room moves, which costs accuracy
    (3 cm of ATE at 350 N), so this test allows more than the others.

    ``search_range`` keeps the bisection where the cracks are (below 300 N the glass holds, and
    the full range runs to 5000 N); ``tolerance`` is in newtons.
    """
    # The static cracks pull the estimate towards a camera that does not move: past the
    # boundary it is the accuracy criterion that fails, while tracking goes on.
    fail_value = sal_outcome.boundary.fail_value
    assert fail_value is not None, "no impact up to 1000 N broke the requirement"
    fail = next(t for t in sal_outcome.trials if t.value == fail_value)
    assert fail.failed == ["ate_rmse < 0.1 m"]


@sal.require(*ROOM_ACCURACY, defocus.f_number >= 2)
def test_defocus(sal_outcome):
    """Focused at 0.5 m (the module's default) while the walls are 2.5-5 m away: apertures down
    to f/2 must keep working (the f-number gets worse when lower: a wider aperture blurs
    more)."""
