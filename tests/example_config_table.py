"""The example experiment configs in ``example_suites/configs/`` (the paper's table of
severities) that test_example_configs_load.py and test_example_configs_perturb.py check: the
files, the table's rows, the modules each must exercise, the world each runs on, and readers of a loaded config's
steps, parameters and graded groups."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from pytest_sal.experiment.schema import ExperimentConfig

__all__ = [
    "CONFIGS",
    "FILES",
    "GRADED",
    "GRADES",
    "INDOOR",
    "MODULES",
    "NAMES",
    "ORIGINAL",
    "REQUIRED",
    "STEREO",
    "URBAN",
    "WORLD",
    "_groups",
    "_params",
    "_real_kind",
    "_steps",
]


CONFIGS = Path(__file__).resolve().parents[1] / "example_suites" / "configs"
FILES = sorted(CONFIGS.glob("*.yaml"))
NAMES = [f.name for f in FILES]

URBAN = ["urban_rain.yaml", "urban_soiling.yaml", "urban_rain_soiling.yaml", "urban_night_fog.yaml", "urban_rain_blur.yaml"]
INDOOR = ["indoor_soiling.yaml", "indoor_crack.yaml", "indoor_soiling_crack.yaml"]
STEREO = ["stereo_bandwidth.yaml", "stereo_frame_drop.yaml"]
REQUIRED = URBAN + INDOOR + STEREO  # the table's ten rows, each graded light / moderate / heavy
ORIGINAL = ["fog_rain_urban.yaml", "indoor_camera.yaml"]

#: Module types each required config must exercise (a composite's steps in order).
MODULES = {
    "urban_rain.yaml": ["rain"],
    "urban_soiling.yaml": ["lens_soiling"],
    "urban_rain_soiling.yaml": ["rain", "lens_soiling"],
    "urban_night_fog.yaml": ["night", "fog"],
    "urban_rain_blur.yaml": ["rain", "motion_blur"],
    "indoor_soiling.yaml": ["lens_soiling"],
    "indoor_crack.yaml": ["cracked_lens"],
    "indoor_soiling_crack.yaml": ["lens_soiling", "cracked_lens"],
    "stereo_bandwidth.yaml": ["bandwidth"],
    "stereo_frame_drop.yaml": ["frame_drop"],
}
WORLD = {**{n: ("urban", "stereo") for n in URBAN}, **{n: ("indoor", "rgbd") for n in INDOOR}, **{n: ("indoor", "stereo") for n in STEREO}}
WORLD.update({"fog_rain_urban.yaml": ("urban", "stereo"), "indoor_camera.yaml": ("indoor", "rgbd")})

GRADES = ("light", "moderate", "heavy")
GRADED = re.compile(r"^(?P<stem>.+)_(?P<grade>light|moderate|heavy)$")


def _real_kind(name: str) -> str:
    if name.startswith("urban_") or name == "fog_rain_urban.yaml":
        return "kitti"
    if name.startswith("indoor_"):
        return "tum"
    if name.startswith("stereo_"):
        return "euroc"
    raise AssertionError(f"no real dataset pairing for {name}")


# ------------------------------------------------------------------------------ helpers


def _steps(config: ExperimentConfig, name: str) -> list[str]:
    pert = next(p for p in config.perturbations if p.name == name)
    return [s.type for s in pert.modules] if pert.type == "composite" else [pert.type]


def _params(config: ExperimentConfig, name: str, step: str) -> dict[str, Any]:
    pert = next(p for p in config.perturbations if p.name == name)
    if pert.type == "composite":
        return dict(next(s for s in pert.modules if s.type == step).parameters)
    assert pert.type == step
    return dict(pert.parameters)


def _groups(config: ExperimentConfig) -> dict[str, dict[str, str]]:
    """``{stem: {grade: perturbation name}}`` of the enabled graded perturbations."""
    groups: dict[str, dict[str, str]] = {}
    for p in config.enabled():
        m = GRADED.match(p.name)
        if m:
            groups.setdefault(m["stem"], {})[m["grade"]] = p.name
    return groups
