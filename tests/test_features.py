"""Feature-tracking diagnostics: ORB on the synthetic world, SuperPoint through a tiny ONNX model."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper, numpy_helper

import sal_modules
from pytest_sal.analysis.feature_tracking import (
    OrbExtractor,
    SuperPointExtractor,
    TrackingStats,
    compare_features,
    create_extractor,
    parse_features,
    track_features,
)
from pytest_sal.analysis.superpoint import decode_superpoint
from sal_adapters import open_dataset
from sal_adapters.common.errors import SalError

GAIN = 10.0  # detector logit per unit brightness of a pixel
DUSTBIN = 5.0  # "no keypoint" logit


# -- a tiny SuperPoint-shaped ONNX model -------------------------------------------------------
def superpoint_model(
    path: Path, descriptor_dim: int = 16, semi_channels: int = 65, names: tuple[str, str, str] = ("image", "semi", "desc")
) -> Path:
    """Input ``1 x 1 x H x W``; ``semi``: an 8x8 stride-8 conv whose channel c (< 64) reads pixel
    (c // 8, c % 8) of its cell times ``GAIN`` (so a bright pixel wins its cell) and whose
    dustbin is a constant ``DUSTBIN``; ``desc``: a fixed random 8x8 stride-8 conv."""
    rng = np.random.default_rng(7)
    w_semi = np.zeros((semi_channels, 1, 8, 8), np.float32)
    for c in range(min(64, semi_channels)):
        w_semi[c, 0, c // 8, c % 8] = GAIN
    b_semi = np.zeros(semi_channels, np.float32)
    b_semi[-1] = DUSTBIN
    w_desc = rng.normal(size=(descriptor_dim, 1, 8, 8)).astype(np.float32)
    b_desc = np.zeros(descriptor_dim, np.float32)
    image, semi, desc = names
    nodes = [
        helper.make_node("Conv", [image, "w_semi", "b_semi"], [semi], kernel_shape=[8, 8], strides=[8, 8]),
        helper.make_node("Conv", [image, "w_desc", "b_desc"], [desc], kernel_shape=[8, 8], strides=[8, 8]),
    ]
    inits = [numpy_helper.from_array(a, n) for n, a in [("w_semi", w_semi), ("b_semi", b_semi), ("w_desc", w_desc), ("b_desc", b_desc)]]
    graph = helper.make_graph(
        nodes,
        "tiny_superpoint",
        [helper.make_tensor_value_info(image, TensorProto.FLOAT, [1, 1, "H", "W"])],
        # descriptor output first: the extractor must tell them apart by shape, not order
        [
            helper.make_tensor_value_info(desc, TensorProto.FLOAT, [1, descriptor_dim, "h", "w"]),
            helper.make_tensor_value_info(semi, TensorProto.FLOAT, [1, semi_channels, "h", "w"]),
        ],
        initializer=inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 10
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


def blob_image(shape: tuple[int, int], centres: np.ndarray, amplitudes: np.ndarray, sigma: float = 1.0) -> np.ndarray:
    """Dark float image in [0, 1] with a Gaussian spot at each (x, y) centre."""
    yy, xx = np.mgrid[: shape[0], : shape[1]].astype(np.float32)
    image = np.zeros(shape, np.float32)
    for (x, y), a in zip(centres, amplitudes):
        image += a * np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * sigma**2))
    return np.clip(image, 0, 1)


def random_blobs(shape: tuple[int, int], count: int, margin: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    centres: list[tuple[int, int]] = []
    while len(centres) < count:
        c = (int(rng.integers(margin, shape[1] - margin)), int(rng.integers(margin, shape[0] - margin)))
        if all(np.hypot(c[0] - x, c[1] - y) >= 14 for x, y in centres):
            centres.append(c)
    return np.array(centres, np.float32), rng.uniform(0.6, 1.0, count).astype(np.float32)


@pytest.fixture(scope="module")
def model_path(tmp_path_factory) -> Path:
    return superpoint_model(tmp_path_factory.mktemp("sp") / "tiny_superpoint.onnx")


@pytest.fixture(scope="module")
def indoor():
    return open_dataset("synthetic", scene="indoor", frames=20, sensor="rgbd")


@pytest.fixture(scope="module")
def orb_clean(indoor) -> TrackingStats:
    return track_features(indoor, OrbExtractor())


# -- ORB on the synthetic world ----------------------------------------------------------------
def test_orb_tracks_on_clean_synthetic_world(orb_clean):
    d = orb_clean.to_dict()
    assert orb_clean.frames == 20 and len(orb_clean.matches) == 19
    assert d["detections_per_frame"]["min"] >= 900  # measured: 1000 in every frame
    assert d["match_ratio"]["min"] > 0.6  # measured: 0.72 on average
    assert orb_clean.mean_track_length > 2.8  # measured: 3.19 frames
    assert d["tracks_spanning_sequence"] >= 30  # measured: 65
    assert d["tracks"] == len(orb_clean.track_lengths) == int(np.sum(orb_clean.track_lengths >= 1))
    # every detection is one track's observation
    assert orb_clean.track_lengths.sum() == orb_clean.detections.sum()


def test_survival_curve_starts_at_one_and_never_rises(orb_clean):
    s = orb_clean.survival
    assert s[0] == 1.0 and len(s) == orb_clean.track_lengths.max()
    assert np.all(np.diff(s) <= 0) and s[-1] > 0
    assert s[1] == pytest.approx(np.mean(orb_clean.track_lengths >= 2))


def test_heavy_sensor_noise_gives_fewer_matches_and_shorter_tracks(indoor, orb_clean):
    noisy = track_features(sal_modules.perturb(indoor, sal_modules.create("sensor_noise", iso=51200.0)), OrbExtractor())
    assert noisy.matches.mean() < 0.8 * orb_clean.matches.mean()  # measured: 479 vs 722
    assert noisy.mean_track_length < 0.75 * orb_clean.mean_track_length  # measured: 1.84 vs 3.19
    assert np.all(noisy.survival[1:5] < orb_clean.survival[1:5])


def test_identical_frames_give_tracks_as_long_as_the_sequence(indoor):
    frame = indoor[0].image
    stats = track_features([frame] * 6, OrbExtractor(features=500))
    assert stats.frames == 6 and stats.track_lengths.max() == 6
    assert np.mean(stats.track_lengths == 6) > 0.97
    assert stats.to_dict()["tracks_spanning_sequence"] >= 0.97 * stats.detections[0]


def test_max_frames_and_empty_sequence(indoor):
    stats = track_features(indoor, OrbExtractor(features=200), max_frames=3)
    assert stats.frames == 3 and len(stats.matches) == 2
    with pytest.raises(SalError, match="empty"):
        track_features([], OrbExtractor())


# -- SuperPoint through onnxruntime ------------------------------------------------------------
def test_superpoint_finds_the_bright_blobs(model_path):
    centres, amplitudes = random_blobs((96, 128), 12, margin=10)
    extractor = SuperPointExtractor(model_path)
    keypoints, descriptors = extractor.detect(blob_image((96, 128), centres, amplitudes))
    assert keypoints.dtype == np.float32 and keypoints.shape == (12, 2)
    assert descriptors.shape == (12, 16)
    np.testing.assert_allclose(np.linalg.norm(descriptors, axis=1), 1.0, atol=1e-5)
    distance = np.linalg.norm(keypoints[:, None] - centres[None], axis=2)
    assert np.all(distance.min(axis=0) <= 1.0)  # every blob found
    assert np.all(distance.min(axis=1) <= 1.0)  # and nothing else


def test_superpoint_pads_sizes_that_are_not_multiples_of_8(model_path):
    centres, amplitudes = random_blobs((101, 133), 10, margin=10, seed=5)
    image = (blob_image((101, 133), centres, amplitudes) * 255).astype(np.uint8)
    keypoints, _ = SuperPointExtractor(model_path).detect(image)
    distance = np.linalg.norm(keypoints[:, None] - centres[None], axis=2)
    assert len(keypoints) == 10 and np.all(distance.min(axis=0) <= 1.0)
    assert np.all(keypoints[:, 0] < 133) and np.all(keypoints[:, 1] < 101)


def test_superpoint_max_keypoints_keeps_the_strongest(model_path):
    centres, _ = random_blobs((96, 128), 12, margin=10)
    amplitudes = np.where(np.arange(12) % 3 == 0, 1.0, 0.45)  # 4 bright spots: heat ~0.9 against ~0.3
    keypoints, _ = SuperPointExtractor(model_path, max_keypoints=4).detect(blob_image((96, 128), centres, amplitudes))
    strongest = centres[amplitudes == 1.0]
    assert len(keypoints) == 4
    assert np.all(np.linalg.norm(keypoints[:, None] - strongest[None], axis=2).min(axis=1) <= 1.0)


def test_superpoint_matches_follow_a_shift(model_path):
    shift = np.array([16.0, 8.0], np.float32)
    centres, amplitudes = random_blobs((96, 160), 14, margin=10, seed=11)
    centres = centres[(centres[:, 0] + shift[0] < 150) & (centres[:, 1] + shift[1] < 86)]
    extractor = SuperPointExtractor(model_path)
    k1, d1 = extractor.detect(blob_image((96, 160), centres, amplitudes))
    k2, d2 = extractor.detect(blob_image((96, 160), centres + shift, amplitudes))
    pairs = extractor.match(d1, d2)
    assert len(pairs) >= 0.8 * len(centres)
    assert len(set(pairs[:, 0])) == len(pairs) == len(set(pairs[:, 1]))
    np.testing.assert_allclose(k2[pairs[:, 1]] - k1[pairs[:, 0]], np.tile(shift, (len(pairs), 1)), atol=1.0)


def test_superpoint_tracks_through_identical_frames(model_path):
    centres, amplitudes = random_blobs((96, 128), 12, margin=10)
    stats = track_features([blob_image((96, 128), centres, amplitudes)] * 5, SuperPointExtractor(model_path))
    assert stats.track_lengths.tolist() == [5] * 12
    assert stats.survival.tolist() == [1.0] * 5


def test_superpoint_model_errors(tmp_path, model_path):
    missing = tmp_path / "nope" / "superpoint.onnx"
    with pytest.raises(SalError, match="nope/superpoint.onnx.*not found"):
        SuperPointExtractor(missing)
    garbage = tmp_path / "garbage.onnx"
    garbage.write_bytes(b"this is not a model")
    with pytest.raises(SalError, match="garbage.onnx: cannot load"):
        SuperPointExtractor(garbage)
    wrong = superpoint_model(tmp_path / "wrong.onnx", semi_channels=64)
    with pytest.raises(SalError, match=r"wrong.onnx: expected a 1x65x.*returned"):
        SuperPointExtractor(wrong).detect(np.zeros((32, 32), np.uint8))
    with pytest.raises(SalError, match="needs a SuperPoint ONNX model"):
        create_extractor("superpoint")
    with pytest.raises(SalError, match="unknown feature type 'sift'"):
        parse_features("orb,sift")


def test_superpoint_accepts_other_names(tmp_path):
    path = superpoint_model(tmp_path / "renamed.onnx", descriptor_dim=8, names=("input.1", "scores", "descriptors"))
    centres, amplitudes = random_blobs((64, 64), 4, margin=10)
    keypoints, descriptors = SuperPointExtractor(path).detect(blob_image((64, 64), centres, amplitudes))
    assert keypoints.shape == (4, 2) and descriptors.shape == (4, 8)


def test_decode_is_depth_to_space():
    semi = np.full((65, 3, 3), -10.0, np.float32)
    semi[64] = 0.0
    semi[8 * 5 + 2, 1, 1] = 20.0  # cell (1, 1), pixel (row 5, column 2) inside it -> x = 10, y = 13
    desc = np.ones((4, 3, 3), np.float32)
    keypoints, descriptors = decode_superpoint(semi, desc, (24, 24))
    np.testing.assert_array_equal(keypoints, [[10.0, 13.0]])
    np.testing.assert_allclose(descriptors, [[0.5] * 4])


# -- comparison output -------------------------------------------------------------------------
def test_compare_features_writes_json_and_pngs(tmp_path, indoor, model_path):
    short = indoor.select(list(range(6)))
    sequences = {"clean": short, "defocus": sal_modules.perturb(short, sal_modules.create("defocus", f_number=0.95, focus_distance_m=0.1))}
    extractors = parse_features("orb,superpoint", model=model_path, max_keypoints=300)
    results = compare_features(sequences, extractors, tmp_path / "features")
    assert set(results) == {"orb", "superpoint"}
    for feature in ("orb", "superpoint"):
        folder = tmp_path / "features" / feature
        summary = json.loads((folder / "summary.json").read_text())
        assert summary["feature"] == feature and set(summary["sequences"]) == {"clean", "defocus"}
        clean = summary["sequences"]["clean"]
        assert clean["frames"] == 6 and len(clean["matches_per_frame"]["values"]) == 5
        assert clean["survival"][0] == 1.0 and "mean_track_length" in clean
        for png in ("track_survival.png", "detections.png"):
            assert (folder / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert results[feature]["summary"] == folder / "summary.json"
    orb = results["orb"]["stats"]
    assert orb["defocus"].matches.mean() < orb["clean"].matches.mean()
    with pytest.raises(SalError, match="once"):
        compare_features(sequences, [OrbExtractor(), OrbExtractor()], tmp_path / "again")
