"""Experiment configs (validation up front, one error naming the key) and ``sal perturb``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from pytest_sal.cli.main import main
from pytest_sal.experiment.config import (
    ConfigError,
    build_modules,
    build_sequence,
    load_config,
)
from sal_adapters import open_dataset
from sal_modules import Composite

EXAMPLES = Path(__file__).resolve().parents[1] / "example_suites" / "configs"
FRAMES = 6


def base_config(tmp_path: Path, **changes: Any) -> dict[str, Any]:
    config: dict[str, Any] = {
        "experiment": {"name": "exp", "seed": 0},
        "dataset": {"type": "synthetic", "max_frames": FRAMES, "options": {"scene": "urban", "frames": FRAMES}},
        "perturbations": [
            {"name": "rain", "type": "rain", "parameters": {"intensity_mm_h": 40}},
            {"name": "fog", "type": "fog", "parameters": {"visibility_m": 50}},
            {
                "name": "combo",
                "type": "composite",
                "parameters": {
                    "modules": [{"type": "rain", "parameters": {"intensity_mm_h": 5}}, {"type": "fog", "parameters": {"visibility_m": 80}}]
                },
            },
        ],
        "output": {"base_dir": str(tmp_path / "out")},
        "robustness_boundary": {
            "enabled": True,
            "target_perturbation": "fog",
            "parameter": "visibility_m",
            "lower_bound": 10,
            "upper_bound": 200,
            "tolerance": 5,
            "max_iters": 4,
            "ate_rmse_fail": 1.0,
        },
    }
    config.update(changes)
    return config


def write(tmp_path: Path, config: dict[str, Any] | str, name: str = "exp.yaml") -> Path:
    path = tmp_path / name
    path.write_text(config if isinstance(config, str) else yaml.safe_dump(config, sort_keys=False))
    return path


def error_of(tmp_path: Path, config: dict[str, Any] | str) -> str:
    path = write(tmp_path, config)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    return str(info.value)


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
    assert "robustness_boundary.max_iters: 0 is not valid; must be an integer >= 1" in with_rb(max_iters=0)
    assert "robustness_boundary.ate_rmse_fail: -1 m is not valid" in with_rb(ate_rmse_fail=-1)
    assert (
        "robustness_boundary.parameter: composite 'combo' has no parameter 'fog.visibility'; did you mean 'fog.visibility_m'?"
        in with_rb(target_perturbation="combo", parameter="fog.visibility")
    )
    config = base_config(tmp_path)
    config["robustness_boundary"].update(target_perturbation="combo", parameter="fog.visibility_m")
    rb = load_config(write(tmp_path, config)).robustness_boundary
    assert rb is not None and rb.module == "fog" and rb.name == "combo_fog_visibility_m"


def test_yaml_syntax_error_and_duplicate_key_name_the_line(tmp_path: Path) -> None:
    message = error_of(tmp_path, "experiment:\n  name: exp\ndataset: [unclosed\n")
    assert message.startswith(f"{tmp_path / 'exp.yaml'}:") and "YAML syntax error" in message
    message = error_of(tmp_path, "experiment:\n  name: exp\n  name: again\ndataset: {type: synthetic}\n")
    assert message.startswith(f"{tmp_path / 'exp.yaml'}:3: YAML syntax error: key 'name' appears twice (first on line 2)")


def test_cli_error_is_one_line_exit_2_and_creates_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    config = base_config(tmp_path)
    config["perturbations"][1]["parameters"]["visibility_m"] = 0.5
    path = write(tmp_path, config)
    assert main(["perturb", str(path), "--cache-dir", str(tmp_path / "cache")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("sal: error: ") and "perturbations[1].parameters.visibility_m" in err
    assert not (tmp_path / "out").exists() and not (tmp_path / "cache").exists()


def test_dry_run_prints_the_plan_and_writes_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write(tmp_path, base_config(tmp_path))
    assert main(["perturb", str(path), "--dry-run", "--cache-dir", str(tmp_path / "cache")]) == 0
    out = capsys.readouterr().out
    assert f"{FRAMES} frames" in out and "visibility_m=50 m" in out and "intensity_mm_h=40 mm/h" in out
    assert str(tmp_path / "out" / "exp" / "images" / "combo") in out and "dry run: nothing written" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["exp.yaml"]


def test_perturb_writes_the_tree(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    config = base_config(tmp_path)
    config["perturbations"] = [
        {"name": "fog", "type": "fog", "parameters": {"visibility_m": 200}},
        {"name": "fog_heavy", "type": "fog", "parameters": {"visibility_m": 15}},
        {"name": "drops", "type": "frame_drop", "parameters": {"drop_rate": 0.5, "mode": "periodic", "period": 2}},
        {"name": "clean", "type": "none"},
        {"name": "off", "type": "rain", "enabled": False},
    ]
    path = write(tmp_path, config)
    cache = tmp_path / "cache"
    assert main(["perturb", str(path), "--cache-dir", str(cache)]) == 0
    out = capsys.readouterr().out
    assert "ms/frame" in out and "fog_heavy" in out
    root = tmp_path / "out" / "exp"
    assert sorted(p.name for p in (root / "images").iterdir()) == ["clean", "drops", "fog", "fog_heavy"]
    assert (root / "config.yaml").read_text() == path.read_text()
    results = json.loads((root / "pipeline_results.json").read_text())
    assert results["status"] == "completed" and results["seed"] == 0
    for name in ("fog", "fog_heavy", "clean"):
        folder = root / "images" / name
        assert len(list((folder / "image_left").glob("*.png"))) == FRAMES
        assert len(list((folder / "image_right").glob("*.png"))) == FRAMES
        assert results["perturbations"][name]["frames_kept"] == FRAMES
        assert results["perturbations"][name]["dropped_frames"] == []
        assert not (folder / "dropped_frames.txt").exists()
    # exact-name routing: fog and fog_heavy are separate and hold their own frames
    fog = open_dataset("synthetic", root / "images" / "fog")
    heavy = open_dataset("synthetic", root / "images" / "fog_heavy")
    clean = open_dataset("synthetic", root / "images" / "clean")
    assert np.abs(heavy[0].image.astype(int) - clean[0].image).mean() > np.abs(fog[0].image.astype(int) - clean[0].image).mean()
    assert results["perturbations"]["fog"]["module"]["params"]["visibility_m"] == 200
    assert results["perturbations"]["fog_heavy"]["module"]["params"]["visibility_m"] == 15
    # frame drop: fewer frames, and the folder, the JSON and dropped_frames.txt agree
    drops = results["perturbations"]["drops"]
    kept = sorted(p.stem for p in (root / "images" / "drops" / "image_left").glob("*.png"))
    assert drops["frames_in"] == FRAMES and 0 < drops["frames_kept"] < FRAMES == drops["frames_kept"] + len(drops["dropped_frames"])
    assert len(kept) == drops["frames_kept"] == len(open_dataset("synthetic", root / "images" / "drops"))
    listed = [int(line) for line in (root / "images" / "drops" / "dropped_frames.txt").read_text().splitlines() if not line.startswith("#")]
    assert listed == drops["dropped_frames"] and not set(listed) & {int(s) for s in kept}
    # a second run reuses the cache
    assert main(["perturb", str(path), "--cache-dir", str(cache)]) == 0
    assert "(cached)" in capsys.readouterr().out
    assert all(r["cached"] for r in json.loads((root / "pipeline_results.json").read_text())["perturbations"].values())


def test_seed_changes_the_output(tmp_path: Path) -> None:
    images = []
    for seed in (1, 2):
        config = base_config(tmp_path / f"s{seed}", experiment={"name": "exp", "seed": seed})
        config["perturbations"] = [{"name": "rain", "type": "rain", "parameters": {"intensity_mm_h": 60}}]
        config["dataset"]["max_frames"] = 2
        del config["robustness_boundary"]
        (tmp_path / f"s{seed}").mkdir()
        path = write(tmp_path / f"s{seed}", config)
        assert main(["perturb", str(path), "--cache-dir", str(tmp_path / "cache")]) == 0
        seq = open_dataset("synthetic", tmp_path / f"s{seed}" / "out" / "exp" / "images" / "rain")
        images.append(seq[1].image)
    assert images[0].shape == images[1].shape and not np.array_equal(images[0], images[1])


def test_refuses_to_replace_a_folder_it_did_not_write(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    config = base_config(tmp_path)
    config["perturbations"] = [{"name": "soil", "type": "lens_soiling"}, {"name": "mine", "type": "lens_soiling"}]
    del config["robustness_boundary"]
    config["dataset"]["max_frames"] = 2
    precious = tmp_path / "out" / "exp" / "images" / "mine" / "notes.txt"
    precious.parent.mkdir(parents=True)
    precious.write_text("keep me")
    assert main(["perturb", str(write(tmp_path, config)), "--cache-dir", str(tmp_path / "cache")]) == 2
    assert "output.base_dir: " in capsys.readouterr().err and precious.read_text() == "keep me"
    assert not (tmp_path / "out" / "exp" / "images" / "soil").exists() and not (tmp_path / "cache").exists()


def test_hostile_configs_end_in_one_short_line(tmp_path: Path) -> None:
    """The CPU time of each rejection (target: under 1 s) is benchmarks/bench_time_limits.py's."""
    # "billion laughs": nine levels of nine aliases (10^9 strings once expanded), before the config
    laughs = 'a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n'
    laughs += "".join(f"{chr(98 + i)}: &{chr(98 + i)} [{','.join(['*' + chr(97 + i)] * 9)}]\n" for i in range(8))
    valid = yaml.safe_dump(base_config(tmp_path), sort_keys=False)
    cases = {
        laughs + valid: "holds more than 100000 values once its YAML aliases are expanded",
        "experiment: " + "[" * 1000 + "]" * 1000 + "\n": "nested deeper than 32 levels",
        yaml.safe_dump(
            base_config(tmp_path, dataset={"type": "synthetic", "options": {"frames": 2**63}})
        ): "dataset.options.frames: 9223372036854775808 is not valid; must be a whole number in 1 .. 10000",
        yaml.safe_dump(
            base_config(tmp_path, dataset={"type": "synthetic", "max_frames": 10**9})
        ): "dataset.max_frames: 1000000000 is not valid; the limit is 1000000 frames",
        yaml.safe_dump(
            base_config(tmp_path, perturbations=[{"name": f"p{i}", "type": "fog"} for i in range(300)])
        ): "perturbations: 300 perturbations; the limit is 256",
        yaml.safe_dump(base_config(tmp_path, experiment={"name": "x" * 100_000})): "experiment.name: 'xxxxxxxx",
        valid.replace("tolerance: 5", "tolerance: .nan"): "robustness_boundary.tolerance: nan is not valid; must be a number > 0",
    }
    for text, message in cases.items():
        error = error_of(tmp_path, text)
        assert message in error and "\n" not in error and len(error) < 400, error


