"""``sal evaluate``: the paper's result tree, with the deterministic FakeSlam as the system."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml

from pytest_sal.cli.main import main
from pytest_sal.testing import FakeSlam
from sal_adapters.trajectory import Trajectory
from sal_wrappers import SYSTEMS

FRAMES = 8
PERTURBATIONS = ("fog", "fog_heavy")
# FakeSlam tracked = min(1, v / 20): fog (10 m) tracks round(8 * 0.5) = 4 frames, fog_heavy (3 m)
# round(8 * 0.15) = 1 frame (too few poses to score), the clean sequence all 8
TRACKED = {"baseline": 8, "fog": 4, "fog_heavy": 1}


class CrashingSlam(FakeSlam):
    """FakeSlam whose run on the heaviest fog comes back failed, as a crashed child would."""

    name = "crashing"

    def run(self, sequence: Any, workdir: Path, timeout: float | None = None) -> Any:
        result = super().run(sequence, workdir, timeout)
        if result.info.get("value") == 3.0:
            return dataclasses.replace(result, trajectory=None, failure="crashed: killed by signal 11 (SIGSEGV)", exit_status=-11)
        return result


class RaisingSlam(FakeSlam):
    name = "raising"

    def run(self, sequence: Any, workdir: Path, timeout: float | None = None) -> Any:
        if sequence.meta.get("perturbation") is not None:
            raise RuntimeError("wrapper bug")
        return super().run(sequence, workdir, timeout)


@pytest.fixture
def systems() -> Iterator[None]:
    for name, cls in (("fake", FakeSlam), ("crashing", CrashingSlam), ("raising", RaisingSlam)):
        SYSTEMS.register(name, cls)
    yield
    for name in ("fake", "crashing", "raising"):
        SYSTEMS.unregister(name)


def write_config(tmp_path: Path, **sections: Any) -> Path:
    config = {
        "experiment": {"name": "exp", "seed": 0},
        "dataset": {"type": "synthetic", "max_frames": FRAMES, "options": {"scene": "indoor", "frames": FRAMES}},
        "perturbations": [
            {"name": "fog", "type": "fog", "parameters": {"visibility_m": 10}},
            {"name": "fog_heavy", "type": "fog", "parameters": {"visibility_m": 3}},
        ],
        "output": {"base_dir": str(tmp_path / "out"), "create_timestamp_dir": False},
        **sections,
    }
    tmp_path.mkdir(parents=True, exist_ok=True)
    path = tmp_path / "exp.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


def evaluate(tmp_path: Path, slam: str = "fake", *extra: str, **sections: Any) -> int:
    calls = tmp_path / "calls.jsonl"
    return main(
        [
            "evaluate",
            str(write_config(tmp_path, **sections)),
            "--slam",
            slam,
            "--runs",
            "2",
            "--slam-option",
            "tracked=min(1, v / 20)",
            "--slam-option",
            f"calls_file={calls}",
            *extra,
        ]
    )


def read(path: Path) -> dict[str, Any]:
    return json.loads(path.read_text())


def test_evaluate_writes_the_paper_tree(tmp_path: Path, systems: None, capsys: pytest.CaptureFixture[str]) -> None:
    assert evaluate(tmp_path) == 0
    out = capsys.readouterr().out
    root = tmp_path / "out" / "exp" / "slam_results" / "fake"

    # the baseline ran once per run number, each perturbation once per run: 2 x 3 calls
    values = [json.loads(line)["value"] for line in (tmp_path / "calls.jsonl").read_text().splitlines()]
    assert values.count(None) == 2 and values.count(10.0) == 2 and values.count(3.0) == 2 and len(values) == 6

    for k in (1, 2):
        for name in ("baseline", "fog", "fog_heavy"):
            traj = Trajectory.read_tum(root / "trajectories" / f"run_{k}" / f"{name}.txt")
            assert len(traj) == TRACKED[name]
            record = read(root / "metrics" / f"run_{k}" / name / "ate.json")
            assert record["run"] == k and record["tracked"] == TRACKED[name] and record["frames"] == FRAMES
            assert record["tracking_rate"] == TRACKED[name] / FRAMES
            assert record["alignment"]["method"] == record["align"] == "se3"  # the indoor scene is RGB-D
            assert record["scored_trajectory"] == "online"
        assert read(root / "metrics" / f"run_{k}" / "baseline" / "ate.json")["ate_rmse"] < 1e-6  # the fake returns ground truth
        assert read(root / "metrics" / f"run_{k}" / "fog" / "ate.json")["failure"] is None
        assert "too few to score" in read(root / "metrics" / f"run_{k}" / "fog_heavy" / "ate.json")["failure"]

        fog = read(root / "metrics" / f"run_{k}" / "fog" / "vs_baseline.json")
        assert fog["tracking_rate"] == {"baseline": 1.0, "perturbed": 0.5, "ratio": 0.5, "difference": -0.5}
        same = fog["baseline_on_tracked_frames"]
        assert same["frames"] == 4 and same["ate_rmse"] is not None and same["ate_rmse"] < 1e-6
        heavy = read(root / "metrics" / f"run_{k}" / "fog_heavy" / "vs_baseline.json")
        assert heavy["perturbed_ok"] is False and heavy["ate_rmse"]["ratio"] is None
        assert heavy["baseline_on_tracked_frames"]["frames"] == 1 and heavy["baseline_on_tracked_frames"]["ate_rmse"] is None
        assert not (root / "metrics" / f"run_{k}" / "baseline" / "vs_baseline.json").exists()

        for png in (
            root / "metrics" / "comparison" / f"run_{k}" / "ate_comparison.png",
            root / "trajectory_plots" / "comparison" / f"run_{k}" / "trajectory_comparison_xz.png",
            root / "trajectory_plots" / "comparison" / f"run_{k}" / "trajectory_comparison_error.png",
        ):
            assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 1000
    assert (root / "metrics" / "aggregated_metrics.png").stat().st_size > 1000

    summary = read(root / "metrics" / "summary.json")
    assert summary["run_count"] == 2 and summary["order"] == ["baseline", "fog", "fog_heavy"]
    assert summary["baseline"]["runs"] == 2 and summary["baseline"]["failures"] == 0
    fog, heavy = summary["perturbations"]["fog"], summary["perturbations"]["fog_heavy"]
    assert fog["failures"] == 0 and fog["ate_rmse"]["count"] == 2
    assert fog["tracking_rate"] == {"median": 0.5, "mean": 0.5, "std": 0.0, "min": 0.5, "max": 0.5, "count": 2, "values": [0.5, 0.5]}
    assert heavy["failures"] == 2 and heavy["ate_rmse"]["count"] == 0 and heavy["ate_rmse"]["median"] is None
    assert heavy["tracking_rate"]["values"] == [0.125, 0.125]
    assert [r["run"] for r in heavy["failure_reasons"]] == [1, 2]
    for entry in (summary["baseline"], fog, heavy):
        assert set(entry) >= {"ate_rmse", "rpe_trans", "rpe_rot", "tracking_rate", "runs", "failures"}

    assert "fog_heavy            run 2/2" in out and "tracked 4/8" in out
    assert "ATE median" in out  # the final table
    # the room's 13 cm path has no segment of the devkit's 100 m: missing, with the reason
    assert summary["kitti_segments_m"] == [100, 200, 300, 400, 500, 600, 700, 800]
    assert (
        summary["baseline"]["t_rel"]["count"] == 0
        and "too short for a segment of 100 m" in summary["baseline"]["kitti_missing"][0]["reason"]
    )
    assert "baseline: t_rel / r_rel missing in 2 run(s): the reference path is 0.1 m, too short for a segment of 100 m" in out


def test_kitti_segments_of_the_config_score_t_rel_and_r_rel(tmp_path: Path, systems: None, capsys: pytest.CaptureFixture[str]) -> None:
    assert evaluate(tmp_path, evaluation={"kitti_segments_m": [0.05, 0.02]}) == 0
    out = capsys.readouterr().out
    root = tmp_path / "out" / "exp" / "slam_results" / "fake"
    baseline = read(root / "metrics" / "run_1" / "baseline" / "ate.json")
    assert baseline["kitti_segments_m"] == [0.02, 0.05] and baseline["kitti_segments"] > 0
    assert baseline["t_rel"] < 1e-6 and baseline["r_rel"] < 1e-6 and baseline["kitti_missing"] is None  # the fake returns ground truth
    assert set(read(root / "metrics" / "run_1" / "fog" / "vs_baseline.json")) >= {"t_rel", "r_rel"}
    summary = read(root / "metrics" / "summary.json")
    assert summary["kitti_segments_m"] == [0.02, 0.05] and summary["baseline"]["t_rel"]["count"] == 2
    assert " t_rel % r_rel deg/100m " in out and "t_rel / r_rel: KITTI segments of 0.02, 0.05 m" in out


def test_a_failed_or_raising_run_is_recorded_and_the_rest_continues(tmp_path: Path, systems: None) -> None:
    assert evaluate(tmp_path / "crash", "crashing") == 0
    root = tmp_path / "crash" / "out" / "exp" / "slam_results" / "crashing"
    record = read(root / "metrics" / "run_2" / "fog_heavy" / "ate.json")
    assert record["failure"] == "crashed: killed by signal 11 (SIGSEGV)"
    assert not (root / "trajectories" / "run_1" / "fog_heavy.txt").exists()
    assert len(Trajectory.read_tum(root / "trajectories" / "run_2" / "fog.txt")) == 4
    summary = read(root / "metrics" / "summary.json")
    assert summary["perturbations"]["fog_heavy"]["failure_reasons"][0]["reason"].startswith("crashed")
    assert summary["perturbations"]["fog"]["failures"] == 0

    assert evaluate(tmp_path / "raise", "raising") == 0
    summary = read(tmp_path / "raise" / "out" / "exp" / "slam_results" / "raising" / "metrics" / "summary.json")
    assert summary["baseline"]["failures"] == 0
    assert summary["perturbations"]["fog"]["failure_reasons"][0]["reason"] == "raised RuntimeError: wrapper bug"


def test_unknown_system_is_one_error_line(tmp_path: Path, systems: None, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["evaluate", str(write_config(tmp_path)), "--slam", "nosuch"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("sal: error: unknown SLAM system 'nosuch'; known: ")
    assert "fake" in err[0] and "reference_vo" in err[0]
    assert not (tmp_path / "out" / "exp" / "slam_results").exists()


def test_a_config_without_perturbations_evaluates_the_baseline_only(tmp_path: Path, systems: None) -> None:
    path = write_config(tmp_path)
    config = yaml.safe_load(path.read_text())
    del config["perturbations"]  # defaults to one perturbation "baseline" of type none
    path.write_text(yaml.safe_dump(config))
    assert main(["evaluate", str(path), "--slam", "fake"]) == 0
    summary = read(tmp_path / "out" / "exp" / "slam_results" / "fake" / "metrics" / "summary.json")
    assert summary["order"] == ["baseline"] and summary["perturbations"] == {} and summary["baseline"]["runs"] == 1


def test_perturbed_frames_come_from_the_cache_sal_perturb_filled(tmp_path: Path, systems: None, monkeypatch: pytest.MonkeyPatch) -> None:
    from sal_modules.weather.fog import Fog

    path, cache = write_config(tmp_path), tmp_path / "cache"
    assert main(["perturb", str(path), "--cache-dir", str(cache)]) == 0

    def no_fog(*_: Any, **__: Any) -> None:
        raise AssertionError("fog computed again")

    monkeypatch.setattr(Fog, "apply", no_fog)
    tracked = ["--slam-option", "tracked=min(1, v / 20)"]
    assert main(["evaluate", str(path), "--slam", "fake", *tracked, "--runs", "2", "--cache-dir", str(cache)]) == 0
    summary = read(tmp_path / "out" / "exp" / "slam_results" / "fake" / "metrics" / "summary.json")
    assert summary["perturbations"]["fog"]["runs"] == 2 and summary["perturbations"]["fog"]["failures"] == 0

    # an empty cache is filled here, so the (patched) fog is computed
    with pytest.raises(AssertionError, match="fog computed again"):
        main(["evaluate", str(path), "--slam", "fake", *tracked, "--cache-dir", str(tmp_path / "empty")])
    # --no-cache perturbs lazily in memory and stores nothing
    monkeypatch.undo()
    assert main(["evaluate", str(path), "--slam", "fake", *tracked, "--no-cache", "--cache-dir", str(tmp_path / "unused")]) == 0
    assert not (tmp_path / "unused").exists()
