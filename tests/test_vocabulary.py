"""The ORB vocabulary builder: DBoW2 text format, determinism, transform, caching, CLI."""

from __future__ import annotations

import math
import os
import threading
from pathlib import Path

import numpy as np
import pytest

from pytest_sal.cli.main import main
from sal_adapters import SalError, open_dataset
from sal_adapters.common import textfiles
from sal_wrappers.orbslam3 import vocabulary as vocab_module
from sal_wrappers.orbslam3.vocabulary import (
    ENV_VARIABLE,
    ensure_vocabulary,
    orb_descriptors,
    orb_image_descriptors,
    sequence_images,
)
from sal_wrappers.orbslam3.vocabulary_training import build_vocabulary
from sal_wrappers.orbslam3.vocabulary_tree import Vocabulary, VocabularyError

THIRD_PARTY = {  # file -> (k, L, nodes, words), see orbslam3_real_data.md section 1
    "ORBvoc_format_kimera_small_k9L3.txt": (9, 3, 781, 692),
    "ORBvoc_format_slambook2_ch11_k10L5.txt": (10, 5, 6162, 4983),
}


@pytest.fixture(scope="module")
def training() -> list[np.ndarray]:
    """ORB descriptors (1000 each) of four indoor views."""
    images = sequence_images(open_dataset("synthetic", scene="indoor", frames=60, seed=0), 4)
    return orb_image_descriptors(images)


@pytest.fixture(scope="module")
def small(training: list[np.ndarray]) -> Vocabulary:
    return build_vocabulary(np.concatenate(training), k=4, levels=3, seed=0, images=training)


@pytest.fixture(scope="module")
def deep(training: list[np.ndarray]) -> Vocabulary:
    """k=10 L=6 on 4000 descriptors: nearly one word per descriptor."""
    return build_vocabulary(np.concatenate(training), k=10, levels=6, seed=0, images=training)


def hamming(a: np.ndarray, b: np.ndarray) -> int:
    return int(np.unpackbits(np.bitwise_xor(a, b)).sum())


def reference_descent(vocabulary: Vocabulary, descriptor: np.ndarray) -> int:
    """Leaf node of one descriptor, the slow way: the first nearest child at every level."""
    children: dict[int, list[int]] = {}
    for node, parent in enumerate(vocabulary.parents.tolist()[1:], start=1):
        children.setdefault(parent, []).append(node)
    node = 0
    while not vocabulary.leaf[node]:
        distances = [hamming(descriptor, vocabulary.descriptors[c]) for c in children[node]]
        node = children[node][int(np.argmin(distances))]
    return node


def check_file(path: Path, k: int, levels: int) -> np.ndarray:
    """Assert the ORB-SLAM3 loader's expectations on a written file; returns its node rows."""
    text = path.read_text(encoding="ascii")
    assert not text.endswith("\n")
    lines = text.split("\n")
    assert lines[0] == f"{k} {levels} 0 0"
    assert all(line.count(" ") == 34 for line in lines[1:])
    rows = np.array(" ".join(lines[1:]).split(), dtype=np.float64).reshape(-1, 35)
    parents = np.concatenate([[-1], rows[:, 0]]).astype(int)
    leaf = np.concatenate([[False], rows[:, 1] == 1])
    weights = np.concatenate([[0.0], rows[:, -1]])
    assert np.all((rows[:, 1] == 0) | (rows[:, 1] == 1))
    assert np.all((rows[:, 2:34] >= 0) & (rows[:, 2:34] <= 255) & (rows[:, 2:34] % 1 == 0))
    ids = np.arange(len(parents))
    assert np.all(parents[1:] < ids[1:]) and np.all(np.diff(parents[1:]) >= 0)  # breadth first
    assert not leaf[parents[1:]].any()  # only inner nodes have children
    has_children = np.isin(ids, parents[1:])
    assert np.array_equal(has_children[1:], ~leaf[1:])
    depth = np.zeros(len(parents), int)
    for _ in range(levels + 1):  # parents first: converges in L rounds
        depth[1:] = depth[parents[1:]] + 1
    assert depth[leaf].min() >= max(1, levels - 4) and depth.max() <= levels
    assert np.all(weights >= 0) and np.all(weights[~leaf] == 0)
    return rows


