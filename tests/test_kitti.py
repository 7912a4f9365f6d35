"""KITTI odometry adapter on the real sequence 07 excerpt and on small copies of it."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from sal_adapters import (
    DatasetError,
    DatasetWarning,
    Trajectory,
    open_dataset,
    write_sequence,
)
from sal_adapters.kitti import read_calib


@pytest.fixture(scope="module")
def kitti07(shared_data) -> Path:
    return shared_data / "kitti" / "sequences" / "07"


def make_copy(kitti07: Path, root: Path, frames: int = 4, color: bool = False, stereo: bool = False) -> Path:
    """A small KITTI tree under ``root`` from the first real frames (right = left shifted 8 px)."""
    seq = root / "sequences" / "07"
    left, right = ("image_2", "image_3") if color else ("image_0", "image_1")
    for i in range(frames):
        src = kitti07 / "image_0" / f"{i:06d}.png"
        (seq / left).mkdir(parents=True, exist_ok=True)
        shutil.copy(src, seq / left / src.name)
        if stereo:
            (seq / right).mkdir(parents=True, exist_ok=True)
            shutil.copy(kitti07 / "image_0" / f"{i + 1:06d}.png", seq / right / src.name)
    shutil.copy(kitti07 / "calib.txt", seq / "calib.txt")
    (seq / "times.txt").write_text("".join((kitti07 / "times.txt").read_text().splitlines(True)[:frames]))
    (root / "poses").mkdir(exist_ok=True)
    poses = (kitti07.parent.parent / "poses" / "07.txt").read_text().splitlines(True)
    (root / "poses" / "07.txt").write_text("".join(poses[:frames]))
    return seq


def test_real_sequence_07(kitti07):
    seq = open_dataset("kitti", kitti07)
    assert len(seq) == 140 and seq.sensor == "mono" and seq.grayscale
    assert seq.camera.fx == pytest.approx(707.0912) and seq.camera.cx == pytest.approx(601.8873)
    assert (seq.camera.width, seq.camera.height) == (1226, 370)
    assert len(seq.groundtruth) == 140 and seq.groundtruth_is_per_frame
    np.testing.assert_allclose(seq.timestamps[:2], [0.0, 0.1038752])
    assert seq.fps == pytest.approx(1 / np.median(np.diff(seq.timestamps)))
    image = seq[10].image
    assert image.shape == (370, 1226, 3) and image.dtype == np.uint8
    assert np.array_equal(image[..., 0], image[..., 2])
    # ground truth: the car drives about 78 m forward (+z) in these 14.5 s
    gt = seq.groundtruth
    assert gt.path_length() == pytest.approx(78.36, abs=0.05)
    np.testing.assert_allclose(gt.matrices[0], np.eye(4), atol=1e-9)


def test_root_with_sequence_option_and_window(kitti07):
    seq = open_dataset("kitti", kitti07.parent.parent, sequence=7, start=20, max_frames=30)
    assert len(seq) == 30 and seq[0].index == 20
    assert len(seq.groundtruth) == 30
    np.testing.assert_array_equal(seq.groundtruth.timestamps, seq.timestamps)
    full = open_dataset("kitti", kitti07)
    np.testing.assert_array_equal(seq.groundtruth.positions, full.groundtruth.positions[20:50])


def test_stereo_baseline_from_projection_matrices(kitti07, tmp_path):
    seq = open_dataset("kitti", make_copy(kitti07, tmp_path, stereo=True), stereo=True)
    calib = read_calib(kitti07 / "calib.txt", ["P0", "P1"])
    assert seq.sensor == "stereo"
    assert seq.camera.baseline_m == pytest.approx(-calib["P1"][0, 3] / calib["P1"][0, 0])
    assert seq.camera.baseline_m == pytest.approx(0.5372, abs=1e-4)
    np.testing.assert_allclose(seq.camera.T_lr[:3, 3], [seq.camera.baseline_m, 0, 0], atol=1e-12)
    assert seq[1].right is not None


def test_colour_camera_ground_truth_moves_to_camera_2(kitti07, tmp_path):
    grey = open_dataset("kitti", make_copy(kitti07, tmp_path / "g"))
    colour = open_dataset("kitti", make_copy(kitti07, tmp_path / "c", color=True))
    assert not colour.grayscale
    P2 = read_calib(kitti07 / "calib.txt", ["P2"])["P2"]
    centre_of_cam2_in_cam0 = -np.linalg.solve(P2[:, :3], P2[:, 3])
    expected = grey.groundtruth.matrices[:, :3, :3] @ centre_of_cam2_in_cam0 + grey.groundtruth.positions
    np.testing.assert_allclose(colour.groundtruth.positions, expected, atol=1e-9)
    assert np.linalg.norm(centre_of_cam2_in_cam0) > 0.05


@pytest.mark.parametrize("stereo", [False, True])
def test_write_and_reopen_gives_the_same_sequence(kitti07, tmp_path, stereo):
    seq = open_dataset("kitti", make_copy(kitti07, tmp_path / "src", stereo=stereo), stereo=stereo)
    reopen_path = write_sequence(seq, tmp_path / "out")
    again = open_dataset("kitti", reopen_path, stereo=stereo)
    assert again.camera == seq.camera and again.sensor == seq.sensor and again.grayscale
    np.testing.assert_array_equal(again.timestamps, seq.timestamps)
    assert again.groundtruth.allclose(seq.groundtruth, atol=1e-9)
    for a, b in zip(again, seq):
        assert np.array_equal(a.image, b.image)
        if stereo:
            assert np.array_equal(a.right, b.right)
    assert (reopen_path / "calib.txt").read_text().splitlines()[0].startswith("P0: 7.070912")


def test_dropped_frames_keep_every_file_consistent(kitti07, tmp_path):
    seq = open_dataset("kitti", kitti07, max_frames=12)
    kept = [0, 1, 4, 5, 9, 11]
    path = write_sequence(seq.select(kept), tmp_path / "dropped")
    assert sorted(p.name for p in (path / "image_0").iterdir()) == [f"{i:06d}.png" for i in range(len(kept))]
    assert len((path / "times.txt").read_text().splitlines()) == len(kept)
    assert len((path.parent.parent / "poses" / "07.txt").read_text().splitlines()) == len(kept)
    again = open_dataset("kitti", path)
    np.testing.assert_array_equal(again.timestamps, seq.timestamps[kept])
    np.testing.assert_allclose(again.groundtruth.positions, seq.groundtruth.positions[kept], atol=1e-9)
    assert np.array_equal(again[2].image, seq[4].image)


def test_cross_layout_from_a_non_kitti_source_warns_about_distortion(kitti07, tmp_path):
    seq = open_dataset("kitti", make_copy(kitti07, tmp_path / "src"))
    distorted = seq.replace(kind="folder", camera=type(seq.camera)(**{**seq.camera.__dict__, "distortion": (0.1, 0, 0, 0)}))
    with pytest.warns(DatasetWarning, match="rectified, undistorted"):
        path = write_sequence(distorted, tmp_path / "out", layout="kitti")
    assert open_dataset("kitti", path).camera.fx == pytest.approx(seq.camera.fx)


def test_never_writes_into_the_source(kitti07, tmp_path):
    src = make_copy(kitti07, tmp_path / "src")
    seq = open_dataset("kitti", src)
    for target in (src, src / "inside", tmp_path / "src"):
        with pytest.raises(DatasetError, match="refusing to write into the source dataset folder"):
            write_sequence(seq, target)


def test_output_folder_rules_and_no_half_written_copy(kitti07, tmp_path):
    seq = open_dataset("kitti", make_copy(kitti07, tmp_path / "src"))
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    with pytest.raises(DatasetError, match="not empty and was not written by pytest-sal"):
        write_sequence(seq, foreign)
    out = tmp_path / "out"
    write_sequence(seq, out)
    write_sequence(seq.select([0, 1]), out)  # an earlier output is replaced as a whole
    assert len(open_dataset("kitti", out / "sequences" / "07")) == 2

    def explode():
        raise RuntimeError("killed mid-write")

    broken = seq.replace(records=[seq.records[0], type(seq.records[0])(index=1, timestamp=0.1, stem="x", image=explode)])
    broken = broken.replace(groundtruth=None)
    with pytest.raises(RuntimeError, match="killed mid-write"):
        write_sequence(broken, tmp_path / "killed")
    assert not (tmp_path / "killed").exists()
    assert not [p for p in tmp_path.iterdir() if ".partial-" in p.name]


def test_missing_folder_and_calib(kitti07, tmp_path):
    with pytest.raises(DatasetError, match="kitti dataset folder not found"):
        open_dataset("kitti", tmp_path / "nowhere")
    seq_dir = make_copy(kitti07, tmp_path)
    (seq_dir / "calib.txt").unlink()
    with pytest.raises(DatasetError) as info:
        open_dataset("kitti", seq_dir)
    assert str(info.value) == f"{seq_dir / 'calib.txt'}: file not found"


def test_calib_without_the_needed_matrix(kitti07, tmp_path):
    seq_dir = make_copy(kitti07, tmp_path)
    (seq_dir / "calib.txt").write_text((kitti07 / "calib.txt").read_text().split("\n", 1)[0] + "\n")
    with pytest.raises(DatasetError, match=r"calib.txt: missing projection matrix P1 \(found: P0\)"):
        open_dataset("kitti", seq_dir, stereo=True)


@pytest.mark.parametrize("fx", ["nan", "0", "-707.1", "1e308", "inf"])
def test_a_focal_length_that_is_not_a_camera_is_named_with_its_file_line_and_key(kitti07, tmp_path, fx):
    """fx = nan, 0 or negative used to be a ValueError traceback from Camera; 1e308 was
    accepted (issue 23, item 12)."""
    seq_dir = make_copy(kitti07, tmp_path)
    lines = (kitti07 / "calib.txt").read_text().splitlines()
    fields = lines[0].split()
    fields[1] = fx
    (seq_dir / "calib.txt").write_text("\n".join([" ".join(fields), *lines[1:]]) + "\n")
    with pytest.raises(DatasetError) as info:
        open_dataset("kitti", seq_dir)
    assert str(info.value).startswith(f"{seq_dir / 'calib.txt'}:1: P0: the focal length fx = {float(fx):g} px")
    assert "expected a finite number between 1 and 1e+06 px" in str(info.value)


def test_a_projection_matrix_with_non_finite_values_is_named(kitti07, tmp_path):
    seq_dir = make_copy(kitti07, tmp_path)
    lines = (kitti07 / "calib.txt").read_text().splitlines()
    fields = lines[1].split()
    fields[4] = "nan"  # P1's baseline term
    (seq_dir / "calib.txt").write_text("\n".join([lines[0], " ".join(fields), *lines[2:]]) + "\n")
    with pytest.raises(DatasetError, match=r"calib.txt:2: P1: expected 12 finite numbers"):
        open_dataset("kitti", seq_dir, stereo=True)


def test_malformed_times_line_is_named(kitti07, tmp_path):
    seq_dir = make_copy(kitti07, tmp_path)
    lines = (seq_dir / "times.txt").read_text().splitlines()
    lines[2] = "0.2 oops"
    (seq_dir / "times.txt").write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError) as info:
        open_dataset("kitti", seq_dir)
    assert str(info.value).startswith(f"{seq_dir / 'times.txt'}:3: expected 1 number")


def test_times_and_images_must_agree(kitti07, tmp_path):
    seq_dir = make_copy(kitti07, tmp_path)
    (seq_dir / "image_0" / "000003.png").unlink()
    with pytest.raises(DatasetError, match=r"times.txt: 4 timestamps for 3 images in image_0/"):
        open_dataset("kitti", seq_dir)


def test_unreadable_image_is_named(kitti07, tmp_path):
    seq_dir = make_copy(kitti07, tmp_path)
    (seq_dir / "image_0" / "000002.png").write_bytes(b"not a png")
    seq = open_dataset("kitti", seq_dir)
    with pytest.raises(DatasetError) as info:
        seq[2].image
    assert str(info.value) == f"{seq_dir / 'image_0' / '000002.png'}: cannot decode image (corrupt or not an image)"


def test_ground_truth_with_wrong_column_count(kitti07, tmp_path):
    seq_dir = make_copy(kitti07, tmp_path)
    poses = tmp_path / "poses" / "07.txt"
    lines = poses.read_text().splitlines()
    lines[1] = " ".join(lines[1].split()[:11])
    poses.write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError) as info:
        open_dataset("kitti", seq_dir)
    assert str(info.value).startswith(f"{poses}:2: expected 12 values")
    assert str(info.value).endswith("per line, got 11")


def test_fingerprint_follows_the_files(kitti07, tmp_path):
    seq_dir = make_copy(kitti07, tmp_path)
    first = open_dataset("kitti", seq_dir).fingerprint
    assert open_dataset("kitti", seq_dir).fingerprint == first
    assert open_dataset("kitti", seq_dir, max_frames=3).fingerprint != first
    image = seq_dir / "image_0" / "000001.png"
    image.write_bytes(image.read_bytes() + b"\0")
    assert open_dataset("kitti", seq_dir).fingerprint != first


def test_groundtruth_is_a_trajectory_in_tum_convention(kitti07):
    gt = open_dataset("kitti", kitti07, max_frames=5).groundtruth
    assert isinstance(gt, Trajectory)
    assert gt.quaternions.shape == (5, 4)
