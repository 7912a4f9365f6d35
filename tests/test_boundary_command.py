"""sal boundary CONFIG --system NAME: the robustness_boundary block searched with the plugin's
boundary search, on a fake SLAM system whose boundary is known exactly."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest

from pytest_sal.cli.main import main
from pytest_sal.engine.outcomes.outcome import Outcome
from pytest_sal.experiment.boundary import linear_sweep_trials
from pytest_sal.experiment.boundary_summary import EXPERIMENT_KEYS, BoundarySummary, read_boundary_summary, upgrade_boundary_summary
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
  max_trials: 10
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


def read_summary(folder: Path) -> BoundarySummary:
    """boundary_summary.json: the outcome as Outcome.to_dict gives it, and the experiment's block."""
    data = json.loads((folder / "boundary_summary.json").read_text())
    assert set(data) == {"outcome", "experiment"} and set(data["experiment"]) == set(EXPERIMENT_KEYS)
    summary = read_boundary_summary(data)
    assert json.loads(json.dumps(summary.outcome.to_dict())) == data["outcome"]
    return summary


def test_boundary_brackets_the_known_failure_point_and_a_rerun_is_all_cached(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(boundary(tmp_path, "--slam-option", STEP)) == 0
    out = capsys.readouterr().out
    folder = tmp_path / "results" / "fogb" / "robustness_boundary" / "fake" / "fog_sweep_visibility_m"
    summary = read_summary(folder)
    outcome, experiment = summary.outcome, summary.experiment
    assert outcome.parameter == "fog.visibility_m" and outcome.boundary.unit == "m"
    assert outcome.requirement == "ate_rmse < 1000 m and tracking_rate >= 0.5 wherever fog.visibility_m >= 100 m"
    bracket = outcome.boundary
    assert bracket.fail_value is not None and bracket.pass_value is not None
    assert bracket.fail_value < 20 <= bracket.pass_value  # the bracket contains the true boundary
    assert bracket.pass_value - bracket.fail_value <= 1 and outcome.termination == "tolerance"
    trials = outcome.trials
    assert (trials[0].value, trials[0].passed) == (100, True)  # the mild end decides first
    assert (trials[1].value, trials[1].passed) == (5, False)  # then the severe end
    for t in trials:
        assert t.passed == (t.value >= 20)
        assert set(t.metrics) >= {"ate_rmse", "tracking_rate"} and not t.cached
    assert len(trials) <= 10
    assert experiment["linear_sweep_trials"] == 96 > len(trials)
    assert experiment["config"] == str(tmp_path / "exp.yaml") and experiment["module"] == "fog"
    assert (experiment["lower_bound"], experiment["upper_bound"], experiment["tolerance"], experiment["max_trials"]) == (5, 100, 1, 10)
    assert experiment["plot"] == str(folder / "boundary_plot.png")
    # one progress line per trial, in order (the trial line of the plugin's live progress), and
    # the summary line with both counts
    lines = [line for line in out.splitlines() if line.lstrip().startswith("step ")]
    assert len(lines) == len(trials)
    for i, (t, line) in enumerate(zip(trials, lines), 1):
        assert line.startswith(f"  step {i:2d}  fog.visibility_m = {t.value:g} m: {'pass' if t.passed else 'FAIL'}  ate_rmse "), line
    assert f"{len(trials)} trials, {len(trials)} runs (0 trials cached) vs 96 for a linear sweep" in out
    assert (folder / "boundary_plot.png").stat().st_size > 10_000

    # a second run reads every trial from the cache and finds the same boundary
    assert main(boundary(tmp_path, "--slam-option", STEP)) == 0
    again = read_summary(folder).outcome
    assert [t.value for t in again.trials] == [t.value for t in trials]
    assert all(t.cached for t in again.trials)
    assert again.boundary == outcome.boundary
    assert f"{len(trials)} trials, {len(trials)} runs ({len(trials)} trials cached)" in capsys.readouterr().out


def test_a_composite_parameter_is_searched_by_its_address(tmp_path: Path) -> None:
    config = write_config(tmp_path, target="noisy_fog", parameter="fog.visibility_m")
    assert main(boundary(tmp_path, "--slam-option", STEP, config=config)) == 0
    folder = tmp_path / "results" / "fogb" / "robustness_boundary" / "fake" / "noisy_fog_fog_visibility_m"
    summary = read_summary(folder)
    assert summary.experiment["module"] == "composite" and summary.outcome.parameter.endswith(".fog.visibility_m")
    bracket = summary.outcome.boundary
    assert bracket.fail_value is not None and bracket.pass_value is not None and bracket.fail_value < 20 <= bracket.pass_value


def test_a_parameter_worse_when_higher_starts_at_the_lower_bound(tmp_path: Path) -> None:
    config = write_config(tmp_path, target="rain", parameter="intensity_mm_h")
    options = ["--slam-option", "parameter=rain.intensity_mm_h", "--slam-option", "tracked=1 if v <= 50 else 0"]
    assert main(boundary(tmp_path, *options, config=config)) == 0
    folder = tmp_path / "results" / "fogb" / "robustness_boundary" / "fake" / "rain_intensity_mm_h"
    outcome = read_summary(folder).outcome
    assert outcome.requirement.endswith("wherever rain.intensity_mm_h <= 5 mm/h")
    assert [t.value for t in outcome.trials[:2]] == [5, 100]
    bracket = outcome.boundary
    assert bracket.pass_value is not None and bracket.fail_value is not None
    assert 49 < bracket.pass_value <= 50 < bracket.fail_value


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
    assert err.startswith("sal: error: --system-option") and "colour" in err


def test_linear_sweep_trials_counts_both_ends() -> None:
    assert linear_sweep_trials(5, 100, 1) == 96
    assert linear_sweep_trials(0, 1, 0.05) == 21
    assert linear_sweep_trials(0, 1, 0.3) == 5


#: a summary as sal boundary wrote it before it wrote Outcome.to_dict (trimmed to what is read)
OLD_SUMMARY = {
    "experiment": "fogb",
    "boundary": "fog_sweep_visibility_m",
    "target_perturbation": "fog_sweep",
    "module": "fog",
    "parameter": "fog.visibility_m",
    "unit": "m",
    "worse": "lower",
    "lower_bound": 5.0,
    "upper_bound": 100.0,
    "tolerance": 1.0,
    "max_iters": 10,  # the old name of max_trials
    "requirement": "ate_rmse < 1000 m and tracking_rate >= 0.5 wherever fog.visibility_m >= 100 m",
    "system": "fake",
    "system_options": {},
    "dataset": "synthetic/indoor-seed0",
    "dataset_fingerprint": "abc",
    "seed": 0,
    "edge": 100.0,
    "edge_verdict": "passed",
    "pass_value": 20.0,
    "fail_value": 19.0,
    "boundary_text": "19-20 m",
    "termination": "tolerance",
    "contradictions": [],
    "trials_used": 2,
    "runs_used": 4,
    "linear_sweep_trials": 96,
    "trials": [
        {
            "value": 100.0,
            "verdict": "pass",
            "metrics": {"ate_rmse": 0.1},
            "failed": [],
            "cached": True,
            "runs": 1,
            "votes": "1 of 1 run passed",
        },
        {
            "value": 19.0,
            "verdict": "fail",
            "metrics": {"ate_rmse": None},
            "failed": ["tracking_rate >= 0.5"],
            "cached": False,
            "runs": 3,
            "votes": "1 of 2 runs failed (1 starved by the machine, not counted)",
            "wall_time_s": 1.5,
        },
    ],
    "plot": "/old/boundary_plot.png",
}


def test_a_summary_of_the_old_flat_form_is_read_as_the_new_one() -> None:
    upgraded = upgrade_boundary_summary(OLD_SUMMARY)
    summary = read_boundary_summary(upgraded)
    assert read_boundary_summary(OLD_SUMMARY) == summary
    outcome = summary.outcome
    assert isinstance(outcome, Outcome) and outcome.verdict == "passed" and outcome.boundary.text() == OLD_SUMMARY["boundary_text"]
    assert outcome.test_id == "sal boundary fogb/fog_sweep_visibility_m" and outcome.parameter == "fog.visibility_m"
    assert [t.votes() for t in outcome.trials] == [t["votes"] for t in OLD_SUMMARY["trials"]]  # type: ignore[index]
    assert [len(t.runs) for t in outcome.trials] == [1, 3] and outcome.runs == OLD_SUMMARY["runs_used"]
    assert outcome.trials[1].failed == ["tracking_rate >= 0.5"] and outcome.trials[1].wall_time_s == 1.5
    assert summary.experiment == {
        "config": None,
        "name": "fogb",
        "boundary": "fog_sweep_visibility_m",
        "target_perturbation": "fog_sweep",
        "module": "fog",
        "lower_bound": 5.0,
        "upper_bound": 100.0,
        "tolerance": 1.0,
        "max_trials": 10,
        "reliability": None,  # the old form had no statistical search
        "confidence": None,
        "max_runs": None,
        "linear_sweep_trials": 96,
        "plot": "/old/boundary_plot.png",
    }


@pytest.mark.parametrize("data", [[], {"outcome": {}}, {"outcome": {"boundary": {}}, "experiment": {}}, {"pass_value": "x"}])
def test_what_is_not_a_boundary_summary_is_one_value_error(data: object) -> None:
    with pytest.raises(ValueError):
        read_boundary_summary(data)


def test_the_experiment_page_shows_an_old_summary_and_names_a_broken_one(tmp_path: Path) -> None:
    from pytest_sal.report.experiment_page import write_experiment_report

    searches = tmp_path / "fogb" / "robustness_boundary" / "fake"
    (searches / "old").mkdir(parents=True)
    (searches / "old" / "boundary_summary.json").write_text(json.dumps(OLD_SUMMARY))
    (searches / "broken").mkdir()
    (searches / "broken" / "boundary_summary.json").write_text(json.dumps({"outcome": {"boundary": "19-20 m"}, "experiment": {}}))
    warnings: list[str] = []
    text = write_experiment_report(tmp_path / "fogb", warn=warnings.append).read_text()
    assert "fog.visibility_m 19-20 m" in text and "a linear sweep at the tolerance step: 96" in text
    assert "1 of 2 runs failed (1 starved by the machine, not counted)" in text and "tracking_rate &gt;= 0.5" in text
    assert len(warnings) == 1 and "robustness_boundary/fake/broken/boundary_summary.json" in warnings[0]
