"""sal features CONFIG: tracking statistics for the clean and every perturbed sequence."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pytest_sal.cli.main import main

CONFIG = """\
experiment: {name: feats, seed: 0}
dataset:
  type: synthetic
  options: {scene: indoor, frames: 6}
perturbations:
  - {name: noisy, type: sensor_noise, parameters: {iso: 51200}}
  - {name: dense_fog, type: fog, enabled: false, parameters: {visibility_m: 3}}
output: {base_dir: OUT}
"""


def write_config(tmp_path: Path) -> Path:
    path = tmp_path / "exp.yaml"
    path.write_text(CONFIG.replace("OUT", str(tmp_path / "results")))
    return path


def test_features_writes_json_and_plots_per_feature_type(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["features", str(write_config(tmp_path)), "--features", "orb"]) == 0
    folder = tmp_path / "results" / "feats" / "features" / "orb"
    summary = json.loads((folder / "summary.json").read_text())
    assert set(summary["sequences"]) == {"baseline", "noisy"}  # the disabled perturbation is skipped
    clean, noisy = summary["sequences"]["baseline"], summary["sequences"]["noisy"]
    assert noisy["mean_track_length"] < clean["mean_track_length"]  # heavy sensor noise shortens tracks
    assert noisy["matches_per_frame"]["mean"] < clean["matches_per_frame"]["mean"]
    assert (folder / "track_survival.png").stat().st_size > 10_000 and (folder / "detections.png").is_file()
    assert "noisy" in capsys.readouterr().out


def test_superpoint_without_a_model_is_one_error_before_any_work(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["features", str(write_config(tmp_path)), "--features", "orb,superpoint"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sal: error:") and "superpoint" in err and "ONNX" in err
    assert not (tmp_path / "results").exists()
