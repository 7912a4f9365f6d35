"""Monocular depth from tiny ONNX models built by the test (tests/onnx_models.py): metric and
inverse outputs, output size, errors naming the file, cache invalidation; the depth provider
choice, depth computed once and cached, damaged cached depth, and native right-camera depth."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest
from depth_sequences import planar_kitti, synthetic
from onnx_models import depth_model

from sal_adapters import Sequence, open_dataset
from sal_adapters.camera import Camera
from sal_adapters.common.errors import CacheWarning
from sal_adapters.sequence import FrameRecord
from sal_adapters.synthetic import make_world
from sal_modules.depth import (
    MonoDepth,
    NativeDepth,
    StereoDepth,
    select_depth_provider,
)
from sal_modules.errors import DepthUnavailable, ModuleError

#: the shared fixtures (euroc)
pytest_plugins = ["depth_sequences"]


# -- monocular ONNX -------------------------------------------------------------------------
def flat_sequence(values: tuple[int, int, int] = (51, 102, 153), size: tuple[int, int] = (60, 80)) -> Sequence:
    """One frame of a uniform colour (a left half darker than the right when values differ)."""
    image = np.empty((*size, 3), np.uint8)
    image[:] = values
    camera = Camera(100.0, 100.0, size[1] / 2, size[0] / 2, size[1], size[0])
    record = FrameRecord(index=0, timestamp=0.0, stem="000000", image=lambda: image)
    return Sequence(
        kind="folder", name="flat", camera=camera, sensor="mono", fps=10.0, records=[record], content_key=f"flat-{values}-{size}"
    )


def test_mono_metric_and_inverse_outputs(tmp_path):
    model = depth_model(tmp_path / "depth.onnx", gain=2.0, offset=1.0)  # depth = 2 mean_c(x) + 1
    seq = flat_sequence()
    plain = {"mean": (0, 0, 0), "std": (1, 1, 1)}  # the model sees I / 255
    expected = 2.0 * (51 + 102 + 153) / 3 / 255 + 1.0  # 1.8
    metric = MonoDepth(model, **plain).compute(seq, 0, "left")
    assert metric.shape == (60, 80) and metric.dtype == np.float32
    np.testing.assert_allclose(metric, expected, rtol=1e-5)
    np.testing.assert_allclose(MonoDepth(model, scale=3.0, **plain).compute(seq, 0, "left"), 3 * expected, rtol=1e-5)
    inverse = MonoDepth(model, output="inverse", scale=3.6, **plain).compute(seq, 0, "left")
    np.testing.assert_allclose(inverse, 3.6 / expected, rtol=1e-5)
    # ImageNet normalisation by default
    imagenet = np.mean([(v / 255 - m) / s for v, m, s in zip((51, 102, 153), (0.485, 0.456, 0.406), (0.229, 0.224, 0.225))])
    np.testing.assert_allclose(MonoDepth(model).compute(seq, 0, "left"), 2 * imagenet + 1, rtol=1e-5)
    # non-positive output is unknown depth, not a negative or infinite one
    negative = depth_model(tmp_path / "negative.onnx", gain=0.0, offset=-1.0)
    assert not MonoDepth(negative).compute(seq, 0, "left").any()
    assert not MonoDepth(negative, output="inverse").compute(seq, 0, "left").any()


def test_mono_output_follows_the_image_and_input_size(tmp_path, monkeypatch):
    image = np.zeros((40, 90, 3), np.uint8)
    image[:, 45:] = 255
    seq = flat_sequence()
    seq = seq.replace(records=[FrameRecord(0, 0.0, "000000", lambda: image)], camera=Camera(50, 50, 45, 20, 90, 40), content_key="halves")
    provider = MonoDepth(depth_model(tmp_path / "d.onnx", gain=1.0, offset=1.0), mean=(0, 0, 0), std=(1, 1, 1))
    shapes = []
    session = provider.session()
    run = session.run
    monkeypatch.setattr(session, "run", lambda names, feeds: shapes.append(feeds["image"].shape) or run(names, feeds))
    depth = provider.compute(seq, 0, "left")
    assert shapes == [(1, 3, 518, 518)]  # dynamic model: the default input size
    np.testing.assert_allclose(depth[:, :40], 1.0, atol=1e-3)
    np.testing.assert_allclose(depth[:, 50:], 2.0, atol=1e-3)
    sized = MonoDepth(provider.model, input_size=(56, 112), mean=(0, 0, 0), std=(1, 1, 1))
    sized_session = sized.session()
    sized_run = sized_session.run
    monkeypatch.setattr(sized_session, "run", lambda names, feeds: shapes.append(feeds["image"].shape) or sized_run(names, feeds))
    sized.compute(seq, 0, "left")
    assert shapes[-1] == (1, 3, 56, 112)
    static = MonoDepth(depth_model(tmp_path / "static.onnx", size=(28, 42)), input_size=(56, 112))
    assert static.compute(seq, 0, "left").shape == (40, 90)  # static 28x42 input, resized back


def test_mono_errors_name_the_file(tmp_path, monkeypatch):
    seq = flat_sequence()
    missing = tmp_path / "nope.onnx"
    assert MonoDepth(missing).unavailable(seq) == f"monocular depth model {missing} not found"
    with pytest.raises(ModuleError, match="nope.onnx not found"):
        MonoDepth(missing).compute(seq, 0, "left")
    with pytest.raises(DepthUnavailable, match=r"nope\.onnx not found"):
        select_depth_provider(seq, str(missing), needed_by="fog")
    junk = tmp_path / "junk.onnx"
    junk.write_text("not a model")
    reason = MonoDepth(junk).unavailable(seq)
    assert reason.startswith(f"monocular depth model {junk} is not a valid ONNX model")
    with pytest.raises(ModuleError, match="junk.onnx is not a valid ONNX model"):
        MonoDepth(junk).compute(seq, 0, "left")
    with pytest.raises(ModuleError, match="output must be"):
        MonoDepth(junk, output="log")
    with pytest.raises(ModuleError, match="no right images"):
        MonoDepth(depth_model(tmp_path / "ok.onnx")).compute(seq, 0, "right")
    monkeypatch.setitem(sys.modules, "onnxruntime", None)  # as if the extra were not installed
    assert "pip install 'pytest-sal[onnx]'" in MonoDepth(depth_model(tmp_path / "ok.onnx")).unavailable(seq)


def test_mono_cache_invalidated_when_the_model_changes(tmp_path):
    seq = flat_sequence()
    path = depth_model(tmp_path / "m.onnx", gain=0.0, offset=2.0)
    first = MonoDepth(path)
    key = first.key(seq)
    assert first.lookup(seq, cache_dir=tmp_path)(0, "left")[0, 0] == pytest.approx(2.0)
    depth_model(path, gain=0.0, offset=5.0)  # same size, new content
    os.utime(path, ns=(1, 1))  # even with an unusual time stamp
    assert MonoDepth(path).key(seq) != key
    assert MonoDepth(path).lookup(seq, cache_dir=tmp_path)(0, "left")[0, 0] == pytest.approx(5.0)
    # the same provider notices the new file too (hash and session)
    assert first.key(seq) != key
    assert first.lookup(seq, cache_dir=tmp_path)(0, "left")[0, 0] == pytest.approx(5.0)
    for changed in ({"scale": 2.0}, {"output": "inverse"}, {"input_size": (28, 28)}, {"mean": (0, 0, 0)}):
        assert MonoDepth(path, **changed).key(seq) != MonoDepth(path).key(seq)


# -- provider choice and cache ----------------------------------------------------------------
def test_select_depth_provider(shared_data, euroc, tmp_path, monkeypatch):
    monkeypatch.delenv("SAL_DEPTH_MODEL", raising=False)
    assert isinstance(select_depth_provider(synthetic("indoor", "rgbd")), NativeDepth)
    assert isinstance(select_depth_provider(synthetic("urban")), NativeDepth)  # exact depth wins
    assert isinstance(select_depth_provider(synthetic("urban"), "stereo"), StereoDepth)
    assert isinstance(select_depth_provider(euroc), StereoDepth)
    kitti_stereo, _ = planar_kitti(shared_data / "kitti" / "sequences" / "07", frames=1)
    assert isinstance(select_depth_provider(kitti_stereo), StereoDepth)
    kitti_mono = open_dataset("kitti", shared_data / "kitti" / "sequences" / "07", max_frames=1)
    with pytest.raises(DepthUnavailable) as info:
        select_depth_provider(kitti_mono, needed_by="fog")
    message = str(info.value)
    assert message.startswith(f"fog needs depth and no depth provider applies to {kitti_mono.name!r}")
    assert "native: sequence" in message and "has no depth maps" in message
    assert "stereo: sequence" in message and "not a stereo pair" in message
    assert "depth='model.onnx'" in message and "SAL_DEPTH_MODEL" in message
    model = depth_model(tmp_path / "model.onnx", gain=0.0, offset=7.0)
    chosen = select_depth_provider(kitti_mono, str(model))
    assert isinstance(chosen, MonoDepth) and chosen.model == model
    monkeypatch.setenv("SAL_DEPTH_MODEL", str(model))
    assert isinstance(select_depth_provider(kitti_mono), MonoDepth)
    with pytest.raises(DepthUnavailable, match="native: .*no depth maps"):
        select_depth_provider(kitti_mono, "native")


def test_depth_computed_once_and_cached(tmp_path, monkeypatch):
    seq = synthetic("urban")
    provider = StereoDepth()
    calls = []
    compute = provider.compute
    monkeypatch.setattr(provider, "compute", lambda s, p, stream: calls.append((p, stream)) or compute(s, p, stream))
    index = seq[1].index
    first = provider.lookup(seq, cache_dir=tmp_path)(index, "left")
    assert calls == [(1, "left")]
    stored = tmp_path / "depth" / provider.key(seq) / f"{index}_left.npy"
    assert stored.is_file()
    again = provider.lookup(seq, cache_dir=tmp_path)  # a fresh lookup: nothing in memory
    np.testing.assert_array_equal(again(index, "left"), first)
    assert calls == [(1, "left")]  # read back from the file, not computed again
    # every option that changes the result changes the key
    base = StereoDepth().key(seq)
    for changed in (
        {"min_depth_m": 3.0},
        {"block_size": 7},
        {"mode": "sgbm"},
        {"uniqueness": 15},
        {"speckle_window": 50},
        {"speckle_range": 1},
        {"min_texture": 2.0},
    ):
        assert StereoDepth(**changed).key(seq) != base, changed
    assert StereoDepth().key(synthetic("indoor")) != base  # and so does the sequence


@pytest.mark.parametrize(
    "damage, problem",
    [
        (lambda path: path.write_bytes(path.read_bytes()[:100]), "cannot read depth array"),
        (lambda path: path.write_bytes(b""), "cannot read depth array"),
        (lambda path: path.write_bytes(os.urandom(4000)), "cannot read depth array"),
        (lambda path: np.save(path, np.zeros((4, 4), np.float32)), "depth array of shape (4, 4), the frames are"),
        (lambda path: np.save(path, np.zeros((4, 4), np.int32)), "depth array must hold floats (m), got int32"),
    ],
    ids=["truncated", "empty", "garbage", "wrong-shape", "integers"],
)
def test_damaged_cached_depth_is_computed_again(tmp_path, damage, problem):
    """A damaged depth file in the cache is not an error on every later run (issue 12): one
    CacheWarning names it, the depth is computed again and the file replaced."""
    seq = synthetic("urban")
    provider = StereoDepth()
    index = seq[1].index
    first = provider.lookup(seq, cache_dir=tmp_path)(index, "left")
    stored = tmp_path / "depth" / provider.key(seq) / f"{index}_left.npy"
    clean = stored.read_bytes()
    damage(stored)
    with pytest.warns(CacheWarning) as caught:
        again = provider.lookup(seq, cache_dir=tmp_path)(index, "left")
    assert [str(w.message).split(": bad cached depth, computed again and replaced: ")[0] for w in caught] == [str(stored)]
    assert problem in str(caught[0].message)
    np.testing.assert_array_equal(again, first)
    assert stored.read_bytes() == clean


def test_native_right_depth_is_the_left_depth_seen_from_the_right_camera() -> None:
    """The warped left ground truth matches the right view's own ground truth, keeps the sky
    at 0 and fills the border band the left camera never sees (no fake sky there)."""
    seq = synthetic("urban")
    right = NativeDepth().compute(seq, 1, "right")
    truth = make_world("urban", 0).render(seq[1].index, right=True)[1]
    both = (truth > 0) & (right > 0)
    error = np.abs(right[both] - truth[both]) / truth[both]
    assert np.median(error) < 0.005 and (error > 0.1).mean() < 0.02
    assert ((truth == 0) == (right == 0)).mean() > 0.99
    band = slice(seq.camera.width - 60, None)
    assert (right[:, band] == 0).mean() <= (truth[:, band] == 0).mean() + 0.01