def test_small_file_format(small: Vocabulary, tmp_path: Path):
    path = small.write_text(tmp_path / "voc.txt")
    rows = check_file(path, 4, 3)
    assert len(rows) == small.n_nodes and np.count_nonzero(rows[:, 1]) == small.n_words
    assert small.n_words > 40 and not any(p.name.endswith(".tmp") for p in tmp_path.iterdir())


@pytest.mark.parametrize(("count", "k", "levels"), [(30, 10, 6), (60, 5, 7), (400, 10, 6)])
def test_every_leaf_is_deep_enough_for_orbslam3(training: list[np.ndarray], tmp_path: Path, count: int, k: int, levels: int):
    # few descriptors -> shallow clusters: they must be extended down to depth L - 4
    vocabulary = build_vocabulary(training[0][:count], k=k, levels=levels, seed=1)
    check_file(vocabulary.write_text(tmp_path / "voc.txt"), k, levels)
    assert vocabulary.depths()[vocabulary.leaf].min() == levels - 4


@pytest.mark.parametrize("name", ["small", "deep"])
def test_idf_weights(name: str, training: list[np.ndarray], request: pytest.FixtureRequest):
    vocabulary: Vocabulary = request.getfixturevalue(name)
    n_w = np.zeros(vocabulary.n_words)
    for descriptors in training:
        n_w[np.unique(vocabulary.transform(descriptors))] += 1
    expected = np.where(n_w > 0, np.log(len(training) / np.maximum(n_w, 1)), 0.0)
    np.testing.assert_allclose(vocabulary.weights[vocabulary.word_nodes()], expected)
    assert np.all(vocabulary.weights[~vocabulary.leaf] == 0)
    # 64 words are in each of the 4 images (IDF 0); nearly every deep word is in one image only
    if name == "deep":
        assert np.mean(vocabulary.weights[vocabulary.leaf] == pytest.approx(math.log(4))) > 0.9


def test_same_seed_same_bytes_other_seed_differs(training: list[np.ndarray], small: Vocabulary, tmp_path: Path):
    descriptors = np.concatenate(training)
    again = build_vocabulary(descriptors, k=4, levels=3, seed=0, images=training)
    other = build_vocabulary(descriptors, k=4, levels=3, seed=1, images=training)
    first = small.write_text(tmp_path / "a.txt").read_bytes()
    assert again.write_text(tmp_path / "b.txt").read_bytes() == first
    assert other.write_text(tmp_path / "c.txt").read_bytes() != first


def test_read_text_round_trip(small: Vocabulary, tmp_path: Path):
    path = small.write_text(tmp_path / "voc.txt")
    back = Vocabulary.read_text(path)
    assert (back.k, back.levels, back.n_nodes, back.n_words) == (4, 3, small.n_nodes, small.n_words)
    for name in ("parents", "leaf", "descriptors"):
        np.testing.assert_array_equal(getattr(back, name), getattr(small, name))
    np.testing.assert_allclose(back.weights, small.weights, rtol=1e-5)
    assert back.to_text() == path.read_text()


@pytest.mark.parametrize("name", sorted(THIRD_PARTY))
def test_reads_third_party_vocabularies(shared_data: Path, name: str):
    path = shared_data / "vocabulary" / name
    vocabulary = Vocabulary.read_text(path)
    assert (vocabulary.k, vocabulary.levels, vocabulary.n_nodes, vocabulary.n_words) == THIRD_PARTY[name]
    original = path.read_text().split("\n")
    written = vocabulary.to_text().split("\n")
    assert original[0].split() == written[0].split() and original[1:] == written[1:]
    rng = np.random.default_rng(0)
    probes = rng.integers(0, 256, (20, 32), dtype=np.uint8)
    assert [vocabulary.word_nodes()[w] for w in vocabulary.transform(probes)] == [reference_descent(vocabulary, p) for p in probes]


def test_transform_takes_the_nearest_child_at_every_level(small: Vocabulary, training: list[np.ndarray]):
    rng = np.random.default_rng(3)
    probes = np.concatenate([rng.integers(0, 256, (15, 32), dtype=np.uint8), training[1][:15]])
    words = small.transform(probes)
    assert words.dtype.kind == "i" and words.min() >= 0 and words.max() < small.n_words
    assert small.word_nodes()[words].tolist() == [reference_descent(small, p) for p in probes]


