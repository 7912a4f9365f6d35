"""``sal perturb``: one-line errors with exit 2, the dry run's plan, the written tree, seeds,
refusing to replace a folder, and hostile configs, paths and YAML that end in one short line."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from experiment_configs import FRAMES, base_config, error_of, write

from pytest_sal.cli.main import main
from pytest_sal.experiment.config import (
    load_config,
)
from sal_adapters import open_dataset


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
    config["robustness_boundary"]["max_trials"] = 10**100
    assert "robustness_boundary.max_trials: 1" + "0" * 100 + " is not valid; the limit is 100 trials" in error_of(tmp_path, config)


def test_an_unknown_name_is_quoted_short_and_a_step_lists_only_modules(tmp_path: Path) -> None:
    config = base_config(tmp_path)
    config["perturbations"][2]["parameters"]["modules"][0]["type"] = "x" * 300
    message = error_of(tmp_path, config)
    assert f"modules[0].type: unknown perturbation module '{'x' * 36}...; known: bandwidth, " in message and "none" not in message
