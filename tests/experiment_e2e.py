"""Shared part of the experiment commands' end-to-end tests (test_experiment_e2e.py and
test_experiment_e2e_boundary.py): the experiment config, and ``sal``, which runs one command in
this process and keeps what it printed, the SLAM runs it made and the files it wrote.

Each command runs once, in a class-scoped fixture of the test class that asserts on its
results; under ``-n 2`` tests/conftest.py sends a class to one worker, so no command runs twice.
"""

from __future__ import annotations

import contextlib
import io
import json
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import yaml

from pytest_sal.cli.main import main
from pytest_sal.experiment.config import build_sequence, load_config
from sal_wrappers import SYSTEMS

__all__ = [
    "BOUNDARY",
    "FAILING",
    "FRAMES",
    "MILD",
    "NAME",
    "PERTURBATIONS",
    "SEED",
    "STEMS",
    "SYSTEM_NAMES",
    "Command",
    "clean_sequence",
    "files_under",
    "png_size",
    "read",
    "sal",
    "slam_options",
    "write_config",
]

SYSTEM_NAMES = ("orbslam3", "reference_vo")
FRAMES = 20
SEED = 7
NAME = "urban_e2e"
PERTURBATIONS = ("fog", "fog_heavy", "rain", "rain_soiled_lens")
#: perturbations both systems survive (measured: 100 % tracked)
MILD = ("fog", "rain", "rain_soiled_lens")
#: 4 m visibility: the images are a flat grey; neither system tracks a frame (measured: 0/20)
FAILING = "fog_heavy"
BOUNDARY: dict[str, Any] = {"name": "fog_visibility", "lower": 2, "upper": 500, "tolerance": 5, "max_trials": 4, "ate_rmse_fail": 0.5}
STEMS = [f"{i:06d}" for i in range(FRAMES)]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def write_config(folder: Path) -> Path:
    """The experiment: synthetic urban stereo, 20 frames, fog / heavy fog / rain / rain through
    a soiled lens, and a boundary search on fog.visibility_m."""
    rain_soiled_lens = {
        "mode": "sequential",
        "modules": [{"type": "rain", "parameters": {"intensity_mm_h": 10}}, {"type": "lens_soiling", "parameters": {"particles": 40}}],
    }
    config = {
        "experiment": {"name": NAME, "description": "e2e: real systems on the synthetic urban street", "seed": SEED},
        "dataset": {"type": "synthetic", "max_frames": FRAMES, "options": {"scene": "urban", "frames": FRAMES}},
        "perturbations": [
            {"name": "fog", "type": "fog", "parameters": {"visibility_m": 60, "heterogeneity": 0.3}},
            {"name": "fog_heavy", "type": "fog", "parameters": {"visibility_m": 4}},
            {"name": "rain", "type": "rain", "parameters": {"intensity_mm_h": 25, "exposure_ms": 8}},
            {"name": "rain_soiled_lens", "type": "composite", "parameters": rain_soiled_lens},
        ],
        "output": {"base_dir": str(folder / "results"), "create_timestamp_dir": False},
        "robustness_boundary": {
            "enabled": True,
            "name": BOUNDARY["name"],
            "target_perturbation": "fog",
            "parameter": "visibility_m",
            "lower_bound": BOUNDARY["lower"],
            "upper_bound": BOUNDARY["upper"],
            "tolerance": BOUNDARY["tolerance"],
            "max_trials": BOUNDARY["max_trials"],
            "ate_rmse_fail": BOUNDARY["ate_rmse_fail"],
        },
    }
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "exp.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


@dataclass
class Command:
    """One ``sal`` command as it ran: the config, its exit status, what it printed, every real
    SLAM run it made (``(system, sequence name)``), and, read right after it ended (a rerun in
    the same folder rewrites them), the files of the results folder and the JSON files asked for."""

    config: Path
    status: int
    out: str
    err: str
    slam_calls: list[tuple[str, str]] = field(default_factory=list)
    files: set[str] = field(default_factory=set)
    kept: dict[str, Any] = field(default_factory=dict)

    @property
    def results(self) -> Path:
        """The experiment's results folder."""
        return self.config.parent / "results" / NAME


def slam_options(system: str, request: pytest.FixtureRequest) -> list[str]:
    """``--slam-option`` arguments: ORB-SLAM3 gets the session's vocabulary (conftest ``orb_vocabulary``)."""
    return ["--slam-option", f"vocabulary={request.getfixturevalue('orb_vocabulary')}"] if system == "orbslam3" else []


def sal(config: Path, args: list[str], keep: tuple[str, ...] = ()) -> Command:
    """``sal ARGS`` in this process with its output captured and every real ``run`` of the two
    systems recorded; it must exit 0. ``keep``: JSON files of the results folder to read at once."""
    calls: list[tuple[str, str]] = []
    out, err = io.StringIO(), io.StringIO()
    with pytest.MonkeyPatch.context() as patch, contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        for name in SYSTEM_NAMES:
            cls = SYSTEMS.get(name)

            def spy(
                self: Any,
                sequence: Any,
                workdir: Path,
                timeout: float | None = None,
                stop: Any = None,
                _real: Any = cls.run,
                _name: str = name,
            ) -> Any:
                calls.append((_name, sequence.name))
                return _real(self, sequence, workdir, timeout=timeout, stop=stop)

            patch.setattr(cls, "run", spy)
        status = main(args)
    command = Command(config, status, out.getvalue(), err.getvalue(), calls)
    assert status == 0, f"sal {' '.join(args)} exited {status}:\n{command.out}\n{command.err}"
    command.files = files_under(command.results)
    command.kept = {name: read(command.results / name) for name in keep}
    return command


def clean_sequence(config: Path) -> Any:
    """The experiment's clean sequence, as the commands open it."""
    return build_sequence(load_config(config))


def files_under(root: Path) -> set[str]:
    """Every file below ``root``, relative, as posix text (folders are implied)."""
    return {p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file() or p.is_symlink()}


def read(path: Path) -> Any:
    return json.loads(path.read_text())


def png_size(path: Path) -> tuple[int, int]:
    """Width and height of a real PNG file of non-trivial size (asserted)."""
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC and data[12:16] == b"IHDR", path
    assert len(data) > 10_000, f"{path}: {len(data)} bytes"
    width, height = struct.unpack(">II", data[16:24])
    assert width >= 400 and height >= 300, (path, width, height)
    return width, height
