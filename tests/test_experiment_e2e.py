"""The experiment commands end to end (``sal perturb``, ``sal evaluate``, ``sal boundary``,
``sal features``) through ``pytest_sal.cli.main.main``, on the synthetic urban stereo world, with the
REAL systems ``orbslam3`` (pyorbslam3 wheel, child process, the session's vocabulary) and
``reference_vo``; every output tree is checked file by file, and its contents against what
``pytest_sal.analysis.trajectory_errors`` computes from the files written.

One test per (command, system): each runs the command itself, so that pytest-xdist never runs
the same expensive command twice on two workers (module fixtures are per worker).

Figures measured on this machine (2 cores; 20 frames, seed 7; ATE = RMSE, SE(3)):

=================  ================  =============
perturbation       orbslam3 ATE (m)  reference_vo
=================  ================  =============
baseline (clean)   0.0074            0.0073
fog 60 m           0.009-0.011       0.223
fog 4 m            fails: 0/20       fails: 0/20
rain 25 mm/h       0.0060            0.0091
rain >> soiling    0.0054            0.0095
=================  ================  =============

ORB-SLAM3 is multi-threaded and varies by a few mm between runs; reference_vo is deterministic.
Boundary (fog.visibility_m in 2 .. 500 m, log bisection, 4 trials): orbslam3 7.95-31.6 m,
reference_vo 31.6-125.7 m (at 31.6 m it tracks 40 % of the frames). ORB features: 493
matches/frame on the clean sequence, 312 in fog 60 m, none in fog 4 m (no keypoint at all).
Timings alone: sal evaluate on the 5 sequences ~17 s (orbslam3, paced at 10 Hz), ~14 s for 2 runs
(reference_vo); sal perturb ~12 s (4 perturbations); boundary, 4 trials, ~16 s / ~7 s. The whole
file with ``-n 2`` on 2 cores: ~105-120 s (the orbslam3 tests ~55 s each, vocabulary build included).
"""

from __future__ import annotations

import json
import struct
from collections.abc import Iterator
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from pytest_sal.analysis.trajectory_errors import ate, rpe
from pytest_sal.cli.main import main
from pytest_sal.engine.boundary_search import TERMINATIONS
from pytest_sal.experiment.boundary import TRACKING_FAIL_RATE, linear_sweep_trials
from pytest_sal.experiment.config import build_modules, build_sequence, load_config
from pytest_sal.experiment.evaluate import SUMMARY_METRICS
from sal_adapters import open_dataset
from sal_adapters.trajectory import Trajectory
from sal_modules import perturb
from sal_wrappers import SYSTEMS

SYSTEM_NAMES = ("orbslam3", "reference_vo")
FRAMES = 20
SEED = 7
NAME = "urban_e2e"
PERTURBATIONS = ("fog", "fog_heavy", "rain", "rain_soiled_lens")
#: perturbations both systems survive (measured: 100 % tracked)
MILD = ("fog", "rain", "rain_soiled_lens")
#: 4 m visibility: the images are a flat grey; neither system tracks a frame (measured: 0/20)
FAILING = "fog_heavy"
BOUNDARY = {"name": "fog_visibility", "lower": 2, "upper": 500, "tolerance": 5, "max_iters": 4, "ate_rmse_fail": 0.5}
STEMS = [f"{i:06d}" for i in range(FRAMES)]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def write_config(tmp_path: Path) -> Path:
    """The experiment: synthetic urban stereo, 20 frames, fog / heavy fog / rain / rain through
    a soiled lens, and a boundary search on fog.visibility_m."""
    config = {
        "experiment": {"name": NAME, "description": "e2e: real systems on the synthetic urban street", "seed": SEED},
        "dataset": {"type": "synthetic", "max_frames": FRAMES, "options": {"scene": "urban", "frames": FRAMES}},
        "perturbations": [
            {"name": "fog", "type": "fog", "parameters": {"visibility_m": 60, "heterogeneity": 0.3}},
            {"name": "fog_heavy", "type": "fog", "parameters": {"visibility_m": 4}},
            {"name": "rain", "type": "rain", "parameters": {"intensity_mm_h": 25, "exposure_ms": 8}},
            {
                "name": "rain_soiled_lens",
                "type": "composite",
                "parameters": {
                    "mode": "sequential",
                    "modules": [
                        {"type": "rain", "parameters": {"intensity_mm_h": 10}},
                        {"type": "lens_soiling", "parameters": {"particles": 40}},
                    ],
                },
            },
        ],
        "output": {"base_dir": str(tmp_path / "results"), "create_timestamp_dir": False},
        "robustness_boundary": {
            "enabled": True,
            "name": BOUNDARY["name"],
            "target_perturbation": "fog",
            "parameter": "visibility_m",
            "lower_bound": BOUNDARY["lower"],
            "upper_bound": BOUNDARY["upper"],
            "tolerance": BOUNDARY["tolerance"],
            "max_iters": BOUNDARY["max_iters"],
            "ate_rmse_fail": BOUNDARY["ate_rmse_fail"],
        },
    }
    tmp_path.mkdir(parents=True, exist_ok=True)
    path = tmp_path / "exp.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


