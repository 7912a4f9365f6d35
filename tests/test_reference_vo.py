"""reference_vo, the built-in visual odometry: accuracy on the synthetic world and on the real
KITTI / EuRoC excerpts, states, determinism, blank frames, options, timeout and failures.

Figures measured (OpenCV 5.0.0, one core: ``taskset -c 0`` and ``cv2.setNumThreads(1)``, on a
shared, loaded machine, so fps varies by +-25 %; ATE = RMSE of ``pytest_sal.analysis.trajectory_errors.ate``, i.e.
evo's APE translation part, SE(3) alignment, Sim(3) for mono; fps = frames / time in the
tracking calls, decoding excluded):

==========================================  ==========  ========  ====  =======
sequence                                    ATE (m)     tracked   maps  fps
==========================================  ==========  ========  ====  =======
synthetic indoor RGB-D 640x480, 100 fr      0.0028      100 %     1     37-48
  same, tracker=klt                         0.0018      100 %     1     36-55
synthetic indoor mono (Sim3), 100 fr        0.017       100 %     1     37-47
synthetic urban stereo 1240x376, 30 fr      0.0091      100 %     1     26-33
synthetic urban mono (Sim3), 30 fr          0.063       100 %     1     19-24
KITTI 07 mono 1226x370 (Sim3), 140 fr       0.36        100 %     1     ~21
  same, tracker=klt                         0.43        100 %     1     ~39
EuRoC V1_01 micro stereo (raw, rectified    0.0015      100 %     1     37-40
  by stereo_rig), 95 fr (74 with GT)        (max displacement 4.4 mm; GT path 1.6 cm)
==========================================  ==========  ========  ====  =======

The thresholds below leave a margin of about 3x over these figures.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import pytest

from pytest_sal.analysis.trajectory_errors import ate
from sal_adapters import Camera, FrameRecord, Sequence, open_dataset
from sal_adapters.common.errors import DatasetWarning
from sal_wrappers import RunResult, SlamSystemError, TrackState, create
from sal_wrappers.reference_vo import odometry as vo_odometry
from sal_wrappers.reference_vo.system import ReferenceVO

OK, LOST, NOT_INITIALISED = TrackState.OK, TrackState.LOST, TrackState.NOT_INITIALISED


def run(sequence: Sequence, workdir: Path, timeout: float | None = None, **options) -> RunResult:
    return create("reference_vo", **options).run(sequence, workdir, timeout=timeout)


def ate_rmse(result: RunResult, sequence: Sequence) -> float:
    return ate(result.trajectory, sequence.groundtruth, align="sim3" if result.sensor == "mono" else "se3").rmse


def assert_clean_run(result: RunResult, sequence: Sequence, rate: float = 0.95) -> None:
    assert result.failure is None, result.log_tail
    assert result.system == "reference_vo" and result.scored == "online"
    assert result.frames == len(sequence)
    assert result.tracking_rate >= rate, result.log_tail
    assert result.maps == 1
    traj = result.trajectory
    assert set(np.round(traj.timestamps, 6)) <= set(np.round(sequence.timestamps, 6))
    assert np.allclose(traj.matrices[0], np.eye(4), atol=1e-9)  # the map's first camera frame
    assert result.track_time_s > 0 and result.info["fps"] > 0


def in_memory(sequence: Sequence) -> Sequence:
    """The sequence with its frames decoded once (the runs here share them; VO never writes)."""
    records = []
    for record, frame in zip(sequence.records, sequence):
        decoded = {name: getattr(frame, name) for name in ("image", "right", "depth")}
        sources = {name: None if a is None else (lambda a=a: a) for name, a in decoded.items()}
        records.append(dataclasses.replace(record, **sources))
    return sequence.replace(records=records)


@pytest.fixture(scope="module")
def indoor() -> Sequence:
    return in_memory(open_dataset("synthetic", scene="indoor", frames=100, sensor="rgbd"))


@pytest.fixture(scope="module")
def urban() -> Sequence:
    return in_memory(open_dataset("synthetic", scene="urban", frames=30, sensor="stereo"))


# -- accuracy on the synthetic world --------------------------------------------------------------
@pytest.mark.parametrize(("tracker", "limit"), [("orb", 0.01), ("klt", 0.01)])
def test_indoor_rgbd(indoor: Sequence, tmp_path: Path, tracker: str, limit: float) -> None:
    result = run(indoor, tmp_path, tracker=tracker)
    assert_clean_run(result, indoor, rate=1.0)
    assert result.sensor == "rgbd"
    assert ate_rmse(result, indoor) < limit  # measured 0.0028 m (orb), 0.0018 m (klt)
    lines = [line for line in result.log_path.read_text().splitlines() if not line.startswith("#")]
    assert len(lines) == len(indoor) and lines[0].split()[2] == "ok"  # position timestamp state inliers ms
    assert result.info["tracker"] == tracker and result.info["mode"] == "rgbd"


def test_indoor_mono_sim3(indoor: Sequence, tmp_path: Path) -> None:
    result = run(indoor, tmp_path, mode="mono")
    assert_clean_run(result, indoor)
    assert result.sensor == "mono"
    assert ate_rmse(result, indoor) < 0.05  # measured 0.017 m (Sim3; GT path 1.1 m)


def test_urban_stereo(urban: Sequence, tmp_path: Path) -> None:
    result = run(urban, tmp_path)
    assert_clean_run(result, urban, rate=1.0)
    assert ate_rmse(result, urban) < 0.03  # measured 0.0091 m over 29 m
    # stereo gives metric scale: the path length matches the ground truth's
    assert result.trajectory.path_length() == pytest.approx(urban.groundtruth.path_length(), rel=0.01)


def test_urban_mono_sim3(urban: Sequence, tmp_path: Path) -> None:
    result = run(urban, tmp_path, mode="mono")
    assert_clean_run(result, urban)
    assert ate_rmse(result, urban) < 0.2  # measured 0.063 m over 29 m


# -- real data ------------------------------------------------------------------------------------
def test_kitti_07_mono(shared_data: Path, tmp_path: Path) -> None:
    seq = open_dataset("kitti", shared_data / "kitti" / "sequences" / "07")
    assert len(seq) == 140 and seq.sensor == "mono"
    result = run(seq, tmp_path)
    assert_clean_run(result, seq)
    assert ate_rmse(result, seq) < 1.0  # measured 0.36 m (Sim3) over 78 m


def test_euroc_stereo_tracks_the_almost_static_camera(shared_data: Path, tmp_path: Path) -> None:
    with pytest.warns(DatasetWarning, match="rows skipped"):
        seq = open_dataset("euroc", shared_data / "euroc" / "V1_01_easy_micro", stereo=True)
    assert len(seq) == 95 and seq.camera.right is not None  # raw, distorted pair
    result = run(seq, tmp_path)
    assert_clean_run(result, seq)
    positions = result.trajectory.positions
    assert np.linalg.norm(positions - positions[0], axis=1).max() < 0.03  # measured 4.4 mm (GT: 1.6 cm path)
    assert ate_rmse(result, seq) < 0.01  # measured 1.5 mm on the 74 frames with ground truth


# -- determinism, states, failures ----------------------------------------------------------------
@pytest.mark.parametrize("tracker", ["orb", "klt"])
def test_two_runs_give_identical_results(indoor: Sequence, tmp_path: Path, tracker: str) -> None:
    seq = indoor.select(range(40))
    first = run(seq, tmp_path / "a", tracker=tracker)
    second = run(seq, tmp_path / "b", tracker=tracker)
    assert np.array_equal(first.states, second.states)
    assert np.array_equal(first.trajectory.positions, second.trajectory.positions)
    assert np.array_equal(first.trajectory.quaternions, second.trajectory.quaternions)


def test_mono_runs_are_identical_too(urban: Sequence, tmp_path: Path) -> None:
    seq = urban.select(range(25))  # several keyframes: triangulation and bundle adjustment
    first, second = (run(seq, tmp_path / d, mode="mono") for d in "ab")
    assert first.info["keyframes"] > 3
    assert np.array_equal(first.trajectory.positions, second.trajectory.positions)


def blank(sensor: str, frames: int = 8) -> Sequence:
    camera = Camera(525.0, 525.0, 319.5, 239.5, 640, 480, baseline_m=0.1)
    image = lambda: np.zeros((480, 640, 3), np.uint8)
    depth = lambda: np.full((480, 640), 2.0, np.float32)
    records = [
        FrameRecord(i, i / 30, f"{i:06d}", image, right=image if sensor == "stereo" else None, depth=depth if sensor == "rgbd" else None)
        for i in range(frames)
    ]
    return Sequence(kind="folder", name="black", camera=camera, sensor=sensor, fps=30.0, records=records)


@pytest.mark.parametrize("sensor", ["mono", "stereo", "rgbd"])
def test_blank_frames_track_nothing_without_raising(tmp_path: Path, sensor: str) -> None:
    result = run(blank(sensor), tmp_path)
    assert result.frames == 8 and result.tracked == 0
    assert np.all(result.states == NOT_INITIALISED)
    assert result.trajectory is None and result.maps == 0
    assert result.failure == "no frame was tracked"
    assert RunResult.from_json(result.to_json()).failure == result.failure


def with_black_frames(sequence: Sequence, positions: range) -> Sequence:
    black = lambda: np.zeros((sequence.camera.height, sequence.camera.width, 3), np.uint8)
    records = [dataclasses.replace(r, image=black) if i in positions else r for i, r in enumerate(sequence.records)]
    return sequence.replace(records=records)


def test_lost_frames_then_relocalised_in_the_same_map(indoor: Sequence, tmp_path: Path) -> None:
    seq = with_black_frames(indoor.select(range(40)), range(20, 22))
    result = run(seq, tmp_path)
    assert list(result.states[18:24]) == [OK, OK, LOST, LOST, OK, OK]
    assert result.maps == 1 and result.tracked == 38
    assert ate_rmse(result, seq) < 0.01


def test_max_lost_starts_a_new_map_segment(indoor: Sequence, tmp_path: Path) -> None:
    seq = with_black_frames(indoor.select(range(40)), range(20, 22))
    result = run(seq, tmp_path, max_lost=1)
    assert list(result.states[19:23]) == [OK, LOST, NOT_INITIALISED, OK]  # the map is dropped after one loss
    assert result.maps == 2 and result.info["segments"] == [20, 18]
    assert len(result.trajectory) == 20  # the largest segment is scored
    assert np.array_equal(result.trajectory.timestamps, seq.timestamps[:20])


# -- options, timeout, errors ---------------------------------------------------------------------
def test_registered_with_its_options() -> None:
    system = create("reference_vo")
    assert isinstance(system, ReferenceVO) and system.name == "reference_vo"
    assert system.sensors == ("mono", "stereo", "rgbd")
    assert system.options() == {"features": 1500, "mode": None, "min_inliers": 20, "tracker": "orb", "max_lost": 3}
    assert create("reference_vo", features=800, tracker="klt").options()["features"] == 800


@pytest.mark.parametrize(
    ("options", "words"),
    [
        ({"features": 10}, "features=10"),
        ({"features": "many"}, "100..20000"),
        ({"mode": "thermal"}, "mode='thermal'"),
        ({"min_inliers": 3}, "6..10000"),
        ({"tracker": "sift"}, "orb, klt"),
        ({"max_lost": 0}, "max_lost=0"),
        ({"speed": 2}, "unknown option speed=2"),
    ],
)
def test_bad_option_is_named(options: dict, words: str) -> None:
    with pytest.raises(SlamSystemError, match=words.replace("(", r"\(").replace(".", r"\.")):
        create("reference_vo", **options)


def test_mode_the_sequence_cannot_give(urban: Sequence, tmp_path: Path) -> None:
    with pytest.raises(SlamSystemError, match="cannot run in 'rgbd' mode"):
        run(urban, tmp_path, mode="rgbd")


def test_timeout_stops_the_run_and_is_reported(indoor: Sequence, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    result = run(indoor, tmp_path / "zero", timeout=0)
    assert result.failure == "timed out after 0 s" and result.tracked == 0 and result.trajectory is None
    step = vo_odometry.Odometry.step

    def slow(self, *args):
        time.sleep(0.05)
        return step(self, *args)

    monkeypatch.setattr(vo_odometry.Odometry, "step", slow)
    result = run(indoor, tmp_path / "slow", timeout=0.3)
    assert result.failure == "timed out after 0.3 s"
    assert 0 < result.tracked < 20 and result.frames == len(indoor)
    assert np.all(result.states[result.tracked :] == LOST)  # frames never given a pose
    assert len(result.trajectory) == result.tracked
    assert "timed out" in result.log_path.read_text()


def test_an_exception_inside_becomes_a_failed_result(indoor: Sequence, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def broken(self, *args):
        raise RuntimeError("matcher exploded")

    monkeypatch.setattr(vo_odometry.Odometry, "_keyframe", broken)
    result = run(indoor.select(range(30)), tmp_path)
    assert result.failure is not None and result.failure.startswith("RuntimeError: matcher exploded (frame ")
    assert result.tracked > 0 and result.trajectory is not None  # the frames before it are kept
    assert "matcher exploded" in result.log_path.read_text()