@pytest.mark.parametrize(
    ("where", "change"),
    [
        ("output.base_dir", lambda c: c["output"].update(base_dir="a\0b")),
        ("dataset.path", lambda c: c.update(dataset={"type": "folder", "path": "data\0/x"})),
        ("dataset.sequence", lambda c: c.update(dataset={"type": "kitti", "path": ".", "sequence": "0\x007"})),
        ("dataset.options.cache_dir", lambda c: c["dataset"]["options"].update(cache_dir="\0")),
        ("dataset.options.timestamps", lambda c: c.update(dataset={"type": "folder", "path": ".", "options": {"timestamps": "t\0.txt"}})),
        ("dataset.options.groundtruth", lambda c: c.update(dataset={"type": "euroc", "path": ".", "options": {"groundtruth": "gt\0"}})),
        (
            "perturbations[0].parameters.model",
            lambda c: c["perturbations"].insert(0, {"name": "n", "type": "night", "parameters": {"model": "m\0.onnx"}}),
        ),
    ],
)
def test_a_nul_character_in_any_path_is_refused_by_its_key(tmp_path: Path, where: str, change: Any) -> None:
    config = base_config(tmp_path)
    change(config)
    message = error_of(tmp_path, config)
    assert f": {where}: contains a NUL character (" in message and "; no path can hold one" in message, message


