"""Trajectory metrics: agreement with evo's command line on reference trajectories, known
answers on synthetic trajectories, association, failures and aggregation."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pytest_sal.analysis.metrics import AGGREGATED, RunMetrics, aggregate, evaluate
from pytest_sal.analysis.trajectory_errors import associate, ate, default_max_diff, rpe, scale_error
from sal_adapters.common.errors import SalError
from sal_adapters.trajectory import Trajectory
from sal_wrappers.base import RunResult, TrackState

EVO_BIN = Path(sys.executable).parent
REL = 1e-6


# -- helpers ------------------------------------------------------------------------------------
def curve(n: int = 200, fps: float = 10.0, noise: float = 0.0, seed: int = 0) -> Trajectory:
    """A smooth 3-D loop (about 60 m) sampled at ``fps``, optionally with position noise (m)."""
    u = np.linspace(0.0, 2 * np.pi, n)
    positions = np.column_stack([10 * np.cos(u), 0.5 * np.sin(3 * u), 8 * np.sin(u)])
    positions += np.random.default_rng(seed).normal(0.0, noise, positions.shape) if noise else 0.0
    quats = Rotation.from_euler("yx", np.column_stack([u, 0.1 * np.sin(2 * u)])).as_quat()
    return Trajectory(np.arange(n) / fps, positions, quats)


def similar(traj: Trajectory, s: float, rotvec: tuple[float, float, float], t: tuple[float, float, float]) -> Trajectory:
    """``traj`` in a world moved by the similarity ``p -> s R p + t``."""
    r = Rotation.from_rotvec(rotvec)
    return Trajectory(
        traj.timestamps, s * r.apply(traj.positions.copy()) + np.asarray(t), (r * Rotation.from_quat(traj.quaternions.copy())).as_quat()
    )


def run_result(traj: Trajectory | None, *, sensor: str = "mono", frames: int = 200, failure: str | None = None) -> RunResult:
    stamps = np.arange(frames) / 10.0
    states = np.full(frames, TrackState.LOST, dtype=np.int8)
    if traj is not None:
        states[np.isin(stamps, traj.timestamps)] = TrackState.OK
    return RunResult(
        system="fake", sequence="loop", sensor=sensor, timestamps=stamps, states=states, trajectory=traj, maps=1, failure=failure
    )


def evo_cli(tool: str, runs: list[list[str]], workdir: Path) -> list[tuple[dict[str, float], int, float | None]]:
    """Run ``evo_ape`` / ``evo_rpe`` once per argument list (at the same time); return per run
    its stats, the number of errors and the Sim(3) scale (``None`` without ``-s``)."""
    exe = EVO_BIN / tool
    if not exe.exists():
        pytest.skip(f"{tool} not found beside {sys.executable}")
    zips = [workdir / f"{tool}-{i}.zip" for i in range(len(runs))]
    homes = [workdir / f"home-{i}" for i in range(len(runs))]  # evo creates ~/.evo on first use: one HOME per process, or they race
    procs = []
    for args, out, home in zip(runs, zips, homes):
        home.mkdir()
        env = {**os.environ, "HOME": str(home), "MPLBACKEND": "Agg"}
        procs.append(
            subprocess.Popen(
                [str(exe), *args, "--save_results", str(out), "--no_warnings", "--silent"],
                env=env,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
            )
        )
    results = []
    for args, proc, out in zip(runs, procs, zips):
        log, _ = proc.communicate(timeout=120)
        assert proc.returncode == 0, f"{tool} {' '.join(args)} failed:\n{log}"
        with zipfile.ZipFile(out) as z:
            stats = json.loads(z.read("stats.json"))
            count = len(np.load(io.BytesIO(z.read("error_array.npy"))))
            sim3 = (
                np.load(io.BytesIO(z.read("alignment_transformation_sim3.npy")))
                if "alignment_transformation_sim3.npy" in z.namelist()
                else None
            )
        results.append((stats, count, None if sim3 is None else float(np.cbrt(np.linalg.det(sim3[:3, :3])))))
    return results


def load_pair(folder: Path, fmt: str, ref_name: str, est_name: str) -> tuple[Trajectory, Trajectory]:
    """Our reading of the files evo reads (KITTI: frame index as time for both, as evo pairs by index)."""
    ref_path, est_path = folder / ref_name, folder / est_name
    if fmt == "kitti":
        return Trajectory.read_kitti(ref_path), Trajectory.read_kitti(est_path)
    if fmt == "euroc":
        return Trajectory.read_euroc(ref_path), Trajectory.read_tum(est_path)
    return Trajectory.read_tum(ref_path), Trajectory.read_tum(est_path)


def cli_files(folder: Path, fmt: str, ref_name: str, est_name: str, max_diff: float) -> list[str]:
    sync = [] if fmt == "kitti" else ["--t_max_diff", repr(float(max_diff))]
    return [fmt, str(folder / ref_name), str(folder / est_name), *sync]


@pytest.fixture(scope="module")
def evo_data(shared_data: Path) -> Path:
    folder = shared_data / "trajectories" / "evo_test_data"
    if not folder.is_dir():
        pytest.skip(f"evo reference trajectories not found at {folder}")
    return folder


# -- agreement with evo's command line --------------------------------------------------------------
ATE_CASES = [
    pytest.param("kitti", "KITTI_00_gt.txt", "KITTI_00_ORB.txt", "se3", id="kitti00-orb-se3"),
    pytest.param("kitti", "KITTI_00_gt.txt", "KITTI_00_ORB.txt", "sim3", id="kitti00-orb-sim3"),
    pytest.param("tum", "fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt", "sim3", id="fr2desk-orb-sim3"),
    pytest.param("tum", "freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam.txt", "se3", id="fr1xyz-rgbdslam-se3"),
    pytest.param("euroc", "V102_groundtruth.csv", "V102.txt", "se3", id="v102-se3"),
]


@pytest.mark.parametrize(("fmt", "ref_name", "est_name", "align"), ATE_CASES)
def test_ate_matches_evo_ape_command_line(evo_data: Path, tmp_path: Path, fmt: str, ref_name: str, est_name: str, align: str) -> None:
    reference, estimate = load_pair(evo_data, fmt, ref_name, est_name)
    ours = ate(estimate, reference, align=align)
    args = cli_files(evo_data, fmt, ref_name, est_name, ours.max_diff) + ["-a"] + (["-s"] if align == "sim3" else [])
    ((stats, count, scale),) = evo_cli("evo_ape", [args], tmp_path)
    assert ours.matched == count == len(ours.errors) == len(ours.timestamps)
    for name in ("rmse", "mean", "median", "std", "min", "max"):
        assert getattr(ours, name) == pytest.approx(stats[name], rel=REL), name
    assert ours.scale == pytest.approx(scale if align == "sim3" else 1.0, rel=REL)


RPE_CASES = [
    pytest.param("kitti", "KITTI_00_gt.txt", "KITTI_00_ORB.txt", "se3", 100.0, "m", id="kitti00-orb-100m"),
    pytest.param("tum", "fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt", "sim3", 0.5, "m", id="fr2desk-orb-sim3-0.5m"),
    pytest.param("euroc", "V102_groundtruth.csv", "V102.txt", "se3", 10, "frames", id="v102-10frames"),
]


@pytest.mark.parametrize(("fmt", "ref_name", "est_name", "align", "delta", "unit"), RPE_CASES)
def test_rpe_matches_evo_rpe_command_line(
    evo_data: Path, tmp_path: Path, fmt: str, ref_name: str, est_name: str, align: str, delta: float, unit: str
) -> None:
    reference, estimate = load_pair(evo_data, fmt, ref_name, est_name)
    ours = rpe(estimate, reference, delta=delta, unit=unit, align=align)
    folder = evo_data
    if fmt == "kitti":
        # KITTI rotations are printed to 7 digits, slightly off orthonormal; we read them as
        # the nearest rotation, which moves RPE by ~5e-6 relative: give evo those poses.
        folder = tmp_path
        reference.write_kitti(folder / ref_name)
        estimate.write_kitti(folder / est_name)
    common = cli_files(folder, fmt, ref_name, est_name, ours.max_diff)
    common += ["-a", *(["-s"] if align == "sim3" else []), "-d", str(delta), "-u", unit[0], "--pairs_from_reference"]
    relations = {"trans_part": ours.trans, "angle_deg": ours.rot}
    cli = evo_cli("evo_rpe", [[*common, "-r", relation] for relation in relations], tmp_path)
    for (relation, mine), (stats, count, _) in zip(relations.items(), cli):
        assert ours.pairs == count
        for name in ("rmse", "mean", "median", "std", "min", "max"):
            assert getattr(mine, name) * delta == pytest.approx(stats[name], rel=REL), f"{relation} {name}"


# -- known answers ------------------------------------------------------------------------------
def test_similarity_transformed_estimate_has_zero_sim3_error() -> None:
    reference = curve()
    estimate = similar(reference, 3.0, (0.2, -0.4, 0.9), (5.0, -2.0, 1.0))
    sim3 = ate(estimate, reference, align="sim3")
    assert sim3.rmse < 1e-9 and sim3.max < 1e-9
    assert sim3.scale == pytest.approx(1 / 3, rel=1e-9)  # s maps the estimate onto the reference
    assert scale_error(estimate, reference) == pytest.approx(2 / 3, rel=1e-9)
    assert sim3.estimate.allclose(reference, atol=1e-9)
    se3 = ate(estimate, reference, align="se3")
    assert se3.rmse > 5.0 and se3.scale == 1.0
    assert ate(estimate, reference, align="none").rmse > se3.rmse
    assert rpe(estimate, reference, align="sim3").trans.max < 1e-9
    assert rpe(estimate, reference, align="sim3").rot.max < 1e-6


def test_rpe_is_drift_per_unit_of_delta() -> None:
    """A straight line run 1 % too long: 0.01 m per metre, 0.1 m per second at 1 m/s."""
    n = 101
    stamps = np.arange(n) / 1.0
    quats = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    reference = Trajectory(stamps, np.column_stack([np.arange(n), np.zeros(n), np.zeros(n)]), quats)
    estimate = Trajectory(stamps, np.column_stack([1.01 * np.arange(n), np.zeros(n), np.zeros(n)]), quats)
    per_metre = rpe(estimate, reference, delta=10.0, unit="m", align="none")
    per_second = rpe(estimate, reference, delta=5.0, unit="s", align="none")
    per_frame = rpe(estimate, reference, delta=20, unit="frames", align="none")
    assert per_metre.pairs == 10 and per_second.pairs == 20 and per_frame.pairs == 5
    assert np.allclose(per_metre.trans_errors, 0.01) and np.allclose(per_second.trans_errors, 0.01)
    assert np.allclose(per_frame.trans_errors, 0.01)
    assert per_metre.rot.max == pytest.approx(0.0, abs=1e-9)


def test_rpe_per_second_agrees_with_evo_frames_on_even_sampling() -> None:
    reference = curve(noise=0.0)
    estimate = similar(curve(noise=0.05, seed=3), 1.0, (0.0, 0.3, 0.0), (1.0, 0.0, 0.0))
    seconds = rpe(estimate, reference, delta=2.0, unit="s")
    frames = rpe(estimate, reference, delta=20, unit="frames")
    assert seconds.pairs == frames.pairs
    assert np.allclose(seconds.trans_errors * 2.0, frames.trans_errors * 20, rtol=1e-9)
    assert np.allclose(seconds.rot_errors * 2.0, frames.rot_errors * 20, rtol=1e-7, atol=1e-9)
    assert np.allclose(seconds.timestamps, frames.timestamps)


def test_inputs_are_never_mutated() -> None:
    reference = curve()
    estimate = similar(curve(noise=0.02), 3.0, (0.1, 0.2, 0.3), (1.0, 2.0, 3.0))
    before = [a.copy() for t in (estimate, reference) for a in (t.timestamps, t.positions, t.quaternions)]
    first = ate(estimate, reference, align="sim3")
    rpe(estimate, reference, align="sim3")
    second = ate(estimate, reference, align="sim3")
    after = [a for t in (estimate, reference) for a in (t.timestamps, t.positions, t.quaternions)]
    assert all(np.array_equal(b, a) for b, a in zip(before, after))
    assert second.scale == first.scale == pytest.approx(1 / 3, rel=1e-3)  # not re-aligned in place
    assert not first.estimate.allclose(estimate, atol=1e-3)


# -- association ----------------------------------------------------------------------------------
def test_association_tolerance_follows_the_frame_rate() -> None:
    reference = curve(fps=10.0)
    late = Trajectory(reference.timestamps + 0.03, reference.positions, reference.quaternions)
    pair = associate(late, reference)  # both at 10 Hz: half a period is 0.05 s
    assert pair.max_diff == pytest.approx(0.05) and len(pair.estimate) == len(reference)
    assert np.allclose(pair.estimate.timestamps - pair.reference.timestamps, 0.03)
    assert associate(late, reference, fps=10.0).max_diff == pytest.approx(0.05)
    with pytest.raises(SalError, match="within 0.0166667 s"):
        associate(late, reference, fps=30.0)
    with pytest.raises(SalError):
        associate(late, reference, max_diff=0.02)
    assert len(associate(late, reference, max_diff=0.04).estimate) == len(reference)
    assert default_max_diff(late, reference, fps=200.0) == 0.01  # never below 0.01 s
    assert default_max_diff(curve(fps=30.0), curve(fps=100.0)) == 0.01  # half the denser period, at least 0.01
    assert default_max_diff(curve(fps=5.0), curve(fps=8.0)) == pytest.approx(0.0625)


def test_no_overlap_names_both_time_ranges() -> None:
    reference = curve()
    later = Trajectory(reference.timestamps + 100.0, reference.positions, reference.quaternions)
    with pytest.raises(SalError, match=r"estimate spans 100\.000\.\.119\.900 s \(200 poses\), reference spans 0\.000\.\.19\.900 s"):
        ate(later, reference)


def test_too_few_associated_poses_for_alignment() -> None:
    reference = curve()
    with pytest.raises(SalError, match="needs 3"):
        ate(reference.select([0, 1]), reference)
    assert ate(reference.select([0, 1]), reference, align="none").rmse == 0.0
    still = Trajectory(reference.timestamps, np.zeros((len(reference), 3)), reference.quaternions)
    with pytest.raises(SalError, match="evo: .*[Dd]egenerate"):
        ate(still, reference, align="sim3")
    with pytest.raises(SalError, match="empty index list"):
        rpe(reference, reference, delta=1000.0)


def test_evaluate_a_monocular_run_aligned_se3_still_reports_its_scale_error() -> None:
    reference = curve()
    metrics = evaluate(run_result(similar(reference, 2.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))), reference, align="se3")
    assert metrics.align == "se3" and metrics.ate_rmse > 1.0 and metrics.scale is None
    assert metrics.scale_error == pytest.approx(0.5)


# -- one run and many runs ----------------------------------------------------------------------
def test_evaluate_a_good_monocular_run() -> None:
    reference = curve()
    tracked = similar(reference, 3.0, (0.0, 0.5, 0.0), (2.0, 0.0, 0.0)).select(np.arange(20, 200))
    metrics = evaluate(run_result(tracked), reference)
    assert metrics.ok and metrics.align == "sim3" and metrics.scored == "online"
    assert metrics.frames == 200 and metrics.tracked == 180 and metrics.matched == 180
    assert metrics.tracking_rate == pytest.approx(0.9) and metrics.first_tracked == 20
    assert metrics.ate_rmse < 1e-9 and metrics.rpe_trans < 1e-9 and metrics.rpe_rot < 1e-6
    assert metrics.scale == pytest.approx(1 / 3) and metrics.scale_error == pytest.approx(2 / 3)
    assert metrics.ate is not None and metrics.ate.matched == 180
    data = json.loads(json.dumps(metrics.to_dict()))
    assert data["ate_rmse"] == metrics.ate_rmse and "ate" not in data


def test_evaluate_a_stereo_run_aligns_se3_without_scale_error() -> None:
    reference = curve()
    metrics = evaluate(run_result(similar(reference, 1.0, (0.0, 0.5, 0.0), (2.0, 0.0, 0.0)), sensor="stereo"), reference)
    assert metrics.align == "se3" and metrics.ate_rmse < 1e-9 and metrics.scale_error is None and metrics.scale is None


@pytest.mark.parametrize(
    ("trajectory", "failure", "reason"),
    [
        pytest.param(curve(), "exit status -11 (SIGSEGV)", "exit status -11", id="crashed"),
        pytest.param(curve().select([5, 6]), None, "too few to score", id="two-poses"),
        pytest.param(None, None, "0 pose", id="nothing-tracked"),
    ],
)
def test_evaluate_a_failed_run_gives_metrics_with_the_reason(trajectory: Trajectory | None, failure: str | None, reason: str) -> None:
    metrics = evaluate(run_result(trajectory, failure=failure), curve())
    assert metrics.ate_rmse is None and metrics.rpe_trans is None and metrics.scale_error is None
    assert not metrics.ok and reason in metrics.failure
    assert metrics.frames == 200


def test_evaluate_without_overlap_or_groundtruth() -> None:
    reference = curve()
    later = Trajectory(reference.timestamps + 100.0, reference.positions, reference.quaternions)
    unscored = evaluate(run_result(later), reference)
    assert unscored.ate_rmse is None and "not scored" in unscored.failure and "100.000..119.900" in unscored.failure
    no_gt = evaluate(run_result(reference), None)
    assert no_gt.ok and no_gt.ate_rmse is None and not no_gt.has_groundtruth and no_gt.tracking_rate == 1.0


def test_aggregate_ignores_missing_values() -> None:
    reference = curve()
    noisy = [evaluate(run_result(curve(noise=s, seed=1), sensor="stereo"), reference) for s in (0.01, 0.03)]
    failed = evaluate(run_result(None, failure="timeout after 60 s"), reference)
    summary = aggregate([*noisy, failed])
    assert summary["runs"] == 3 and summary["failures"] == 1
    ate_values = [m.ate_rmse for m in noisy]
    assert summary["ate_rmse"] == {
        "median": pytest.approx(np.median(ate_values)),
        "mean": pytest.approx(np.mean(ate_values)),
        "min": min(ate_values),
        "max": max(ate_values),
        "count": 2,
        "values": ate_values,
    }
    assert summary["tracking_rate"]["values"] == [1.0, 1.0, 0.0]
    assert summary["scale_error"] == {"median": None, "mean": None, "min": None, "max": None, "count": 0, "values": []}
    assert set(AGGREGATED) <= set(summary)
    assert aggregate([])["runs"] == 0
    # one rule with a trial's medians: a metric missing in half the runs or more has no statistics
    mostly_failed = aggregate([noisy[0], failed, failed])
    assert mostly_failed["ate_rmse"] == {"median": None, "mean": None, "min": None, "max": None, "count": 1, "values": [ate_values[0]]}
    assert mostly_failed["failure_reasons"] == ["timeout after 60 s"] * 2
    assert aggregate([noisy[0].to_dict(), failed.to_dict()])["ate_rmse"]["median"] is None  # 1 of 2: not more than half


def test_run_metrics_fields_are_json_ready() -> None:
    metrics = RunMetrics(
        system="s",
        sequence="q",
        sensor="mono",
        scored="final",
        align="sim3",
        frames=0,
        tracked=0,
        tracking_rate=0.0,
        first_tracked=None,
        maps=0,
    )
    assert json.loads(json.dumps(metrics.to_dict()))["scored"] == "final"


@pytest.mark.parametrize("position", [1e308, -1e308, 1e12])
@pytest.mark.parametrize("sensor", ["mono", "stereo"])
def test_poses_far_beyond_any_drive_fail_the_run_with_the_reason_instead_of_raising(position: float, sensor: str) -> None:
    """Poses at 1e308 m made evo's alignment raise ``LinAlgError: SVD did not converge``, which
    failed the test instead of the run (issue 23, item 12)."""
    gt = curve()
    positions = gt.positions.copy()
    positions[50:60] = position
    estimate = Trajectory(gt.timestamps, positions, gt.quaternions)
    scored = evaluate(run_result(estimate, sensor=sensor), gt)
    assert scored.failure is not None and scored.failure.startswith("not scored: 10 of 200 poses lie beyond 1e+06 m from the origin")
    assert scored.ate_rmse is None and scored.tracking_rate == 1.0