def slam_options(system: str, request: pytest.FixtureRequest) -> list[str]:
    """``--slam-option`` arguments: ORB-SLAM3 gets the session's vocabulary (conftest)."""
    if system == "orbslam3":
        return ["--slam-option", f"vocabulary={request.getfixturevalue('orb_vocabulary')}"]
    return []


@pytest.fixture
def slam_calls(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[tuple[str, str]]]:
    """Every real ``run`` of the two systems, as ``(system, sequence name)``; the run itself is
    the real one."""
    calls: list[tuple[str, str]] = []
    for name in SYSTEM_NAMES:
        cls = SYSTEMS.get(name)
        real = cls.run

        def spy(self: Any, sequence: Any, workdir: Path, timeout: float | None = None, _real: Any = real, _name: str = name) -> Any:
            calls.append((_name, sequence.name))
            return _real(self, sequence, workdir, timeout=timeout)

        monkeypatch.setattr(cls, "run", spy)
    yield calls


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


def clean_sequence(config: Path) -> Any:
    return build_sequence(load_config(config))


# ------------------------------------------------------------------------------ sal perturb


def test_perturb_writes_each_perturbation_in_the_dataset_layout(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """No SLAM system takes part in ``sal perturb``: one run covers both systems."""
    config = write_config(tmp_path)
    cache = tmp_path / "cache"
    assert main(["perturb", str(config), "--cache-dir", str(cache)]) == 0
    root = tmp_path / "results" / NAME
    layout = (
        {f"depth/{s}.npy" for s in STEMS}
        | {f"image_left/{s}.png" for s in STEMS}
        | {f"image_right/{s}.png" for s in STEMS}
        | {"groundtruth.txt", "times.txt", "sequence.json", "sal_sequence.json"}
    )
    expected = {"config.yaml", "pipeline_results.json"} | {f"images/{p}/{f}" for p in PERTURBATIONS for f in layout}
    assert files_under(root) == expected  # no dropped_frames.txt: no perturbation drops a frame
    assert (root / "config.yaml").read_text() == config.read_text()

    results = read(root / "pipeline_results.json")
    assert results["status"] == "completed" and results["seed"] == SEED and results["experiment"] == NAME
    assert results["dataset"] == {"type": "synthetic", "name": "synthetic/urban-seed0", "frames": FRAMES}
    assert list(results["perturbations"]) == list(PERTURBATIONS)
    for name, entry in results["perturbations"].items():
        assert entry["frames_in"] == entry["frames_kept"] == FRAMES and entry["dropped_frames"] == []
        assert entry["cached"] is False and entry["output"] == str(root / "images" / name)
    assert results["perturbations"]["rain_soiled_lens"]["type"] == "composite"

    # each folder opens again as the dataset it was written as: same frames, times and ground
    # truth as the clean sequence, and the images are exactly the perturbed ones (PNG is lossless)
    clean = clean_sequence(config)
    modules = build_modules(load_config(config))
    for name in PERTURBATIONS:
        folder = root / "images" / name
        marker = read(folder / "sal_sequence.json")
        assert marker["layout"] == "synthetic" and marker["frames"] == FRAMES
        info = read(folder / "sequence.json")
        assert info["sensor"] == "stereo" and info["frames"] == FRAMES and info["scene"] == "urban"
        assert info["name"].startswith("synthetic/urban-seed0+")
        copy = open_dataset("synthetic", folder)
        assert len(copy) == FRAMES and copy.sensor == "stereo"
        np.testing.assert_array_equal(copy.timestamps, clean.timestamps)
        times = [line.split() for line in (folder / "times.txt").read_text().splitlines() if not line.startswith("#")]
        assert [row[0] for row in times] == STEMS and [float(row[2]) for row in times] == list(clean.timestamps)
        gt = Trajectory.read_tum(folder / "groundtruth.txt")
        np.testing.assert_allclose(gt.positions, clean.groundtruth.positions, atol=1e-12)
        expected_frame = perturb(clean, modules[name], seed=SEED)[0]
        written = copy[0]
        np.testing.assert_array_equal(written.image, expected_frame.image)
        np.testing.assert_array_equal(written.right, expected_frame.right)
        assert written.depth is not None and written.depth.shape == written.image.shape[:2]
        assert np.abs(written.image.astype(int) - clean[0].image.astype(int)).mean() > 1.0  # really perturbed
    out = capsys.readouterr().out
    assert f"wrote {root}" in out and "rain>>lens_soiling" in out

    # a second run copies the perturbed sequences from the cache and writes the same tree
    assert main(["perturb", str(config), "--cache-dir", str(cache)]) == 0
    assert files_under(root) == expected
    again = read(root / "pipeline_results.json")
    assert all(entry["cached"] for entry in again["perturbations"].values())
    assert "(cached)" in capsys.readouterr().out


# ------------------------------------------------------------------------------ sal evaluate


@pytest.mark.parametrize("system", SYSTEM_NAMES)
def test_evaluate_writes_the_paper_tree(
    system: str, tmp_path: Path, request: pytest.FixtureRequest, slam_calls: list[tuple[str, str]], capsys: pytest.CaptureFixture[str]
) -> None:
    runs = 2 if system == "reference_vo" else 1  # reference_vo is deterministic: both runs agree
    config = write_config(tmp_path)
    assert main(["evaluate", str(config), "--slam", system, "--runs", str(runs), *slam_options(system, request)]) == 0
    out = capsys.readouterr().out
    root = tmp_path / "results" / NAME / "slam_results" / system
    clean = clean_sequence(config)
    groundtruth = clean.groundtruth
    names = ("baseline", *PERTURBATIONS)
    ks = range(1, runs + 1)

    # the baseline ran once per run number, every perturbation once per run: nothing more
    assert len(slam_calls) == runs * len(names) and {s for s, _ in slam_calls} == {system}
    sequences = [seq for _, seq in slam_calls]
    # each sequence is named after its perturbation in the config (fog and fog_heavy stay apart), once per run
    assert sorted(sequences) == sorted([clean.name, *(f"{clean.name}+{p}" for p in PERTURBATIONS)] * runs)
    work = root / "work"
    assert sorted(d.name for d in work.iterdir()) == [f"run_{k}" for k in ks]
    for k in ks:
        assert sorted(d.name for d in (work / f"run_{k}").iterdir()) == sorted(names)
        for name in names:
            assert (work / f"run_{k}" / name / f"{system}.log").is_file()

    records = {(k, n): read(root / "metrics" / f"run_{k}" / n / "ate.json") for k in ks for n in names}

    # the failing perturbation is recorded with its reason; all the others ran and were scored
    for k in ks:
        failed = records[(k, FAILING)]
        # both systems call a run that tracked nothing a failure of the run, and its log tail is kept
        expected = {"orbslam3": f"never initialised: no frame of {FRAMES} was tracked", "reference_vo": "no frame was tracked"}[system]
        assert failed["failure"] == expected and failed["log_tail"], failed
        assert failed["ate_rmse"] is None and failed["tracked"] == 0 and failed["tracking_rate"] == 0.0
        assert failed["ate_stats"] is None and failed["frames"] == FRAMES
        assert f"[{failed['failure']}]" in out
        for name in ("baseline", *MILD):
            assert records[(k, name)]["failure"] is None, (name, records[(k, name)])

    # exactly the paper's tree (besides work/): no trajectory of a run that tracked nothing
    expected = {"metrics/summary.json", "metrics/aggregated_metrics.png"}
    for k in ks:
        expected |= {f"trajectories/run_{k}/{n}.txt" for n in ("baseline", *MILD)}
        expected |= {f"metrics/run_{k}/{n}/ate.json" for n in names}
        expected |= {f"metrics/run_{k}/{p}/vs_baseline.json" for p in PERTURBATIONS}
        expected |= {f"metrics/comparison/run_{k}/ate_comparison.png", f"trajectory_plots/comparison/run_{k}/trajectory_comparison_xz.png"}
        expected.add(f"trajectory_plots/comparison/run_{k}/trajectory_comparison_error.png")
    assert {f for f in files_under(root) if not f.startswith("work/")} == expected

    for k in ks:
        for name in ("baseline", *MILD):
            record = records[(k, name)]
            path = root / "trajectories" / f"run_{k}" / f"{name}.txt"
            lines = path.read_text().splitlines()
            assert lines[0].startswith("#") and all(len(line.split()) == 8 for line in lines[1:])  # TUM
            traj = Trajectory.read_tum(path)
            assert len(traj) == record["tracked"] == record["matched"]
            assert set(traj.timestamps) <= set(clean.timestamps)  # stamped with the frames' times
            assert record["run"] == k and record["system"] == system and record["sensor"] == "stereo"
            assert record["frames"] == FRAMES and record["align"] == record["alignment"]["method"] == "se3"
            assert record["tracking_rate"] == record["tracked"] / FRAMES >= 0.9
            # the ATE and RPE written are what pytest_sal.analysis.trajectory_errors gives for the written trajectory
            max_diff = record["alignment"]["max_diff_s"]
            assert max_diff == pytest.approx(0.5 / clean.fps)
            again = ate(traj, groundtruth, align="se3", max_diff=max_diff)
            assert record["ate_rmse"] == pytest.approx(again.rmse, rel=1e-9, abs=1e-12)
            assert record["ate_stats"]["max"] == pytest.approx(again.max, rel=1e-9)
            assert record["ate_stats"]["median"] == pytest.approx(again.median, rel=1e-9)
            drift = rpe(traj, groundtruth, delta=1.0, unit="m", align="se3", max_diff=max_diff)
            assert record["rpe_trans"] == pytest.approx(drift.trans.rmse, rel=1e-9)
            assert record["rpe_rot"] == pytest.approx(drift.rot.rmse, rel=1e-9)
            assert record["ate_rmse"] < 0.5  # mild perturbations: measured 0.005-0.22 m
        baseline = records[(k, "baseline")]
        assert baseline["tracked"] == FRAMES
        assert len(Trajectory.read_tum(root / "trajectories" / f"run_{k}" / "baseline.txt").timestamps) == FRAMES
        np.testing.assert_array_equal(Trajectory.read_tum(root / "trajectories" / f"run_{k}" / "baseline.txt").timestamps, clean.timestamps)
        assert baseline["ate_rmse"] < 0.05, baseline["ate_rmse"]  # measured 0.0073-0.0074 m over ~20 m
        assert not (root / "metrics" / f"run_{k}" / "baseline" / "vs_baseline.json").exists()

        # vs_baseline: the two ate.json values, their ratio and difference
        for p in PERTURBATIONS:
            vs = read(root / "metrics" / f"run_{k}" / p / "vs_baseline.json")
            rec = records[(k, p)]
            for metric in ("ate_rmse", "rpe_trans", "tracking_rate"):
                pair = vs[metric]
                assert pair["baseline"] == baseline[metric] and pair["perturbed"] == rec[metric], (p, metric)
                if rec[metric] is None:
                    assert pair["ratio"] is None and pair["difference"] is None
                else:
                    assert pair["ratio"] == pytest.approx(rec[metric] / baseline[metric])
                    assert pair["difference"] == pytest.approx(rec[metric] - baseline[metric])
            assert vs["baseline_ok"] is True and vs["baseline_failure"] is None
            assert vs["perturbed_ok"] is (rec["failure"] is None) and vs["perturbed_failure"] == rec["failure"]
            assert vs["frames"] == {
                "baseline": FRAMES,
                "perturbed": FRAMES,
                "tracked_baseline": FRAMES,
                "tracked_perturbed": rec["tracked"],
            }
            same = vs["baseline_on_tracked_frames"]
            if p == FAILING:
                assert same["ate_rmse"] is None and same["reason"] == "this run has no trajectory"
            elif rec["tracked"] == FRAMES:  # same frames: the baseline's own ATE
                assert same["frames"] == FRAMES and same["ate_rmse"] == pytest.approx(baseline["ate_rmse"], rel=1e-9)

        assert png_size(root / "metrics" / "comparison" / f"run_{k}" / "ate_comparison.png")
        assert png_size(root / "trajectory_plots" / "comparison" / f"run_{k}" / "trajectory_comparison_xz.png")
        assert png_size(root / "trajectory_plots" / "comparison" / f"run_{k}" / "trajectory_comparison_error.png")
    assert png_size(root / "metrics" / "aggregated_metrics.png")

    # summary.json: per sequence, median / mean / std / min / max of each metric over the runs
    summary = read(root / "metrics" / "summary.json")
    assert summary["system"] == system and summary["experiment"] == NAME and summary["sequence"] == clean.name
    assert summary["frames"] == FRAMES and summary["run_count"] == runs and summary["order"] == list(names)
    assert list(summary["perturbations"]) == list(PERTURBATIONS)
    if system == "orbslam3":
        assert summary["options"]["vocabulary"] == str(request.getfixturevalue("orb_vocabulary"))
    entries = {"baseline": summary["baseline"], **summary["perturbations"]}
    for name, entry in entries.items():
        assert entry["runs"] == runs
        assert entry["failures"] == (runs if name == FAILING else 0)
        assert [r["run"] for r in entry["failure_reasons"]] == ([*ks] if name == FAILING else [])
        assert [r["reason"] for r in entry["failure_reasons"]] == [records[(k, name)]["failure"] for k in ks if name == FAILING]
        for metric in SUMMARY_METRICS:
            values = [records[(k, name)][metric] for k in ks if records[(k, name)][metric] is not None]
            stats = entry[metric]
            assert stats["values"] == values and stats["count"] == len(values), (name, metric)
            if not values:
                assert all(stats[s] is None for s in ("median", "mean", "std", "min", "max"))
                continue
            a = np.asarray(values, dtype=float)
            assert stats["median"] == pytest.approx(float(np.median(a)))
            assert stats["mean"] == pytest.approx(float(a.mean()))
            assert stats["std"] == pytest.approx(float(a.std()), abs=1e-15)
            assert (stats["min"], stats["max"]) == (float(a.min()), float(a.max()))
    assert entries[FAILING]["ate_rmse"]["count"] == 0 and entries[FAILING]["tracking_rate"]["values"] == [0.0] * runs

    if runs == 2:  # reference_vo is deterministic: both runs give the same trajectories and metrics
        for name in ("baseline", *MILD):
            first, second = (root / "trajectories" / f"run_{k}" / f"{name}.txt" for k in ks)
            assert first.read_text() == second.read_text(), name
            assert entries[name]["ate_rmse"]["std"] == 0.0 and entries[name]["ate_rmse"]["min"] == entries[name]["ate_rmse"]["max"]
    assert f"wrote {root}" in out and "ATE median" in out


# ------------------------------------------------------------------------------ sal boundary


def verdict(metrics: dict[str, Any]) -> str:
    """The block's requirement: ate_rmse < ate_rmse_fail and tracking_rate >= 0.5."""
    ate_rmse, rate = metrics.get("ate_rmse"), metrics.get("tracking_rate")
    ok = ate_rmse is not None and ate_rmse < BOUNDARY["ate_rmse_fail"] and rate is not None and rate >= TRACKING_FAIL_RATE
    return "pass" if ok else "fail"


def without_cache_fields(trials: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Trials as compared between a run and its cached rerun (``cached`` and timing differ)."""
    return [{k: v for k, v in t.items() if k not in ("cached", "wall_time_s", "runs")} for t in trials]


def votes(trial: dict[str, Any]) -> tuple[int, int]:
    """(runs that agree with the trial's verdict, runs) of a trial of ``Outcome.to_dict``."""
    return sum(r["passed"] == trial["passed"] for r in trial["runs"]), len(trial["runs"])


@pytest.mark.parametrize("system", SYSTEM_NAMES)
def test_boundary_brackets_the_fog_failure_and_a_rerun_reads_the_cache(
    system: str, tmp_path: Path, request: pytest.FixtureRequest, slam_calls: list[tuple[str, str]], capsys: pytest.CaptureFixture[str]
) -> None:
    config = write_config(tmp_path)
    args = ["boundary", str(config), "--slam", system, "--cache-dir", str(tmp_path / "cache"), *slam_options(system, request)]
    assert main(args) == 0
    out = capsys.readouterr().out
    folder = tmp_path / "results" / NAME / "robustness_boundary" / system / BOUNDARY["name"]
    assert sorted(p.name for p in (tmp_path / "results" / NAME).iterdir()) == ["robustness_boundary"]
    summary = read(folder / "boundary_summary.json")
    assert set(summary) == {"outcome", "experiment"}  # Outcome.to_dict(), and what only the experiment knows
    outcome, experiment = summary["outcome"], summary["experiment"]
    trials = outcome["trials"]
    n = len(trials)
    runs = sum(len(t["runs"]) for t in trials)

    # the tree: the summary, the plot, and one work folder per SLAM run: one run per trial for
    # the deterministic reference VO, a vote of at least 2 for ORB-SLAM3
    run_dirs = sorted(p.name for p in (folder / "runs").iterdir())
    assert len(run_dirs) == runs == len(slam_calls)
    assert all(len(t["runs"]) == 1 for t in trials) if system == "reference_vo" else all(len(t["runs"]) >= 2 for t in trials)
    assert {f for f in files_under(folder) if not f.startswith("runs/")} == {"boundary_summary.json", "boundary_plot.png"}
    assert all((folder / "runs" / d / f"{system}.log").is_file() for d in run_dirs)
    assert png_size(folder / "boundary_plot.png")
    assert experiment["plot"] == str(folder / "boundary_plot.png")

    assert outcome["system"] == system and outcome["parameter"] == "fog.visibility_m" and outcome["boundary"]["unit"] == "m"
    assert outcome["worse"] == "lower" and outcome["edge"] == BOUNDARY["upper"]
    assert (
        outcome["requirement"]
        == f"ate_rmse < {BOUNDARY['ate_rmse_fail']:g} m and tracking_rate >= 0.5 wherever fog.visibility_m >= {BOUNDARY['upper']} m"
    )
    assert (experiment["lower_bound"], experiment["upper_bound"], experiment["tolerance"], experiment["max_iters"]) == (
        BOUNDARY["lower"],
        BOUNDARY["upper"],
        BOUNDARY["tolerance"],
        BOUNDARY["max_iters"],
    )
    assert outcome["seed"] == SEED and outcome["dataset"] == "synthetic/urban-seed0"
    assert experiment["linear_sweep_trials"] == linear_sweep_trials(BOUNDARY["lower"], BOUNDARY["upper"], BOUNDARY["tolerance"]) == 101
    assert n <= BOUNDARY["max_iters"]

    # every trial: value, metrics, verdict, and the verdict is the requirement applied to its metrics
    for t in trials:
        assert set(t) >= {"value", "metrics", "passed", "failed", "cached", "runs"}
        assert BOUNDARY["lower"] <= t["value"] <= BOUNDARY["upper"]
        agreeing, voting = votes(t)
        if agreeing == voting:  # unanimous: the median run agrees
            assert ("pass" if t["passed"] else "fail") == verdict(t["metrics"]), t
        assert (not t["passed"]) == bool(t["failed"]) and t["cached"] is False
    # the mild end passes (clean-looking air), the severe end fails (2 m: nothing tracked)
    assert (trials[0]["value"], trials[0]["passed"]) == (BOUNDARY["upper"], True)
    assert (trials[1]["value"], trials[1]["passed"]) == (BOUNDARY["lower"], False)
    assert trials[1]["metrics"]["tracking_rate"] == 0.0 and trials[1]["metrics"]["ate_rmse"] is None
    assert outcome["verdict"] == "passed"

    # pass_value / fail_value bracket the boundary on the side where visibility gets worse (lower)
    passing = [t["value"] for t in trials if t["passed"]]
    failing = [t["value"] for t in trials if not t["passed"]]
    pass_value, fail_value = outcome["boundary"]["pass_value"], outcome["boundary"]["fail_value"]
    assert BOUNDARY["lower"] <= fail_value < pass_value <= BOUNDARY["upper"]
    assert pass_value in passing and fail_value in failing
    assert not [t["value"] for t in trials if fail_value < t["value"] < pass_value]  # the tightest bracket
    assert outcome["termination"] in TERMINATIONS
    if pass_value - fail_value > BOUNDARY["tolerance"]:
        assert outcome["termination"] == "max_trials" and n == BOUNDARY["max_iters"]
    assert f"{n} trials, {runs} runs (0 trials cached) vs 101 for a linear sweep" in out
    assert len([line for line in out.splitlines() if line.lstrip().startswith("step ")]) >= n

    # the same command again: every trial read back from the cache, no SLAM run at all
    slam_calls.clear()
    assert main(args) == 0
    out = capsys.readouterr().out
    assert slam_calls == []
    assert sorted(p.name for p in (folder / "runs").iterdir()) == run_dirs
    again = read(folder / "boundary_summary.json")["outcome"]
    assert all(t["cached"] for t in again["trials"])
    assert without_cache_fields(again["trials"]) == without_cache_fields(trials)
    assert [votes(t) for t in again["trials"]] == [votes(t) for t in trials]
    assert (again["boundary"], again["termination"]) == (outcome["boundary"], outcome["termination"])
    assert f"{n} trials, {runs} runs ({n} trials cached)" in out


# ------------------------------------------------------------------------------ sal features


def test_features_orb_tracks_every_sequence_and_fog_costs_matches(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``sal features`` runs no SLAM system: one run covers both."""
    config = write_config(tmp_path)
    assert main(["features", str(config), "--features", "orb"]) == 0
    root = tmp_path / "results" / NAME / "features"
    assert files_under(root) == {"orb/summary.json", "orb/track_survival.png", "orb/detections.png"}
    assert png_size(root / "orb" / "track_survival.png") and png_size(root / "orb" / "detections.png")
    summary = read(root / "orb" / "summary.json")
    assert summary["feature"] == "orb" and summary["extractor"].startswith("OrbExtractor(")
    seqs = summary["sequences"]
    assert list(seqs) == ["baseline", *PERTURBATIONS]
    for name, s in seqs.items():
        assert s["frames"] == FRAMES and s["feature"] == "orb"
        detections, matches = s["detections_per_frame"]["values"], s["matches_per_frame"]["values"]
        assert len(detections) == FRAMES and len(matches) == FRAMES - 1
        assert all(0 <= m <= min(a, b) for m, a, b in zip(matches, detections, detections[1:])), name
        assert s["matches_per_frame"]["mean"] == pytest.approx(float(np.mean(matches)), abs=1e-6)
        survival = s["survival"]
        if s["tracks"] == 0:
            assert survival == [] and sum(detections) == 0
            continue
        assert survival[0] == 1.0, name  # every track lasts at least one frame
        assert all(b <= a for a, b in pairwise(survival)), name  # never increases
        assert len(survival) == s["max_track_length"] <= FRAMES and survival[-1] > 0
        assert s["tracks"] == sum(detections) - sum(matches)  # each unmatched keypoint starts a track
        assert s["mean_track_length"] == pytest.approx(sum(detections) / s["tracks"], rel=1e-5)

    clean = seqs["baseline"]
    assert clean["matches_per_frame"]["mean"] > 300  # measured 493 of 1000 keypoints
    # fog at 60 m costs a third of the matches and shortens tracks (measured 312 vs 493)
    assert seqs["fog"]["matches_per_frame"]["mean"] < 0.8 * clean["matches_per_frame"]["mean"]
    assert seqs["fog"]["mean_track_length"] < clean["mean_track_length"]
    # at 4 m the image is flat: not one keypoint (measured), so no track at all
    assert seqs[FAILING]["detections_per_frame"]["max"] == 0 and seqs[FAILING]["tracks"] == 0
    for name in ("rain", "rain_soiled_lens"):
        assert seqs[name]["matches_per_frame"]["mean"] < clean["matches_per_frame"]["mean"]
    out = capsys.readouterr().out
    assert "orb:" in out and all(name in out for name in seqs)
