"""The frame_drop module: drop sets nested across rates, the binomial tolerance, periodic drops,
the search unit, and dropped frames' round trip through the writer and reader of every dataset
kind."""

from __future__ import annotations

import shutil
import warnings
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from sal_adapters import (
    DatasetWarning,
    Sequence,
    open_dataset,
    write_sequence,
)
from sal_modules import (
    ParameterError,
    create,
    perturb,
)
from sal_modules.transport.frame_drop import FrameDrop

#: the shared fixtures (kitti, urban)
pytest_plugins = ["transport_sequences"]


# -- frame_drop ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def long_street() -> Sequence:
    """2000 frames; frame_drop decides from the index alone, so no image is rendered."""
    return open_dataset("synthetic", scene="urban", frames=2000, sensor="mono")


def dropped(sequence: Sequence, seed: int = 7, **params: Any) -> set[int]:
    return set(sequence.indices.tolist()) - set(perturb(sequence, create("frame_drop", **params), seed=seed).indices.tolist())


def test_frame_drop_sets_are_nested_across_rates(long_street: Sequence) -> None:
    low, mid, high = (dropped(long_street, drop_rate=rate) for rate in (0.1, 0.3, 0.6))
    assert low < mid < high
    assert dropped(long_street, seed=8, drop_rate=0.3) != mid


@pytest.mark.parametrize("rate", [0.05, 0.3, 0.6])
def test_frame_drop_rate_within_binomial_tolerance(long_street: Sequence, rate: float) -> None:
    n = len(long_street)
    count = len(dropped(long_street, drop_rate=rate))
    assert abs(count - n * rate) <= 4 * np.sqrt(n * rate * (1 - rate)), (count, n * rate)


def test_frame_drop_periodic_drops_exactly_every_period_th_frame(long_street: Sequence) -> None:
    assert dropped(long_street, mode="periodic", period=7) == set(range(6, 2000, 7))
    assert dropped(long_street, mode="periodic", period=1) == set(range(2000))


def test_frame_drop_is_searched_in_its_own_unit_a_share_of_the_frames() -> None:
    # one unit for drop_rate in create(), YAML, the DSL and reports: a share 0 .. 1
    scale = FrameDrop.drop_rate.search_space()
    assert (scale.domain, scale.min, scale.max, scale.unit, scale.scale) == ("continuous", 0.0, 1.0, "", "linear")
    assert create("frame_drop", drop_rate=0.3).drop_rate == 0.3
    assert FrameDrop.drop_rate.worse == "higher"
    with pytest.raises(ParameterError, match="drop_rate"):
        create("frame_drop", drop_rate=1.5)


def tum_fr1_xyz(shared_data: Path, root: Path, frames: int = 30) -> Path:
    """The first rows of the real fr1_xyz lists, with small placeholder images."""
    src = shared_data / "trajectories" / "tum_fr1_xyz_txt"
    folder = root / "rgbd_dataset_freiburg1_xyz"
    for sub in ("rgb", "depth"):
        (folder / sub).mkdir(parents=True)
    for name, rows in (("rgb.txt", frames), ("depth.txt", frames), ("groundtruth.txt", 10 * frames)):
        lines = (src / name).read_text().splitlines(True)
        (folder / name).write_text("".join(lines[: 3 + rows]))
    rng = np.random.default_rng(1)
    for name, depth in (("rgb.txt", False), ("depth.txt", True)):
        for line in (folder / name).read_text().splitlines()[3:]:
            image = np.full((6, 8), 5000, np.uint16) if depth else rng.integers(0, 256, (6, 8, 3), dtype=np.uint8)
            assert cv2.imwrite(str(folder / line.split()[1]), image)
    return folder


def open_kind(kind: str, shared_data: Path, root: Path) -> Sequence:
    if kind == "kitti":
        return open_dataset("kitti", shared_data / "kitti" / "sequences" / "07", max_frames=12)
    if kind == "tum":
        with pytest.warns(DatasetWarning, match="have no depth map"):
            return open_dataset("tum", tum_fr1_xyz(shared_data, root))
    if kind == "euroc":
        with pytest.warns(DatasetWarning, match=r"cam1/data\.csv: .* rows skipped"):
            return open_dataset("euroc", shared_data / "euroc" / "V1_01_easy_micro", stereo=True, start=20, max_frames=16)
    if kind == "folder":
        copy = root / "fr3"
        shutil.copytree(shared_data / "tum_rgbd_samples" / "fr3_long_office_household_4frames_pyslam", copy)
        return open_dataset("folder", copy, intrinsics=(535.4, 539.2, 320.1, 247.6))
    return open_dataset("synthetic", scene="indoor", frames=10)


@pytest.mark.parametrize("kind", ["kitti", "tum", "euroc", "folder", "synthetic"])
def test_dropped_frames_vanish_from_every_dataset_layout(kind: str, shared_data: Path, tmp_path: Path) -> None:
    clean = open_kind(kind, shared_data, tmp_path)
    out = perturb(clean, create("frame_drop", mode="periodic", period=2), seed=1)
    positions = [p for p, index in enumerate(clean.indices) if (index + 1) % 2 != 0]
    assert list(out.indices) == [clean.records[p].index for p in positions] and 0 < len(out) < len(clean)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the written copy reopens without complaint
        back = open_dataset(kind, write_sequence(out, tmp_path / "out"), **({"stereo": True} if clean.sensor == "stereo" else {}))
    assert len(back) == len(positions) and back.sensor == clean.sensor
    np.testing.assert_array_equal(back.timestamps, clean.timestamps[positions])
    for frame, p in zip(back, positions):
        np.testing.assert_array_equal(frame.image, clean[p].image)
        if clean.sensor == "stereo":
            np.testing.assert_array_equal(frame.right, clean[p].right)
        if clean.sensor == "rgbd":
            np.testing.assert_array_equal(frame.depth, clean[p].depth)
    if clean.groundtruth_is_per_frame:
        assert back.groundtruth_is_per_frame
        np.testing.assert_allclose(back.groundtruth.positions, clean.groundtruth.positions[positions], atol=1e-9)
    elif clean.groundtruth is not None:  # a trajectory at its own rate is kept whole
        assert back.groundtruth.allclose(clean.groundtruth, atol=1e-9)


def test_random_drops_keep_the_frame_rate_of_a_reopened_copy(shared_data: Path, tmp_path: Path) -> None:
    """KITTI stores no rate: it is measured from times.txt, and the gaps left by dropped
    frames must not lower it (a SLAM config or a later bandwidth step reads it)."""
    clean = open_dataset("kitti", shared_data / "kitti" / "sequences" / "07", max_frames=60)
    out = perturb(clean, create("frame_drop", drop_rate=0.6), seed=2)
    back = open_dataset("kitti", write_sequence(out, tmp_path / "out"))
    assert len(back) < len(clean) and back.fps == pytest.approx(clean.fps, rel=0.01)