def test_training_descriptors_find_their_own_leaf(deep: Vocabulary, training: list[np.ndarray]):
    # a node with <= k distinct descriptors gets one leaf per descriptor, and converged
    # k-majority keeps every training descriptor on its training path
    descriptors = np.concatenate(training)
    leaves = deep.leaf_nodes(descriptors)
    own = np.all(deep.descriptors[leaves] == descriptors, axis=1)
    shallow = deep.depths()[leaves] < deep.levels  # not a centroid leaf of the last level
    assert own[shallow].all() and own.mean() > 0.9


def test_transform_rejects_other_descriptors(small: Vocabulary):
    with pytest.raises(VocabularyError, match="N x 32 uint8"):
        small.transform(np.zeros((3, 64), np.uint8))


def test_orb_descriptors(training: list[np.ndarray]):
    image = sequence_images(open_dataset("synthetic", scene="indoor", frames=60, seed=0), 1)[0]
    descriptors = orb_descriptors([image, image[..., 0]], features=500)
    assert descriptors.dtype == np.uint8 and descriptors.shape == (1000, 32)
    assert orb_descriptors([]).shape == (0, 32)
    assert all(d.shape == (1000, 32) for d in training)


@pytest.mark.parametrize(
    ("descriptors", "options", "message"),
    [
        (np.zeros((10, 31), np.uint8), {}, "N x 32 uint8"),
        (np.zeros((10, 32), np.float32), {}, "N x 32 uint8"),
        (np.zeros((0, 32), np.uint8), {}, "N >= 1, got none"),
        (np.zeros((10, 32), np.uint8), {"k": 21}, "k must be 2..20"),
        (np.zeros((10, 32), np.uint8), {"levels": 0}, "levels 1..10"),
    ],
)
def test_build_rejects_bad_input(descriptors: np.ndarray, options: dict, message: str):
    with pytest.raises(VocabularyError, match=message):
        build_vocabulary(descriptors, **options)


def test_identical_descriptors_give_one_chain(tmp_path: Path):
    vocabulary = build_vocabulary(np.full((50, 32), 7, np.uint8), k=10, levels=6)
    assert (vocabulary.n_nodes, vocabulary.n_words) == (2, 1)  # root -> inner -> leaf at depth 2
    check_file(vocabulary.write_text(tmp_path / "v.txt"), 10, 6)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("10 6", "expected 'k L scoring weighting'"),
        ("30 6 0 0\n0 1" + " 0" * 33, "header out of range"),
        ("4 3 0 0\n0 0" + " 1" * 33 + "\n1 1 5 0", "expected 35 fields per node, got 4"),
        ("4 3 0 0\n0 1" + " 1" * 33 + "\n1 1" + " 0" * 33, "parent 1 is not an inner node"),
        ("4 3 0 0\n0 0" + " 1" * 33, "inner node 1 has no children"),
        ("4 3 0 0\n0 1" + " 1" * 32 + " x", "expected numbers, got '0 1 1"),
    ],
)
def test_read_text_errors_name_file_and_line(tmp_path: Path, text: str, message: str):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(VocabularyError, match=message) as info:
        Vocabulary.read_text(path)
    assert str(info.value).startswith(str(path))
    with pytest.raises(VocabularyError, match="not found"):
        Vocabulary.read_text(tmp_path / "missing.txt")


def test_read_text_accepts_a_trailing_newline(small: Vocabulary, tmp_path: Path):
    path = tmp_path / "dbow2.txt"
    path.write_text(small.to_text() + "\n")  # DBoW2's saveToTextFile ends with one
    assert Vocabulary.read_text(path).n_nodes == small.n_nodes


def test_ensure_vocabulary_honours_the_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    given = tmp_path / "mine.txt"
    given.write_text("10 6 0 0")
    monkeypatch.setenv(ENV_VARIABLE, str(given))
    assert ensure_vocabulary(cache_dir=tmp_path / "cache") == given
    monkeypatch.setenv(ENV_VARIABLE, str(tmp_path / "nothing.txt"))
    with pytest.raises(SalError, match=ENV_VARIABLE):
        ensure_vocabulary(cache_dir=tmp_path / "cache")


