"""Generic-test cases of the lens and optics modules (see module_cases.py)."""

from __future__ import annotations

from module_cases import ModuleCase

CASES = {
    "lens_soiling": ModuleCase(
        params={"particles": 60},
        ladder={"particles": [10, 40, 160, 640]},
    ),
    "cracked_lens": ModuleCase(
        params={"impact_force_n": 500.0},
        ladder={"impact_force_n": [200.0, 400.0, 800.0, 2000.0]},
    ),
    "defocus": ModuleCase(
        params={"f_number": 1.4, "focal_length_mm": 8.0, "focus_distance_m": 0.5},
        ladder={"f_number": [8.0, 4.0, 2.0, 1.0]},
        random=False,
    ),
}
