"""Trajectory I/O against evo's own readers on the reference trajectories, and round trips."""

from __future__ import annotations

import numpy as np
import pytest
from evo.tools import file_interface
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from sal_adapters import DatasetError, Trajectory


@pytest.fixture(scope="module")
def evo_data(shared_data):
    return shared_data / "trajectories" / "evo_test_data"


def assert_same_as_evo(ours: Trajectory, theirs) -> None:
    assert len(ours) == theirs.num_poses
    np.testing.assert_allclose(ours.timestamps, theirs.timestamps, rtol=0, atol=1e-6)
    np.testing.assert_allclose(ours.matrices, np.array(theirs.poses_se3), atol=1e-9)


def test_tum_matches_evo(evo_data):
    path = evo_data / "fr2_desk_groundtruth.txt"
    ours = Trajectory.read_tum(path)
    assert_same_as_evo(ours, file_interface.read_tum_trajectory_file(str(path)))


def test_kitti_with_times_matches_evo(evo_data):
    ours = Trajectory.read_kitti(evo_data / "KITTI_00_gt.txt", times=evo_data / "KITTI_00_gt_times.txt")
    theirs = file_interface.read_kitti_poses_file(str(evo_data / "KITTI_00_gt.txt"))
    assert len(ours) == theirs.num_poses == 4541
    np.testing.assert_allclose(ours.matrices, np.array(theirs.poses_se3), atol=1e-6)
    assert ours.timestamps[1] == pytest.approx(0.1037359)


def test_kitti_with_leading_time_column(shared_data):
    ours = Trajectory.read_kitti(shared_data / "trajectories" / "kitti_gt_poses_with_times" / "07.txt")
    plain = Trajectory.read_kitti(shared_data / "kitti" / "poses" / "07.txt")
    assert ours.timestamps[1] == pytest.approx(0.1038752)
    np.testing.assert_allclose(ours.positions[: len(plain)], plain.positions, atol=1e-9)


def test_euroc_matches_evo(evo_data):
    path = evo_data / "V102_groundtruth.csv"
    ours = Trajectory.read_euroc(path)
    assert_same_as_evo(ours, file_interface.read_euroc_csv_trajectory(str(path)))


def test_round_trips_read_back_exactly(evo_data, tmp_path):
    traj = Trajectory.read_tum(evo_data / "fr2_desk_ORB.txt")
    traj.write_tum(tmp_path / "a.txt")
    again = Trajectory.read_tum(tmp_path / "a.txt")
    assert np.array_equal(again.timestamps, traj.timestamps)
    assert np.array_equal(again.positions, traj.positions)

    traj.write_kitti(tmp_path / "k.txt", times_path=tmp_path / "times.txt")
    kitti = Trajectory.read_kitti(tmp_path / "k.txt", times=tmp_path / "times.txt")
    assert np.array_equal(kitti.timestamps, traj.timestamps)
    assert kitti.allclose(traj, atol=1e-9)

    traj.write_euroc(tmp_path / "e.csv")
    assert Trajectory.read_euroc(tmp_path / "e.csv").allclose(traj, atol=1e-9)


def test_evo_alignment_never_touches_our_trajectory(evo_data):
    traj = Trajectory.read_tum(evo_data / "fr2_desk_ORB.txt")
    ref = Trajectory.read_tum(evo_data / "fr2_desk_groundtruth.txt")
    before = traj.positions.copy()
    from evo.core import sync

    ref_evo, est = sync.associate_trajectories(ref.to_evo(), traj.to_evo(), max_diff=0.01)
    est.align(ref_evo, correct_scale=True)
    assert not np.allclose(est.positions_xyz, before[: est.num_poses])
    assert np.array_equal(traj.positions, before)
    assert not traj.positions.flags.writeable
    assert Trajectory.from_evo(traj.to_evo()).allclose(traj)


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.tuples(st.floats(-100, 100), st.floats(-100, 100), st.floats(-100, 100)), min_size=1, max_size=8),
    st.integers(0, 2**31 - 1),
)
def test_matrices_round_trip(positions, seed):
    rotations = Rotation.random(len(positions), random_state=seed).as_matrix()
    poses = np.tile(np.eye(4), (len(positions), 1, 1))
    poses[:, :3, :3] = rotations
    poses[:, :3, 3] = positions
    traj = Trajectory.from_matrices(np.arange(len(positions), dtype=float), poses)
    np.testing.assert_allclose(traj.matrices, poses, atol=1e-9)


def test_transformed_composes_on_the_right_side():
    T = np.eye(4)
    T[:3, 3] = [1.0, 2.0, 3.0]
    offset = np.eye(4)
    offset[:3, :3] = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    offset[:3, 3] = [1.0, 0.0, 0.0]
    traj = Trajectory.from_matrices([0.0], T[None])
    moved = traj.transformed(right=offset)
    # the body-frame offset (1, 0, 0) is applied in the (unrotated) pose frame
    np.testing.assert_allclose(moved.positions[0], [2.0, 2.0, 3.0])


@pytest.mark.parametrize(
    ("content", "reader", "expected"),
    [
        ("0 1 2 3 0 0 0 1\n1 1 2 3 0 0 1\n", "read_tum", "bad.txt:2: expected 8 values"),
        ("# header\n0 1 2 x 0 0 0 1\n", "read_tum", "bad.txt:2: expected numbers, got 'x'"),
        ("1 0 0 0 0 1 0 0 0 0 1\n", "read_kitti", "bad.txt:1: expected 12 or 13 values"),
        ("2 0 0 0 0 2 0 0 0 0 2 0\n", "read_kitti", "determinant"),
        ("#t,x\n100,1,2,3\n", "read_euroc", "bad.txt:2: expected at least 8 comma-separated values"),
        ("", "read_tum", "bad.txt: no values"),
    ],
)
def test_malformed_files_name_file_and_line(tmp_path, content, reader, expected):
    path = tmp_path / "bad.txt"
    path.write_text(content)
    with pytest.raises(DatasetError) as info:
        getattr(Trajectory, reader)(path)
    assert expected in str(info.value)
    assert str(path) in str(info.value)
