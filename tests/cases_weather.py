"""Generic-test parameters of the weather modules (fog, rain, snow)."""

from __future__ import annotations

from module_cases import ModuleCase

CASES = {
    # homogeneous fog draws nothing at random: another seed gives the same image
    "fog": ModuleCase(params={"visibility_m": 40.0}, ladder={"visibility_m": [300.0, 60.0, 15.0]}, random=False),
    "rain": ModuleCase(params={"intensity_mm_h": 50.0}, ladder={"intensity_mm_h": [5.0, 25.0, 100.0]}, frames=2),
    "snow": ModuleCase(params={"intensity_mm_h": 2.0}, ladder={"intensity_mm_h": [0.5, 2.0, 8.0]}, frames=2),
}
