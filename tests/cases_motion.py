"""Registry-driven test parameters of the motion and timing modules (see module_cases.py)."""

from __future__ import annotations

from module_cases import ModuleCase

CASES = {
    "motion_blur": ModuleCase(
        params={"speed_kmh": 60.0, "exposure_ms": 20.0},
        ladder={"speed_kmh": [10.0, 40.0, 120.0, 400.0]},
        random=False,
    ),
    "rolling_shutter": ModuleCase(
        params={"readout_ms": 60.0},
        ladder={"readout_ms": [10.0, 40.0, 100.0, 200.0]},
        random=False,
    ),
    "stereo_desync": ModuleCase(
        params={"delay_ms": 50.0},
        sensor="stereo",
        ladder={"delay_ms": [20.0, 60.0, 150.0, 400.0]},
        random=False,
        frames=4,
    ),
}
