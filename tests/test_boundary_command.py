"""sal boundary CONFIG --slam NAME: the robustness_boundary block searched with the plugin's
boundary search, on a fake SLAM system whose boundary is known exactly."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest

from pytest_sal.cli.boundary import linear_sweep_trials
from pytest_sal.cli.main import main
from pytest_sal.testing import FakeSlam
from sal_wrappers import SYSTEMS

# tracks everything at 20 m and beyond, a quarter of the frames below: the boundary is 20 m
STEP = "tracked=1 if v >= 20 else 0.25"

CONFIG = """\
experiment: {name: fogb, seed: 0}
dataset:
  type: synthetic
  options: {scene: indoor, frames: 8}
perturbations:
  - {name: fog_sweep, type: fog, parameters: {visibility_m: 50}}
  - {name: rain, type: rain, parameters: {intensity_mm_h: 10}}
  - {name: NAME2, type: composite, parameters: {modules: [{type: sensor_noise, parameters: {iso: 800}}, {type: fog}]}}
BOUNDARY
output: {base_dir: OUT}
"""

BOUNDARY = """\
robustness_boundary:
  enabled: ENABLED
  target_perturbation: TARGET
  parameter: PARAMETER
  lower_bound: 5
  upper_bound: 100
  tolerance: 1
  max_iters: 10
  ate_rmse_fail: 1000
  fail_on_tracking_failure: true