def test_ensure_vocabulary_uses_an_official_orbvoc_in_the_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.delenv(ENV_VARIABLE, raising=False)
    (tmp_path / "ORBvoc.txt").write_text("10 6  0 0")
    assert ensure_vocabulary(cache_dir=tmp_path) == tmp_path / "ORBvoc.txt"


@pytest.fixture
def noise_views(monkeypatch: pytest.MonkeyPatch) -> None:
    """ensure_vocabulary trains on two noise images instead of rendering the world."""
    rng = np.random.default_rng(5)
    views = [rng.integers(0, 256, (240, 320, 3), dtype=np.uint8) for _ in range(2)]
    monkeypatch.setattr(vocab_module, "synthetic_training_images", lambda seed, frames, progress: views)
    monkeypatch.delenv(ENV_VARIABLE, raising=False)


@pytest.mark.usefixtures("noise_views")
def test_ensure_vocabulary_builds_once_even_when_called_concurrently(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    builds = []

    def counting_build(*args, **kwargs):
        builds.append(args[1:3])
        return build_vocabulary(*args, **kwargs)

    monkeypatch.setattr(vocab_module, "build_vocabulary", counting_build)
    found: list[Path] = []
    threads = [
        threading.Thread(target=lambda: found.append(ensure_vocabulary(cache_dir=tmp_path, k=4, levels=3, frames=1))) for _ in range(3)
    ]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert builds == [(4, 3)] and len(set(found)) == 1 and len(found) == 3
    path = found[0]
    assert path.parent == tmp_path and "k4-L3-s0" in path.name
    check_file(path, 4, 3)
    stamp = path.stat().st_mtime_ns
    assert ensure_vocabulary(cache_dir=tmp_path, k=4, levels=3, frames=1) == path
    assert builds == [(4, 3)] and path.stat().st_mtime_ns == stamp
    assert ensure_vocabulary(cache_dir=tmp_path, k=4, levels=3, frames=1, seed=1) != path
    assert len(builds) == 2


@pytest.mark.usefixtures("noise_views")
def test_a_killed_build_leaves_no_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    def killed(*_: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(textfiles.os, "replace", killed)  # dies after writing the temporary file
    with pytest.raises(KeyboardInterrupt):
        ensure_vocabulary(cache_dir=tmp_path, k=4, levels=3, frames=1)
    assert [p.name for p in tmp_path.iterdir() if not p.name.endswith(".lock")] == []


def test_default_vocabulary(orb_vocabulary: Path):
    vocabulary = Vocabulary.read_text(orb_vocabulary)
    assert (vocabulary.k, vocabulary.levels) == (10, 6) and vocabulary.n_words > 20000
    if os.environ.get(ENV_VARIABLE):
        return  # the user's own file
    check_file(orb_vocabulary, 10, 6)
    assert np.count_nonzero(vocabulary.weights[vocabulary.leaf] > 0) > 0.9 * vocabulary.n_words
    assert ensure_vocabulary(cache_dir=orb_vocabulary.parent) == orb_vocabulary


def test_cli_builds_a_vocabulary(tmp_path: Path, capsys: pytest.CaptureFixture[str], shared_data: Path):
    out = tmp_path / "voc.txt"
    kitti = shared_data / "kitti" / "sequences" / "07"
    argv = [
        "vocab",
        "build",
        "--from",
        "synthetic",
        "--from",
        f"kitti:{kitti}",
        "--frames",
        "2",
        "--k",
        "5",
        "--levels",
        "3",
        "-o",
        str(out),
    ]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    for key in ("descriptors  6000 from 6 images", "nodes", "words", "time", "file"):
        assert key in printed
    check_file(out, 5, 3)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--from", "kitti"], "needs a folder"),
        (["--from", "nosuch:/x"], "unknown dataset kind 'nosuch'"),
        (["--k", "1"], "k must be 2..20"),
        (["--from", "kitti:/no/such/folder"], "/no/such/folder"),
    ],
)
def test_cli_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str):
    assert main(["vocab", "build", *argv, "-o", str(tmp_path / "v.txt")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("sal: error:") and message in err[0]
