"""The experiment config the config and ``sal perturb`` tests start from (test_experiment_config.py,
test_experiment_perturb.py), and helpers that write it and read the one error line."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from pytest_sal.experiment.config import (
    ConfigError,
    load_config,
)

__all__ = ["FRAMES", "base_config", "error_of", "write"]


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
            "max_trials": 4,
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
