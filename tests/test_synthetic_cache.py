"""The synthetic world's render cache and layout: frames rendered on access, cached and read back,
concurrent renders, the cache folder opened as a dataset, round trips of every sensor and of
foreign sequences, and bad options and malformed folders named."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import numpy as np
import pytest

from sal_adapters import (
    Camera,
    DatasetError,
    FrameRecord,
    Sequence,
    Trajectory,
    open_dataset,
    write_sequence,
)
from sal_adapters.synthetic import RENDERER_VERSION, WORLDS
from sal_adapters.synthetic.cache import FrameStore
from sal_adapters.synthetic.world import World


# -- lazy rendering and the cache -------------------------------------------------------------------
def test_open_renders_nothing_and_access_renders_one_frame(tmp_path: Path) -> None:
    seq = open_dataset("synthetic", scene="indoor", frames=5, cache_dir=tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["groundtruth.txt", "sequence.json", "times.txt"]
    assert seq.source == tmp_path and seq.fingerprint  # fingerprint needs no frame file
    assert seq[1].image.shape == (480, 640, 3)
    files = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*") if p.is_file())
    assert files == ["depth/000001.npy", "groundtruth.txt", "image_left/000001.png", "sequence.json", "times.txt"]


def test_cached_frames_are_read_back_not_rendered_again(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seq = open_dataset("synthetic", scene="urban", frames=4, sensor="stereo", cache_dir=tmp_path)
    calls: list[tuple[int, bool]] = []
    render = World.render

    def counting(self: World, index: int, right: bool = False):
        calls.append((index, right))
        return render(self, index, right)

    monkeypatch.setattr(World, "render", counting)
    first, first_right = seq[2].image, seq[2].right
    assert calls == [(2, False), (2, True)] and (tmp_path / "image_right" / "000002.png").is_file()
    again = open_dataset("synthetic", scene="urban", frames=4, sensor="rgbd", cache_dir=tmp_path)[2]
    assert np.array_equal(again.image, first) and again.depth is not None
    assert np.array_equal(seq[2].right, first_right)
    assert calls == [(2, False), (2, True)]


def test_concurrent_renders_of_one_frame_are_harmless(tmp_path: Path) -> None:
    store = FrameStore(WORLDS["indoor"](0), tmp_path)
    results: list[np.ndarray] = []
    threads = [threading.Thread(target=lambda: results.append(store.left(3))) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(results) == 4 and all(np.array_equal(r, results[0]) for r in results)
    assert np.array_equal(store.left(3), results[0])
    assert not list(tmp_path.rglob(".*"))  # no temporary file left behind


def test_render_cache_folder_opens_as_a_dataset(tmp_path: Path) -> None:
    seq = open_dataset("synthetic", scene="indoor", frames=4, seed=2, cache_dir=tmp_path)
    image = seq[3].image
    again = open_dataset("synthetic", tmp_path)
    assert len(again) == 4 and again.sensor == "rgbd" and again.meta == seq.meta
    assert np.array_equal(again[3].image, image) and again.groundtruth.allclose(seq.groundtruth, atol=0.0)
    assert again.content_key == seq.content_key and again.fingerprint == seq.fingerprint
    open_dataset("synthetic", scene="indoor", frames=6, seed=2, cache_dir=tmp_path)
    assert len(open_dataset("synthetic", tmp_path, sensor="mono")) == 6
    info = json.loads((tmp_path / "sequence.json").read_text())
    assert (info["scene"], info["seed"], info["renderer_version"], info["cache"]) == ("indoor", 2, RENDERER_VERSION, True)
    (tmp_path / "sequence.json").write_text(json.dumps({**info, "renderer_version": RENDERER_VERSION - 1}))
    with pytest.raises(DatasetError, match="renderer version"):
        open_dataset("synthetic", tmp_path)  # frames of an older look are not mixed with new ones


def test_cache_folder_of_another_world_is_refused(tmp_path: Path) -> None:
    open_dataset("synthetic", scene="indoor", frames=2, seed=1, cache_dir=tmp_path)
    with pytest.raises(DatasetError, match="seed=1"):
        open_dataset("synthetic", scene="indoor", frames=2, seed=2, cache_dir=tmp_path)


def test_writing_into_the_render_cache_is_refused() -> None:
    seq = open_dataset("synthetic", scene="indoor", frames=2)
    with pytest.raises(DatasetError, match="source"):
        write_sequence(seq, seq.source / "copy")


# -- the layout: write and read back ----------------------------------------------------------------
def assert_same(copy: Sequence, original: Sequence) -> None:
    assert copy.kind == "synthetic" and len(copy) == len(original)
    assert (copy.sensor, copy.fps, copy.camera) == (original.sensor, original.fps, original.camera)
    assert [r.stem for r in copy.records] == [r.stem for r in original.records]
    assert np.array_equal(copy.indices, original.indices) and np.array_equal(copy.timestamps, original.timestamps)
    assert copy.groundtruth.allclose(original.groundtruth, atol=1e-12)
    for a, b in zip(copy, original):
        assert np.array_equal(a.image, b.image)
        assert (a.right is None) == (b.right is None) and (a.right is None or np.array_equal(a.right, b.right))
        assert (a.depth is None) == (b.depth is None) and (a.depth is None or np.array_equal(a.depth, b.depth))


@pytest.mark.parametrize("sensor", ["mono", "stereo", "rgbd"])
def test_round_trip_of_every_sensor(tmp_path: Path, sensor: str) -> None:
    seq = open_dataset("synthetic", scene="indoor", frames=3, sensor=sensor)
    copy = open_dataset("synthetic", write_sequence(seq, tmp_path / "copy"))
    assert_same(copy, seq)
    assert copy.meta == seq.meta and copy.name == seq.name
    assert (tmp_path / "copy" / "image_right").is_dir() == (sensor == "stereo")
    assert (tmp_path / "copy" / "depth").is_dir()


def test_round_trip_keeps_dropped_frames_and_their_indices(tmp_path: Path) -> None:
    seq = open_dataset("synthetic", scene="urban", frames=6).select([0, 2, 5])
    copy = open_dataset("synthetic", write_sequence(seq, tmp_path / "copy"))
    assert_same(copy, seq)
    assert list(copy.indices) == [0, 2, 5] and [r.stem for r in copy.records] == ["000000", "000002", "000005"]


def test_round_trip_of_a_foreign_sequence(tmp_path: Path) -> None:
    """Any sequence: odd stems, integer ns times, ground truth at another rate, mixed streams."""
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (8, 10, 3), dtype=np.uint8) for _ in range(3)]
    depths = [rng.uniform(0.5, 4, (8, 10)).astype(np.float32), None, rng.uniform(0.5, 4, (8, 10)).astype(np.float32)]
    records = [
        FrameRecord(
            index=10 + 3 * k,
            timestamp=1403715274.1 + 0.05 * k,
            stem=f"cam-{k}",
            image=lambda k=k: images[k],
            depth=None if depths[k] is None else (lambda k=k: depths[k]),
            timestamp_ns=1403715274100000000 + 50000000 * k,
        )
        for k in range(3)
    ]
    t = np.linspace(1403715274.0, 1403715274.3, 31)
    gt = Trajectory(t, np.c_[t - t[0], np.zeros(31), np.zeros(31)], np.tile([0, 0, 0, 1.0], (31, 1)))
    seq = Sequence(
        kind="custom", name="custom/x", camera=Camera(20.0, 20.0, 5.0, 4.0, 10, 8), sensor="mono", fps=20.0, records=records, groundtruth=gt
    )
    copy = open_dataset("synthetic", write_sequence(seq, tmp_path / "copy", layout="synthetic"))
    assert_same(copy, seq)
    assert [r.timestamp_ns for r in copy.records] == [r.timestamp_ns for r in records]


@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("scene", "mars"),
        ("frames", 0),
        ("frames", -3),
        ("frames", 2.5),
        ("frames", "many"),
        ("seed", -1),
        ("seed", True),
        ("sensor", "lidar"),
    ],
)
def test_bad_option_values_name_the_option(option: str, value: object) -> None:
    with pytest.raises(DatasetError) as error:
        open_dataset("synthetic", **{option: value})
    assert option in str(error.value) and repr(value) in str(error.value)
    assert "use" in str(error.value)


def test_malformed_folders_name_the_file(tmp_path: Path) -> None:
    seq = open_dataset("synthetic", scene="indoor", frames=3, sensor="mono")
    folder = write_sequence(seq, tmp_path / "copy")
    with pytest.raises(DatasetError, match=r"image_right.000000\.png"):
        open_dataset("synthetic", folder, sensor="stereo")
    times = folder / "times.txt"
    lines = times.read_text().splitlines()
    times.write_text("\n".join([*lines[:2], "000001 one 0.1", *lines[3:]]) + "\n")
    with pytest.raises(DatasetError, match=r"times\.txt:3"):
        open_dataset("synthetic", folder)
    times.write_text("\n".join(lines) + "\n")
    (folder / "image_left" / "000002.png").unlink()
    with pytest.raises(DatasetError, match=r"image_left.000002\.png"):
        open_dataset("synthetic", folder)
    (folder / "sequence.json").write_text("{not json")
    with pytest.raises(DatasetError, match=r"sequence\.json"):
        open_dataset("synthetic", folder)
    with pytest.raises(DatasetError, match=r"sequence\.json not found"):
        open_dataset("synthetic", tmp_path)
