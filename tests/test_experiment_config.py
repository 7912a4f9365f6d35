"""Experiment configs: validation up front, one error naming the key (unknown keys, wrong types,
unknown modules and parameters, out-of-range values, datasets, perturbation names, the
robustness boundary, YAML syntax)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from experiment_configs import FRAMES, base_config, error_of, write

from pytest_sal.experiment.config import (
    build_modules,
    build_sequence,
    load_config,
)
from sal_modules import Composite

EXAMPLES = Path(__file__).resolve().parents[1] / "example_suites" / "configs"


def test_valid_config_loads_into_frozen_dataclasses(tmp_path: Path) -> None:
    config = load_config(write(tmp_path, base_config(tmp_path)))
    assert config.experiment.seed == 0 and config.dataset.type == "synthetic"
    assert [p.name for p in config.perturbations] == ["rain", "fog", "combo"]
    assert config.perturbations[2].modules[1].type == "fog"
    assert config.robustness_boundary is not None and config.robustness_boundary.module == "fog"
    assert config.output_dir() == tmp_path / "out" / "exp"
    with pytest.raises(AttributeError):
        config.experiment.seed = 3  # type: ignore[misc]
    modules = build_modules(config)
    assert isinstance(modules["combo"], Composite) and modules["fog"].visibility_m == 50  # type: ignore[union-attr]
    assert len(build_sequence(config)) == FRAMES


def test_example_configs_validate() -> None:
    urban = load_config(EXAMPLES / "fog_rain_urban.yaml")
    assert urban.robustness_boundary is not None and urban.robustness_boundary.parameter == "visibility_m"
    assert any(p.type == "composite" for p in urban.perturbations)
    indoor = load_config(EXAMPLES / "indoor_camera.yaml")
    assert {p.type for p in indoor.perturbations} == {"lens_soiling", "cracked_lens", "composite"}


@pytest.mark.parametrize(
    ("section", "known"),
    [
        ("experiment", "name, description, version, seed"),
        ("dataset", "type, path, sequence, max_frames, start, stereo, options"),
        ("output", "base_dir, create_timestamp_dir"),
        ("robustness_boundary", "enabled, name, target_perturbation"),
    ],
)
def test_unknown_key_in_each_section(tmp_path: Path, section: str, known: str) -> None:
    config = base_config(tmp_path)
    config[section]["zzz"] = 1  # like no key: the list
    message = error_of(tmp_path, config)
    assert message.startswith(f"{tmp_path / 'exp.yaml'}: {section}.zzz: unknown key; known: {known}")


def test_unknown_key_at_top_level_and_in_perturbations(tmp_path: Path) -> None:
    config = base_config(tmp_path)
    config["experiment"]["descrption"] = "x"
    assert error_of(tmp_path, config).endswith("experiment.descrption: unknown key; did you mean 'description'?")
    assert ": slam: unknown key; known: experiment, dataset, perturbations, output, robustness_boundary" in error_of(
        tmp_path, base_config(tmp_path, slam={})
    )
    config = base_config(tmp_path)
    config["perturbations"][1]["params"] = {}
    assert "perturbations[1].params: unknown key; did you mean 'parameters'?" in error_of(tmp_path, config)
    config = base_config(tmp_path)
    config["perturbations"][2]["parameters"]["modules"][0]["paramters"] = {}
    assert "perturbations[2].parameters.modules[0].paramters: unknown key; did you mean 'parameters'?" in error_of(tmp_path, config)


def test_wrong_types(tmp_path: Path) -> None:
    config = base_config(tmp_path)
    config["experiment"]["seed"] = "seven"
    assert "experiment.seed: 'seven' is not valid; must be an integer >= 0" in error_of(tmp_path, config)
    config = base_config(tmp_path)
    config["perturbations"][0]["enabled"] = "yes please"
    assert "perturbations[0].enabled: 'yes please' is not valid; must be true or false" in error_of(tmp_path, config)
    config = base_config(tmp_path, perturbations={"name": "fog"})
    assert "perturbations: " in error_of(tmp_path, config) and "must be a list" in error_of(tmp_path, config)
    config = base_config(tmp_path)
    config["dataset"]["max_frames"] = 0
    assert "dataset.max_frames: 0 is not valid; must be an integer >= 1 or null" in error_of(tmp_path, config)


def test_unknown_module_and_parameter(tmp_path: Path) -> None:
    config = base_config(tmp_path)
    config["perturbations"][1]["type"] = "fgo"
    message = error_of(tmp_path, config)
    assert message.endswith("exp.yaml: perturbations[1].type: unknown perturbation module 'fgo'; did you mean 'fog'?")
    config["perturbations"][1]["type"] = "xyz"  # nothing close: the list
    assert "perturbations[1].type: unknown perturbation module 'xyz'; known: none, composite, bandwidth, " in error_of(tmp_path, config)
    config = base_config(tmp_path)
    config["perturbations"][1]["parameters"] = {"visibilty_m": 50}
    message = error_of(tmp_path, config)
    assert message.endswith("perturbations[1].parameters.visibilty_m: fog has no such parameter; did you mean 'visibility_m'?")
    config["perturbations"][1]["parameters"] = {"xyz": 50}
    assert "perturbations[1].parameters.xyz: fog has no such parameter; parameters: visibility_m, " in error_of(tmp_path, config)


def test_out_of_range_value_names_the_path_unit_and_range(tmp_path: Path) -> None:
    config = base_config(tmp_path)
    config["perturbations"][1]["parameters"]["visibility_m"] = 0.5
    assert error_of(tmp_path, config) == (
        f"{tmp_path / 'exp.yaml'}: perturbations[1].parameters.visibility_m: 0.5 m is not valid; "
        "visibility_m must be a number in 1 .. 100000 m"
    )
    config = base_config(tmp_path)
    config["perturbations"][2]["parameters"]["modules"][0]["parameters"]["intensity_mm_h"] = 999
    assert (
        "perturbations[2].parameters.modules[0].parameters.intensity_mm_h: 999 mm/h is not valid; intensity_mm_h must be a number in 0.1 .. 300 mm/h"
        in error_of(tmp_path, config)
    )


def test_missing_dataset_path_and_unknown_kind(tmp_path: Path) -> None:
    config = base_config(tmp_path, dataset={"type": "kitti", "path": str(tmp_path / "nowhere"), "sequence": "07"})
    assert f"dataset.path: '{tmp_path / 'nowhere'}' does not exist; give the dataset folder" in error_of(tmp_path, config)
    (tmp_path / "run.mcap").write_bytes(b"")
    config = base_config(tmp_path, dataset={"type": "kitti", "path": str(tmp_path / "run.mcap")})
    assert f"dataset.path: '{tmp_path / 'run.mcap'}' is not a folder; give the dataset folder" in error_of(tmp_path, config)
    config = base_config(tmp_path, dataset={"type": "video", "path": str(tmp_path / "clip.mp4")})
    assert f"dataset.path: '{tmp_path / 'clip.mp4'}' does not exist; give the dataset file or folder" in error_of(tmp_path, config)
    config = base_config(tmp_path, dataset={"type": "tum"})
    assert "dataset.path: is required for dataset kind 'tum'" in error_of(tmp_path, config)
    config = base_config(tmp_path, dataset={"type": "kitty", "path": "."})
    assert "dataset.type: unknown dataset kind 'kitty'; did you mean 'kitti'?" in error_of(tmp_path, config)
    config = base_config(tmp_path)
    config["dataset"]["options"]["scnee"] = "urban"
    assert "dataset.options.scnee: unknown option of dataset kind 'synthetic'; did you mean 'scene'?" in error_of(tmp_path, config)
    config["dataset"]["options"] = {"xyz": 1}
    assert "dataset.options.xyz: unknown option of dataset kind 'synthetic'; known: scene, frames, seed, sensor, cache_dir" in error_of(
        tmp_path, config
    )


def test_dataset_path_is_env_expanded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "data").mkdir()
    monkeypatch.setenv("SAL_TEST_ROOT", str(tmp_path))
    config = base_config(tmp_path, dataset={"type": "folder", "path": "${SAL_TEST_ROOT}/data"})
    assert load_config(write(tmp_path, config)).dataset.path == tmp_path / "data"


def test_duplicate_and_unsafe_perturbation_names(tmp_path: Path) -> None:
    config = base_config(tmp_path)
    config["perturbations"][2]["name"] = "rain"
    assert "perturbations[2].name: 'rain' is already the name of perturbations[0]; names must be unique" in error_of(tmp_path, config)
    config = base_config(tmp_path)
    config["perturbations"][0]["name"] = "../escape"
    assert "perturbations[0].name: '../escape' cannot be a folder name" in error_of(tmp_path, config)
    config = base_config(tmp_path)
    config["perturbations"][1]["name"] = "baseline"  # a fog: the clean sequence's name is taken
    assert "perturbations[1].name: 'baseline' is kept for the clean sequence (type none); rename this" in error_of(tmp_path, config)
    config["perturbations"].append({"name": "baseline", "type": "none"})  # the clean sequence itself may be listed
    config["perturbations"][1]["name"] = "fog"
    assert load_config(write(tmp_path, config)).perturbations[3].type == "none"


def test_robustness_boundary_checks(tmp_path: Path) -> None:
    def with_rb(**rb: Any) -> str:
        config = base_config(tmp_path)
        config["robustness_boundary"].update(rb)
        return error_of(tmp_path, config)

    assert "robustness_boundary.target_perturbation: 'foog' is not a perturbation of this config; did you mean 'fog'?" in with_rb(
        target_perturbation="foog"
    )
    assert (
        "robustness_boundary.target_perturbation: 'xyz' is not a perturbation of this config; perturbations: rain, fog, combo"
        in with_rb(target_perturbation="xyz")
    )
    assert (
        "robustness_boundary.parameter: 'heterogeneity' is not a searchable parameter of 'fog' (fog); searchable: visibility_m"
        in with_rb(parameter="heterogeneity")
    )
    assert "robustness_boundary.lower_bound: 0.5 m is not valid; visibility_m search values must be a number in 1 .. 100000 m" in with_rb(
        lower_bound=0.5
    )
    assert "robustness_boundary.upper_bound: 10 must be greater than lower_bound 200" in with_rb(lower_bound=200, upper_bound=10)
    assert "robustness_boundary.tolerance: 0 is not valid" in with_rb(tolerance=0)
    assert "robustness_boundary.max_trials: 0 is not valid; must be an integer >= 1" in with_rb(max_trials=0)
    assert "robustness_boundary.ate_rmse_fail: -1 m is not valid" in with_rb(ate_rmse_fail=-1)
    assert "robustness_boundary.reliability: 1.5 is not valid; must be a probability between 0 and 1 (both excluded)" in with_rb(
        reliability=1.5
    )
    assert "robustness_boundary.confidence: 0.3 is not valid; must be a probability between 0.5 and 1" in with_rb(confidence=0.3)
    assert "robustness_boundary.max_runs: 0 is not valid; must be an integer >= 1" in with_rb(max_runs=0)
    assert "robustness_boundary.max_runs: 20000 is not valid; the limit is 10000 runs" in with_rb(max_runs=20000)
    assert (
        "robustness_boundary.parameter: composite 'combo' has no parameter 'fog.visibility'; did you mean 'fog.visibility_m'?"
        in with_rb(target_perturbation="combo", parameter="fog.visibility")
    )
    config = base_config(tmp_path)
    config["robustness_boundary"].update(target_perturbation="combo", parameter="fog.visibility_m")
    rb = load_config(write(tmp_path, config)).robustness_boundary
    assert rb is not None and rb.module == "fog" and rb.name == "combo_fog_visibility_m"
    assert (rb.reliability, rb.confidence, rb.max_runs) == (0.8, 0.9, 30)  # the plugin's defaults
    config["robustness_boundary"].update(reliability=0.9, confidence=0.95, max_runs=60)
    rb = load_config(write(tmp_path, config)).robustness_boundary
    assert rb is not None and (rb.reliability, rb.confidence, rb.max_runs) == (0.9, 0.95, 60)


def test_yaml_syntax_error_and_duplicate_key_name_the_line(tmp_path: Path) -> None:
    message = error_of(tmp_path, "experiment:\n  name: exp\ndataset: [unclosed\n")
    assert message.startswith(f"{tmp_path / 'exp.yaml'}:") and "YAML syntax error" in message
    message = error_of(tmp_path, "experiment:\n  name: exp\n  name: again\ndataset: {type: synthetic}\n")
    assert message.startswith(f"{tmp_path / 'exp.yaml'}:3: YAML syntax error: key 'name' appears twice (first on line 2)")
