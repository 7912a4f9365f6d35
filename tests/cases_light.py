"""Generic-test cases of the light and sensor modules (see module_cases.py)."""

from __future__ import annotations

from module_cases import ModuleCase

CASES = {
    "night": ModuleCase(
        params={"illuminance_lux": 5.0},
        ladder={"illuminance_lux": [500.0, 50.0, 5.0, 0.5]},
    ),
    "sensor_noise": ModuleCase(
        params={"iso": 3200.0},
        ladder={"iso": [200.0, 800.0, 3200.0, 12800.0]},
    ),
    "sun_glare": ModuleCase(
        # a low sun 60 deg to the right, outside every test camera's view: its veil reaches
        # the lens whatever the scene (indoors, a flat 12 m stand-in depth), while a sun in
        # the view is hidden by any nearer surface (see test_sun_glare_occlusion.py)
        params={"sun_illuminance_klux": 100.0, "sun_azimuth_deg": 60.0},
        ladder={"sun_illuminance_klux": [5.0, 20.0, 60.0, 150.0]},
        random=False,
    ),
}