"""


@pytest.fixture(autouse=True)
def fake_system() -> Iterator[None]:
    SYSTEMS.register("fake", FakeSlam)
    yield
    SYSTEMS.unregister("fake")


def write_config(
    tmp_path: Path, *, block: bool = True, enabled: bool = True, target: str = "fog_sweep", parameter: str = "visibility_m"
) -> Path:
    boundary = BOUNDARY.replace("ENABLED", str(enabled).lower()).replace("TARGET", target).replace("PARAMETER", parameter) if block else ""
    text = CONFIG.replace("BOUNDARY\n", boundary).replace("OUT", str(tmp_path / "results")).replace("NAME2", "noisy_fog")
    path = tmp_path / "exp.yaml"
    path.write_text(text)
    return path


def boundary(tmp_path: Path, *extra: str, config: Path | None = None) -> list[str]:
    return ["boundary", str(config or write_config(tmp_path)), "--slam", "fake", "--cache-dir", str(tmp_path / "cache"), *extra]


def test_boundary_brackets_the_known_failure_point_and_a_rerun_is_all_cached(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(boundary(tmp_path, "--slam-option", STEP)) == 0
    out = capsys.readouterr().out
    folder = tmp_path / "results" / "fogb" / "robustness_boundary" / "fake" / "fog_sweep_visibility_m"
    summary = json.loads((folder / "boundary_summary.json").read_text())
    for key in ("pass_value", "fail_value", "trials", "termination", "parameter", "unit", "requirement", "linear_sweep_trials"):
        assert key in summary, key
    assert summary["parameter"] == "fog.visibility_m" and summary["unit"] == "m"
    assert summary["requirement"] == "ate_rmse < 1000 m and tracking_rate >= 0.5 wherever fog.visibility_m >= 100 m"
    assert summary["fail_value"] < 20 <= summary["pass_value"]  # the bracket contains the true boundary
    assert summary["pass_value"] - summary["fail_value"] <= 1 and summary["termination"] == "tolerance"
    trials = summary["trials"]
    assert trials[0]["value"] == 100 and trials[0]["verdict"] == "pass"  # the mild end decides first
    assert trials[1]["value"] == 5 and trials[1]["verdict"] == "fail"  # then the severe end
    for t in trials:
        assert t["verdict"] == ("pass" if t["value"] >= 20 else "fail")
        assert set(t["metrics"]) >= {"ate_rmse", "tracking_rate"} and not t["cached"]
    assert summary["trials_used"] == len(trials) <= 10
    assert summary["linear_sweep_trials"] == 96 > len(trials)
    # one progress line per trial, in order, and the summary line with both counts
    lines = [line for line in out.splitlines() if line.lstrip().startswith("step ")]
    assert len(lines) == len(trials)
    assert all(f"{t['value']:g} m" in line and ("PASS" if t["verdict"] == "pass" else "FAIL") in line for t, line in zip(trials, lines))
    assert f"{len(trials)} trials, {len(trials)} runs (0 trials cached) vs 96 for a linear sweep" in out
    assert (folder / "boundary_plot.png").stat().st_size > 10_000

    # a second run reads every trial from the cache and finds the same boundary
    assert main(boundary(tmp_path, "--slam-option", STEP)) == 0
    again = json.loads((folder / "boundary_summary.json").read_text())
    assert [t["value"] for t in again["trials"]] == [t["value"] for t in trials]
    assert all(t["cached"] for t in again["trials"])
    assert (again["pass_value"], again["fail_value"]) == (summary["pass_value"], summary["fail_value"])
    assert f"{len(trials)} trials, {len(trials)} runs ({len(trials)} trials cached)" in capsys.readouterr().out


def test_a_composite_parameter_is_searched_by_its_address(tmp_path: Path) -> None:
    config = write_config(tmp_path, target="noisy_fog", parameter="fog.visibility_m")
    assert main(boundary(tmp_path, "--slam-option", STEP, config=config)) == 0
    folder = tmp_path / "results" / "fogb" / "robustness_boundary" / "fake" / "noisy_fog_fog_visibility_m"
    summary = json.loads((folder / "boundary_summary.json").read_text())
    assert summary["module"] == "composite" and summary["parameter"].endswith(".fog.visibility_m")
    assert summary["fail_value"] < 20 <= summary["pass_value"]


def test_a_parameter_worse_when_higher_starts_at_the_lower_bound(tmp_path: Path) -> None:
    config = write_config(tmp_path, target="rain", parameter="intensity_mm_h")
    options = ["--slam-option", "parameter=rain.intensity_mm_h", "--slam-option", "tracked=1 if v <= 50 else 0"]
    assert main(boundary(tmp_path, *options, config=config)) == 0
    folder = tmp_path / "results" / "fogb" / "robustness_boundary" / "fake" / "rain_intensity_mm_h"
    summary = json.loads((folder / "boundary_summary.json").read_text())
    assert summary["requirement"].endswith("wherever rain.intensity_mm_h <= 5 mm/h")
    assert [t["value"] for t in summary["trials"][:2]] == [5, 100]
    assert summary["pass_value"] <= 50 < summary["fail_value"] and summary["pass_value"] > 49


@pytest.mark.parametrize(
    ("block", "enabled", "words"),
    [(False, True, "no robustness_boundary block"), (True, False, "robustness_boundary.enabled")],
)
def test_without_an_enabled_block_one_error_names_robustness_boundary(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], block: bool, enabled: bool, words: str
) -> None:
    config = write_config(tmp_path, block=block, enabled=enabled)
    assert main(boundary(tmp_path, config=config)) == 2
    err = capsys.readouterr().err
    assert err.startswith("sal: error:") and err.count("\n") == 1
    assert "robustness_boundary" in err and words in err and str(config) in err
    assert not (tmp_path / "results").exists()


def test_an_unknown_system_lists_the_known_ones(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = boundary(tmp_path)
    args[args.index("fake")] = "no_such_slam"
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("sal: error:") and "no_such_slam" in err and "known:" in err
    assert "fake" in err and "reference_vo" in err
    assert not (tmp_path / "results").exists()


def test_an_option_the_system_does_not_take_is_one_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(boundary(tmp_path, "--slam-option", "colour=3")) == 2
    err = capsys.readouterr().err
    assert err.startswith("sal: error: --slam-option") and "colour" in err


def test_linear_sweep_trials_counts_both_ends() -> None:
    assert linear_sweep_trials(5, 100, 1) == 96
    assert linear_sweep_trials(0, 1, 0.05) == 21
    assert linear_sweep_trials(0, 1, 0.3) == 5
