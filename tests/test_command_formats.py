"""The ``command`` system reads back each trajectory format the fake SLAM program writes (TUM,
KITTI, JSON; dropped frames, partial poses, keyframe trajectories, time units) and the tracking
states that follow from it."""

from __future__ import annotations

import numpy as np
import pytest
from command_programs import LOST, NI, OK, assert_states, expected, fake

from sal_wrappers import RunResult, create

#: the shared fixtures (indoor, scripts, short, urban)
pytest_plugins = ["command_programs"]


# -- each output format reads back what the program wrote --------------------------------------------
@pytest.mark.parametrize(
    ("fmt", "options", "extra"),
    [
        ("tum", {"output_format": "tum", "layout": "tum"}, []),
        ("tum-ns", {"output_format": "tum", "time_unit": "ns", "layout": "tum"}, []),
        ("euroc", {"output_format": "euroc", "layout": "tum"}, []),
        ("json-matrix", {"output_format": "json"}, []),  # default layout: the synthetic one
        ("json-quat", {"output_format": "json", "layout": "tum"}, []),
    ],
)
def test_formats_read_back(scripts, short, tmp_path, fmt, options, extra):
    system = create("command", argv=fake(scripts, "--format", fmt, *extra), sensor="mono", **options)
    result = system.run(short, tmp_path / "w", timeout=60)
    assert result.ok, (result.failure, result.log_tail)
    assert result.exit_status == 0 and result.maps == 1 and result.tracking_rate == 1.0
    assert result.trajectory.allclose(expected(short, list(range(6))), atol=1e-6)
    assert result.final_trajectory is not None and len(result.final_trajectory) == 6
    assert result.scored == "final" and result.sensor == "mono"
    assert result.info["output_format"] == options["output_format"]
    assert result.info["staged"] in result.info["argv"]
    assert RunResult.from_json(result.to_json()).trajectory.allclose(result.trajectory)


@pytest.mark.parametrize(
    ("fmt", "extra", "positions"),
    [
        ("kitti13", [], list(range(10))),
        ("kitti12", [], list(range(10))),  # no times: one pose per frame given
        ("kitti12", ["--first", "3", "--times-out", "{output_times}"], list(range(3, 10))),
    ],
)
def test_kitti_formats(scripts, urban, tmp_path, fmt, extra, positions):
    system = create("command", argv=fake(scripts, "--gt", "kitti", "--format", fmt, *extra), output_format="kitti", layout="kitti")
    result = system.run(urban, tmp_path / "w", timeout=60)
    assert result.ok, (result.failure, result.log_tail)
    assert result.info["staged"].endswith("sequences/00")
    assert result.trajectory.allclose(expected(urban, positions), atol=1e-6)
    assert result.tracked == len(positions)


def test_kitti_without_times_for_part_of_the_frames_is_unparsable(scripts, urban, tmp_path):
    system = create(
        "command", argv=fake(scripts, "--gt", "kitti", "--format", "kitti12", "--first", "3"), output_format="kitti", layout="kitti"
    )
    result = system.run(urban, tmp_path / "w", timeout=60)
    assert not result.ok and result.exit_status == 0
    assert "unparsable output" in result.failure and "7 poses" in result.failure and "{output_times}" in result.failure
    assert result.tracked == 0 and result.trajectory is None


def test_dropped_frames_keep_their_times(scripts, urban, tmp_path):
    kept = [0, 1, 2, 5, 6, 8, 9]
    dropped = urban.select(kept)
    system = create("command", argv=fake(scripts, "--gt", "kitti", "--format", "kitti12"), output_format="kitti", layout="kitti")
    result = system.run(dropped, tmp_path / "w", timeout=60)
    assert result.ok, result.failure
    np.testing.assert_allclose(result.timestamps, urban.timestamps[kept])
    gt = dropped.groundtruth
    assert np.allclose(result.trajectory.positions[:, 1:], gt.positions[:, 1:]) and result.tracking_rate == 1.0


# -- tracking states ---------------------------------------------------------------------------------
def test_poses_for_part_of_the_frames(scripts, indoor, tmp_path):
    system = create("command", argv=fake(scripts, "--first", "5", "--stop", "15", "--skip", "9,10"), sensor="mono", layout="tum")
    result = system.run(indoor, tmp_path / "w", timeout=60)
    assert result.ok
    assert_states(result, [NI] * 5 + [OK] * 4 + [LOST] * 2 + [OK] * 4 + [LOST] * 5)
    assert result.tracked == 8 and result.tracking_rate == pytest.approx(0.4) and result.first_tracked == 5
    assert result.trajectory.allclose(expected(indoor, [5, 6, 7, 8, 11, 12, 13, 14]), atol=1e-6)


def test_keyframe_trajectory(scripts, indoor, tmp_path):
    system = create("command", argv=fake(scripts, "--first", "2", "--every", "4"), keyframes=True, sensor="mono", layout="tum")
    result = system.run(indoor, tmp_path / "w", timeout=60)
    assert result.ok
    assert_states(result, [NI] * 2 + [OK] * 17 + [LOST])  # keyframes at 2, 6, 10, 14, 18
    assert len(result.trajectory) == 5


def test_wrong_time_unit_matches_no_frame(scripts, short, tmp_path):
    system = create("command", argv=fake(scripts, "--format", "tum-ns", "--first", "1"), sensor="mono", layout="tum")
    result = system.run(short, tmp_path / "w", timeout=60)
    assert not result.ok and result.maps == 0 and result.trajectory is None
    assert result.failure.startswith("none of the 5 poses")
    assert "time_unit" in result.failure
