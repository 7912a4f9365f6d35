"""KITTI's t_rel / r_rel: the vectorised metric against a literal port of the devkit's C++ on
real KITTI ground truth and a real estimate, physics checks, lost frames, short sequences,
monocular scale and the places the metric reaches (requirements, YAML, trial runs)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from plugin_suites import project, run
from scipy.spatial.transform import Rotation

from pytest_sal.analysis.kitti_metrics import (
    KITTI_SEGMENTS_M,
    kitti_errors,
    kitti_odometry,
    parse_segments,
    segment_lengths,
    trajectory_distances,
)
from pytest_sal.analysis.metrics import AGGREGATED, evaluate
from pytest_sal.engine.outcomes.outcome import Boundary, Outcome, Trial
from pytest_sal.engine.requirements import METRICS, Requirement, r_rel, t_rel
from pytest_sal.engine.search.requirement_search import failure_message
from pytest_sal.experiment.config import ConfigError, parse_config
from sal_adapters.common.errors import SalError
from sal_adapters.trajectory import Trajectory
from sal_modules import fog
from sal_wrappers.base import RunResult, TrackState

SHORT = (10.0, 20.0, 30.0, 40.0)


# -- the oracle: evaluate_odometry.cpp of the KITTI odometry devkit, loop for loop ------------
def devkit_trajectory_distances(poses: np.ndarray) -> list[float]:
    dist = [0.0]
    for i in range(1, len(poses)):
        p1, p2 = poses[i - 1], poses[i]
        dx, dy, dz = p1[0, 3] - p2[0, 3], p1[1, 3] - p2[1, 3], p1[2, 3] - p2[2, 3]
        dist.append(dist[i - 1] + math.sqrt(dx * dx + dy * dy + dz * dz))
    return dist


def devkit_last_frame_from_segment_length(dist: list[float], first_frame: int, length: float) -> int:
    for i in range(first_frame, len(dist)):
        if dist[i] > dist[first_frame] + length:
            return i
    return -1


def devkit_rotation_error(pose_error: np.ndarray) -> float:
    a, b, c = pose_error[0, 0], pose_error[1, 1], pose_error[2, 2]
    d = 0.5 * (a + b + c - 1.0)
    return math.acos(max(min(d, 1.0), -1.0))


def devkit_translation_error(pose_error: np.ndarray) -> float:
    dx, dy, dz = pose_error[0, 3], pose_error[1, 3], pose_error[2, 3]
    return math.sqrt(dx * dx + dy * dy + dz * dz)


def devkit_sequence_errors(
    poses_gt: np.ndarray, poses_result: np.ndarray, lengths: tuple[float, ...]
) -> list[tuple[int, int, float, float, float]]:
    """``(first_frame, last_frame, len, r_err, t_err)`` per segment, as ``calcSequenceErrors``."""
    err = []
    step_size = 10
    dist = devkit_trajectory_distances(poses_gt)
    for first_frame in range(0, len(poses_gt), step_size):
        for length in lengths:
            last_frame = devkit_last_frame_from_segment_length(dist, first_frame, length)
            if last_frame == -1:
                continue
            pose_delta_gt = np.linalg.inv(poses_gt[first_frame]) @ poses_gt[last_frame]
            pose_delta_result = np.linalg.inv(poses_result[first_frame]) @ poses_result[last_frame]
            pose_error = np.linalg.inv(pose_delta_result) @ pose_delta_gt
            r_err = devkit_rotation_error(pose_error)
            t_err = devkit_translation_error(pose_error)
            err.append((first_frame, last_frame, length, r_err / length, t_err / length))
    return err


def devkit_summary(err: list[tuple[int, int, float, float, float]]) -> tuple[float, float]:
    """``(t_rel %, r_rel deg/100 m)``: the means over all segments, as the KITTI table shows them."""
    t = sum(e[4] for e in err) / len(err)
    r = sum(e[3] for e in err) / len(err)
    return 100.0 * t, r * 180.0 / math.pi * 100.0


# -- data -----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def trajectories(shared_data: Path) -> Path:
    return shared_data / "trajectories"


@pytest.fixture(scope="module")
def gt07(trajectories: Path) -> Trajectory:
    """KITTI 07 ground truth, 1101 frames, about 695 m."""
    return Trajectory.read_kitti(trajectories / "kitti_gt_poses_with_times" / "07.txt")


def perturbed(gt: Trajectory, seed: int = 7) -> Trajectory:
    """``gt`` with a 2 % scale error, a yaw drift growing along the path, 5 cm position noise
    and 0.1 deg rotation noise: every part of the devkit's error is exercised."""
    rng = np.random.default_rng(seed)
    poses = gt.matrices
    dist = trajectory_distances(gt.positions)
    drift = Rotation.from_euler("y", np.radians(0.8 / 100.0) * dist[:, None]).as_matrix()  # 0.8 deg/100 m about the camera's vertical
    noise = Rotation.from_rotvec(rng.normal(0.0, np.radians(0.1), (len(gt), 3))).as_matrix()
    out = poses.copy()
    out[:, :3, :3] = drift @ poses[:, :3, :3] @ noise
    out[:, :3, 3] = 1.02 * np.einsum("nij,nj->ni", drift, poses[:, :3, 3]) + rng.normal(0.0, 0.05, (len(gt), 3))
    return Trajectory.from_matrices(gt.timestamps, out)


