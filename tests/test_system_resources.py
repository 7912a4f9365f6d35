"""What one run of a system takes where it runs (SlamSystem.resources): the defaults per system,
the command system's num_cpus / num_gpus / memory options, and that none of it changes a cache key."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from pytest_sal import tracking_rate
from pytest_sal.engine.execution.trial_runner import TrialRunner
from pytest_sal.engine.requirements import Requirement
from sal_adapters import open_dataset
from sal_modules import fog
from sal_wrappers import SlamSystem, SlamSystemError, create
from sal_wrappers.orbslam3.system import OrbSlam3


def test_defaults_per_system() -> None:
    one_cpu = {"num_cpus": 1.0, "num_gpus": 0.0, "memory": None}
    assert SlamSystem().resources() == one_cpu
    assert create("reference_vo").resources() == one_cpu
    assert create("command", argv=["true"]).resources() == one_cpu
    # ORB-SLAM3 takes a core and a half (created without its __init__, which needs pyorbslam3)
    assert OrbSlam3.__new__(OrbSlam3).resources() == {"num_cpus": 2.0, "num_gpus": 0.0, "memory": None}


def test_a_command_system_asks_for_what_its_recipe_says() -> None:
    droid = create("command", argv=["true"], name="droid_slam", num_cpus=4, num_gpus=1, memory=8_000_000_000)
    assert droid.resources() == {"num_cpus": 4.0, "num_gpus": 1.0, "memory": 8_000_000_000}
    shared = create("command", argv=["true"], num_cpus=0.5, num_gpus=0.25)
    assert shared.resources() == {"num_cpus": 0.5, "num_gpus": 0.25, "memory": None}


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("num_cpus", 0, r"option num_cpus=0 is not allowed; give CPU cores, 0 < num_cpus <= 1024 \(fractions allowed\)"),
        ("num_cpus", 2000, r"option num_cpus=2000 is not allowed"),
        ("num_cpus", "2", r"option num_cpus='2' is not allowed"),
        ("num_cpus", float("nan"), r"option num_cpus=nan is not allowed"),
        ("num_gpus", -1, r"option num_gpus=-1 is not allowed; give GPUs, 0 <= num_gpus <= 64 \(fractions allowed\)"),
        ("num_gpus", True, r"option num_gpus=True is not allowed"),
        ("memory", "2G", r"option memory='2G' is not allowed; give the memory one run takes in bytes as a whole number > 0"),
        ("memory", 0, r"option memory=0 is not allowed"),
        ("memory", 1.5e9, r"option memory=1500000000.0 is not allowed"),
    ],
)
def test_bad_resources_name_the_option_the_value_and_the_range(option: str, value: Any, message: str) -> None:
    with pytest.raises(SlamSystemError, match=message):
        create("command", argv=["true"], **{option: value})


def test_resources_never_change_a_cache_key(tmp_path: Path) -> None:
    dataset = open_dataset("synthetic", scene="indoor", frames=4, sensor="rgbd")
    requirement = Requirement.build([tracking_rate >= 0.5, fog.visibility_m >= 25])

    def key(system: SlamSystem) -> str:
        return TrialRunner(dataset, fog.visibility_m.ref(), system, requirement, workdir=tmp_path).key(30.0)

    plain = create("command", argv=["true"])
    assert key(create("command", argv=["true"], num_cpus=8, num_gpus=2, memory=2**33)) == key(plain)
    assert key(create("command", argv=["true"], version="2")) != key(plain)  # what decides results does change it
    vo = create("reference_vo")
    before = key(vo)
    vo.num_cpus, vo.num_gpus = 4.0, 1.0
    assert key(vo) == before and vo.resources()["num_gpus"] == 1.0