def test_a_path_too_long_for_the_file_system_is_refused_by_its_key(tmp_path: Path) -> None:
    config = base_config(tmp_path)
    config["output"]["base_dir"] = "x" * 300
    assert "output.base_dir: 'xxx" in error_of(tmp_path, config)
    assert "is too long (300 bytes, a name of 300); a path may have at most 4096 bytes and each name in it 255" in error_of(
        tmp_path, config
    )


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("experiment: " + "1" * 5000 + "\n", "exp.yaml:1: YAML syntax error: '111"),
        ("experiment: 2001-02-30\n", "exp.yaml:1: YAML syntax error: '2001-02-30' is not a valid timestamp value"),
        ("experiment: !!float x\n", "exp.yaml:1: YAML syntax error: 'x' is not a valid float value"),
        ("experiment: !!timestamp x\n", "exp.yaml:1: YAML syntax error: 'x' is not a valid timestamp value"),
        ("experiment: !!bool maybe\n", "exp.yaml:1: YAML syntax error: 'maybe' is not a valid bool value"),
        ("experiment:\n  ? [a]\n  : 1\n", "exp.yaml:2: YAML syntax error: a key cannot be a list"),
        (
            "experiment:\n  name: \x00\n",
            "exp.yaml:2: YAML syntax error: character #x0000 is not allowed (special characters are not allowed)",
        ),
        ("experiment: *" + "a" * 500 + "\n", "exp.yaml:1: YAML syntax error: found undefined alias 'aaa"),
        ('experiment: {name: e}\ndataset: {type: synthetic}\n"a\\nb\\x1b": 1\n', "exp.yaml: 'a\\nb\\x1b': unknown key; known: experiment,"),
        (
            "experiment: {name: e}\ndataset: {type: synthetic, " + "x" * 300 + ": 1}\n",
            "exp.yaml: dataset.'xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx...: unknown key",
        ),
        (
            "experiment: {name: e}\ndataset: {type: kitti, path: ., sequence: .inf}\n",
            "dataset.sequence: inf is not valid; must be a string or null",
        ),
        (
            "experiment: {name: e}\ndataset: {type: folder, path: ., options: {fps: [30]}}\n",
            "dataset.options.fps: [30] is not valid; must be a number or null",
        ),
        (
            "experiment: {name: e}\ndataset: {type: folder, path: ., options: {fps: .inf}}\n",
            "dataset.options.fps: inf is not valid; must be a number or null",
        ),
        (
            "experiment: {name: e}\ndataset: {type: synthetic, options: {scene: {a: 1}}}\n",
            "dataset.options.scene: {'a': 1} is not valid; must be a string",
        ),
        (
            "experiment: {name: e}\ndataset: {type: tum, path: ., options: {intrinsics: [1, 2]}}\n",
            "dataset.options.intrinsics: [1, 2] is not valid; must be a list of 4 numbers, a string or null",
        ),
        (
            "experiment: {name: e}\ndataset: {type: synthetic, options: {frames: 1000000}}\n",
            "dataset.options.frames: 1000000 is not valid; must be a whole number in 1 .. 10000",
        ),
    ],
)
def test_yaml_python_cannot_hold_and_wrong_option_types_are_one_line(tmp_path: Path, text: str, message: str) -> None:
    error = error_of(tmp_path, text)
    assert message in error and error.isprintable() and len(error) < 300 + len(str(tmp_path)), error