def assert_same_as_devkit(result, oracle: list[tuple[int, int, float, float, float]]) -> None:
    first, last, length, r_err, t_err = (np.asarray(column) for column in zip(*oracle))
    order = np.lexsort((result.length, result.first))  # the devkit's order: by first frame, then length
    assert np.array_equal(result.first[order], first) and np.array_equal(result.last[order], last)
    assert np.array_equal(result.length[order], length)
    np.testing.assert_allclose(result.t_errors[order], t_err, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(result.r_errors[order], r_err, rtol=0, atol=1e-9)  # acos near 1 is good to ~1e-8 rad
    t, r = devkit_summary(oracle)
    assert result.t_rel == pytest.approx(t, rel=1e-9) and result.r_rel == pytest.approx(r, rel=1e-6)
    assert result.count == len(oracle)


# -- against the devkit ---------------------------------------------------------------------------
@pytest.mark.parametrize("lengths", [KITTI_SEGMENTS_M, SHORT], ids=["devkit-100-800m", "short-10-40m"])
def test_a_perturbed_kitti_ground_truth_scores_as_the_devkit_scores_it(gt07: Trajectory, lengths: tuple[float, ...]) -> None:
    estimate = perturbed(gt07)
    oracle = devkit_sequence_errors(gt07.matrices, estimate.matrices, lengths)
    result = kitti_errors(gt07.matrices, estimate.matrices, segments_m=lengths)
    assert_same_as_devkit(result, oracle)
    assert result.t_rel > 1.0 and result.r_rel > 0.3  # the perturbation shows
    # paired by timestamp and rigidly aligned first: a rigid alignment changes no relative pose
    aligned = kitti_odometry(estimate, gt07, segments_m=lengths, align="se3")
    assert aligned.t_rel == pytest.approx(result.t_rel, rel=1e-9) and aligned.r_rel == pytest.approx(result.r_rel, rel=1e-6)


def test_orb_slam2_on_kitti_00_scores_as_the_devkit_and_as_its_paper_reports(trajectories: Path) -> None:
    """A real estimate: ORB-SLAM2 (stereo) on all of KITTI 00; its paper (Mur-Artal and
    Tardos 2017, table 2) reports t_rel 0.70 % and r_rel 0.25 deg/100 m for this sequence."""
    folder = trajectories / "evo_test_data"
    times = folder / "KITTI_00_gt_times.txt"
    gt = Trajectory.read_kitti(folder / "KITTI_00_gt.txt", times)
    orb = Trajectory.read_kitti(folder / "KITTI_00_ORB.txt", times)
    result = kitti_errors(gt.matrices, orb.matrices)
    assert_same_as_devkit(result, devkit_sequence_errors(gt.matrices, orb.matrices, KITTI_SEGMENTS_M))
    assert round(result.t_rel, 2) == 0.70 and round(result.r_rel, 2) == 0.25
    short = kitti_errors(gt.matrices[:600], orb.matrices[:600], segments_m=SHORT)  # short segments on a short excerpt
    assert_same_as_devkit(short, devkit_sequence_errors(gt.matrices[:600], orb.matrices[:600], SHORT))


def test_a_segment_ends_past_its_length_not_on_it() -> None:
    """On a straight line of 1 m steps, frame f + 10 is exactly 10 m on: the devkit's ``>``
    ends the 10 m segment at f + 11."""
    poses = np.tile(np.eye(4), (40, 1, 1))
    poses[:, 2, 3] = np.arange(40.0)
    estimate = poses.copy()
    estimate[:, 2, 3] *= 1.1
    result = kitti_errors(poses, estimate, segments_m=(10.0,))
    assert result.first.tolist() == [0, 10, 20] and result.last.tolist() == [11, 21, 31]
    assert_same_as_devkit(result, devkit_sequence_errors(poses, estimate, (10.0,)))
    assert result.t_rel == pytest.approx(11.0)  # 10 % of 11 m over 10 m


# -- physics --------------------------------------------------------------------------------------
def test_the_ground_truth_against_itself_scores_zero(gt07: Trajectory) -> None:
    result = kitti_odometry(gt07, gt07, segments_m=SHORT)
    assert result.count > 0 and result.t_rel < 1e-9 and result.r_rel < 1e-9


def test_a_constant_scale_error_of_one_percent_is_a_t_rel_of_one_percent(gt07: Trajectory) -> None:
    """The devkit's error is the segment's end-point error: 1 % of the chord, which is the path
    on a straight road (10-40 m on KITTI 07) and less on its long loops (0.62 % over 100-800 m)."""
    poses = gt07.matrices
    scaled = poses.copy()
    scaled[:, :3, 3] *= 1.01
    for lengths, expected in ((SHORT, 1.0), (KITTI_SEGMENTS_M, 0.62)):
        result = kitti_errors(poses, scaled, segments_m=lengths)
        chord = np.linalg.norm(poses[result.last, :3, 3] - poses[result.first, :3, 3], axis=1)
        np.testing.assert_allclose(result.t_errors, 0.01 * chord / result.length, rtol=1e-9)  # |E_t| = 1 % of the chord
        assert result.t_rel == pytest.approx(expected, abs=0.02) and result.r_rel < 1e-9


@pytest.mark.parametrize("drift", [0.5, 2.0])
def test_a_constant_yaw_drift_per_100_m_is_that_r_rel(gt07: Trajectory, drift: float) -> None:
    poses = gt07.matrices
    dist = trajectory_distances(gt07.positions)
    turned = Rotation.from_euler("y", np.radians(drift / 100.0) * dist[:, None]).as_matrix() @ poses[:, :3, :3]
    drifted = poses.copy()
    drifted[:, :3, :3] = turned
    result = kitti_errors(poses, drifted, segments_m=KITTI_SEGMENTS_M)
    travelled = dist[result.last] - dist[result.first]
    np.testing.assert_allclose(result.r_errors, np.radians(drift / 100.0) * travelled / result.length, rtol=1e-6)
    assert result.r_rel == pytest.approx(drift, rel=0.02)


# -- lost frames, short sequences, scale ------------------------------------------------------------
def test_segments_with_a_lost_end_are_skipped(gt07: Trajectory) -> None:
    estimate = perturbed(gt07)
    lost = np.zeros(len(gt07), dtype=bool)
    lost[200:420] = True
    lost[905] = True
    garbage = estimate.matrices
    garbage[lost, :3, 3] = 1e6  # never read
    result = kitti_errors(gt07.matrices, garbage, ~lost, segments_m=SHORT)
    oracle = [e for e in devkit_sequence_errors(gt07.matrices, estimate.matrices, SHORT) if not lost[e[0]] and not lost[e[1]]]
    assert_same_as_devkit(result, oracle)
    assert result.skipped > 0 and result.count + result.skipped == len(devkit_sequence_errors(gt07.matrices, estimate.matrices, SHORT))
    # the same through timestamps: the lost frames are simply absent from the estimate
    dropped = kitti_odometry(estimate.select(~lost), gt07, segments_m=SHORT, align="none")
    assert dropped.count == result.count and dropped.t_rel == pytest.approx(result.t_rel, rel=1e-9)


def test_nothing_to_score_is_missing_with_a_reason_never_zero(shared_data: Path, gt07: Trajectory) -> None:
    excerpt = Trajectory.read_kitti(shared_data / "kitti" / "poses" / "07.txt")  # 140 frames, 78 m
    short = kitti_odometry(excerpt, excerpt)
    assert short.t_rel is None and short.r_rel is None and short.count == 0
    assert (
        short.reason
        == "the reference path is 78.4 m, too short for a segment of 100 m (KITTI segment lengths 100, 200, 300, 400, 500, 600, 700, 800 m)"
    )
    assert kitti_odometry(excerpt, excerpt, segments_m=SHORT).t_rel == pytest.approx(0.0, abs=1e-9)
    tracked = np.zeros(len(gt07), dtype=bool)
    tracked[::10] = True  # every segment starts on a tracked frame, but ends on a lost one
    tracked[gt07.timestamps > 30] = False
    lost = kitti_errors(gt07.matrices, gt07.matrices, tracked, segments_m=(500.0,))
    assert (
        lost.t_rel is None
        and lost.skipped > 0
        and lost.reason == f"none of the {lost.skipped} KITTI segment(s) has an estimated pose at both ends (tracking lost)"
    )


def mono_run(estimate: Trajectory, reference: Trajectory) -> RunResult:
    states = np.full(len(reference), TrackState.OK, dtype=np.int8)
    return RunResult(
        system="fake", sequence="07", sensor="mono", timestamps=reference.timestamps, states=states, trajectory=estimate, maps=1
    )


def test_a_monocular_run_is_scored_after_the_sim3_alignment_of_its_ate(gt07: Trajectory) -> None:
    """A monocular map has an arbitrary scale (here 0.3) and frame: the Sim(3) alignment of the
    ATE corrects both, so a perfect shape scores 0, while a rigid alignment leaves the 70 % error."""
    world = np.eye(4)
    world[:3, :3] = Rotation.from_rotvec([0.2, -1.0, 0.4]).as_matrix()
    world[:3, 3] = [5.0, -2.0, 30.0]
    poses = world @ gt07.matrices
    poses[:, :3, 3] *= 0.3
    mono = Trajectory.from_matrices(gt07.timestamps, poses)
    metrics = evaluate(mono_run(mono, gt07), gt07, kitti_segments=SHORT)
    assert metrics.align == "sim3" and metrics.kitti_segments_m == SHORT and metrics.kitti_segments > 0
    assert metrics.t_rel < 1e-6 and metrics.r_rel < 1e-6 and metrics.kitti_missing is None
    rigid = evaluate(mono_run(mono, gt07), gt07, align="se3", kitti_segments=SHORT)
    assert rigid.t_rel == pytest.approx(70.0, rel=0.03)  # 70 % of the chord over the segment length
    default = evaluate(mono_run(gt07.select(slice(0, 140)), gt07.select(slice(0, 140))), gt07.select(slice(0, 140)))
    assert default.t_rel is None and default.failure is None and "too short for a segment of 100 m" in default.kitti_missing
    assert "t_rel" in default.to_dict() and {"t_rel", "r_rel"} <= set(AGGREGATED)


# -- options and where the metric goes ------------------------------------------------------------
def test_segment_lengths_are_checked_and_parsed() -> None:
    assert parse_segments("40, 10,20,30,") == SHORT and segment_lengths([20, 10, 20]) == (10.0, 20.0)
    for bad in ("", "10,x", "0", "-5", "nan", "inf"):
        with pytest.raises(SalError, match=r"KITTI segment lengths .*: expected numbers > 0 in metres separated by commas"):
            parse_segments(bad)
    for bad in ([], [0], [10, True], ["10"], "10"):
        with pytest.raises(SalError, match="KITTI segment lengths must be one or more numbers > 0"):
            segment_lengths(bad)


def test_t_rel_and_r_rel_are_requirement_metrics_with_units() -> None:
    requirement = Requirement.build([t_rel < 5, r_rel < 2, fog.visibility_m >= 25])
    assert str(requirement) == "t_rel < 5 % and r_rel < 2 deg/100m wherever fog.visibility_m >= 25 m"
    assert METRICS["t_rel"] is t_rel and METRICS["r_rel"].unit == "deg/100m"
    assert requirement.holds({"t_rel": 1.2, "r_rel": 0.4}) and not requirement.holds({"t_rel": None, "r_rel": 0.4})


YAML = "experiment: {name: e}\ndataset: {type: synthetic}\n"


def test_the_yaml_evaluation_section_sets_the_segment_lengths() -> None:
    assert parse_config(YAML).evaluation.kitti_segments_m is None
    assert parse_config(YAML + "evaluation: {kitti_segments_m: [40, 10, 20, 30]}\n").evaluation.kitti_segments_m == SHORT
    for value, message in (
        ("[]", "<config>: evaluation.kitti_segments_m: [] is not valid; must be a list of segment lengths > 0 m, e.g. [10, 20, 30, 40]"),
        ("[10, -1]", "<config>: evaluation.kitti_segments_m: [10, -1] is not valid; must be a list of segment lengths > 0 m"),
        ("10", "<config>: evaluation.kitti_segments_m: 10 is not valid; must be a list of segment lengths > 0 m"),
    ):
        with pytest.raises(ConfigError) as error:
            parse_config(YAML + f"evaluation: {{kitti_segments_m: {value}}}\n")
        assert str(error.value).startswith(message)
    with pytest.raises(ConfigError, match=r"evaluation.segments: unknown key; did you mean .kitti_segments_m.\?"):
        parse_config(YAML + "evaluation: {segments: [10]}\n")


def test_a_failed_test_says_why_its_kitti_metric_is_missing() -> None:
    why = "the reference path is 58.7 m, too short for a segment of 100 m (KITTI segment lengths 100, 200, 300, 400, 500, 600, 700, 800 m)"
    metrics = {"ate_rmse": 0.2, "tracking_rate": 1.0, "t_rel": None, "r_rel": None, "kitti_missing": why, "failures": []}
    trial = Trial(25.0, False, metrics, failed=["t_rel < 5 %"])
    outcome = Outcome(
        test_id="t",
        system="fake",
        dataset="urban",
        parameter="fog.visibility_m",
        worse="lower",
        edge=25.0,
        requirement="t_rel < 5 % wherever fog.visibility_m >= 25 m",
        criteria=[("t_rel", "<", 5.0)],
        envelope=">= 25 m",
        verdict="failed",
        boundary=Boundary(None, 25.0, "m"),
        termination="edge failed",
        trials=[trial],
    )
    assert f"at fog.visibility_m = 25 m: ate_rmse 0.2, tracking_rate 1, t_rel missing: {why}; failed: t_rel < 5 %" in failure_message(
        outcome
    )


def test_the_ini_segments_reach_the_plugins_trials(pytester: pytest.Pytester) -> None:
    """The 20-frame street is 19 m long: t_rel is missing with the devkit's lengths (the test
    fails, saying why) and scored with ``sal_kitti_segments = 5,10`` (the fake tracks it exactly)."""
    project(
        pytester,
        "from pytest_sal.engine.requirements import t_rel  # pytest_sal exports it once __init__ lists it\n\n@sal.at(fog.visibility_m, 100)\n@sal.require(t_rel < 5)\ndef test_kitti(sal_trial):\n    pass\n",
    )
    missing = run(pytester, [])
    missing.assert_outcomes(failed=1)
    missing.stdout.fnmatch_lines(["*t_rel missing: the reference path is * m, too short for a segment of 100 m*failed: t_rel < 5 %*"])
    scored = run(pytester, [], "-o", "sal_kitti_segments=5,10")
    scored.assert_outcomes(passed=1)