def test_modules_and_search_trials_are_bounded(tmp_path: Path) -> None:
    config = base_config(tmp_path)
    config["perturbations"][2]["parameters"]["modules"] *= 200
    assert "perturbations[2].parameters.modules: 400 steps; the limit is 256 modules (split the experiment)" in error_of(tmp_path, config)
    config = base_config(tmp_path)
    config["perturbations"][2]["parameters"]["modules"] *= 127  # 254 steps after rain and fog: 256 modules
    assert load_config(write(tmp_path, config)).perturbations[2].modules
    config["perturbations"].append({"name": "more", "type": "fog"})
    assert "perturbations[3]: brings the modules to 257 (composite steps count one each); the limit is 256" in error_of(tmp_path, config)
    config = base_config(tmp_path)
    config["robustness_boundary"]["max_iters"] = 10**100
    assert "robustness_boundary.max_iters: 1" + "0" * 100 + " is not valid; the limit is 100 trials" in error_of(tmp_path, config)


def test_an_unknown_name_is_quoted_short_and_a_step_lists_only_modules(tmp_path: Path) -> None:
    config = base_config(tmp_path)
    config["perturbations"][2]["parameters"]["modules"][0]["type"] = "x" * 300
    message = error_of(tmp_path, config)
    assert f"modules[0].type: unknown perturbation module '{'x' * 36}...; known: bandwidth, " in message and "none" not in message
