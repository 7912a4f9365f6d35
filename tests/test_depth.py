"""Depth providers: stereo semi-global matching, monocular ONNX models, provider choice, cache.

Stereo depth is checked against exact depth: the synthetic urban world (left and right views),
the synthetic indoor world re-imaged through distorted, rotated lenses (the rectification
round trip back to raw pixels), and a real KITTI 07 frame turned into a stereo pair of a known
planar world (the excerpt has no right camera). On the real EuRoC pair, points tracked from one
camera to the other must reproject where the depth puts them. Monocular depth runs tiny ONNX
models built by the test (tests/onnx_models.py).
"""

from __future__ import annotations

import os
import sys
from functools import cache
from pathlib import Path

import cv2
import numpy as np
import pytest
from onnx_models import depth_model

from sal_adapters import DatasetWarning, Sequence, open_dataset
from sal_adapters.camera import Camera
from sal_adapters.errors import CacheWarning
from sal_adapters.images import read_image
from sal_adapters.sequence import FrameRecord
from sal_adapters.synthetic import make_world
from sal_modules.depth import (
    MonoDepth,
    NativeDepth,
    StereoDepth,
    left_depth_to_right,
    select_depth_provider,
)
from sal_modules.depth.stereo_fill import fill_unmeasurable
from sal_modules.depth.stereo_rig import stereo_rig
from sal_modules.errors import DepthUnavailable, ModuleError


@cache
def synthetic(scene: str, sensor: str = "stereo") -> Sequence:
    return open_dataset("synthetic", scene=scene, frames=2, sensor=sensor)


def relative_error(depth: np.ndarray, truth: np.ndarray) -> tuple[float, float, float]:
    """Median relative error and share of errors over 10 % on pixels valid in both, and the
    share of valid ground-truth pixels that got depth."""
    both = (depth > 0) & (truth > 0)
    rel = np.abs(depth[both] - truth[both]) / truth[both]
    return float(np.median(rel)), float(np.mean(rel > 0.1)), float(both.sum() / (truth > 0).sum())


# -- stereo on exact ground truth -----------------------------------------------------------
def test_stereo_matches_synthetic_urban_depth_left_and_right():
    seq = synthetic("urban")
    provider = StereoDepth()
    assert provider.unavailable(seq) is None
    left = provider.compute(seq, 1, "left")
    assert left.dtype == np.float32 and left.shape == (seq.camera.height, seq.camera.width)
    median, bad, coverage = relative_error(left, seq[1].depth)
    assert median < 0.01 and bad < 0.06 and coverage > 0.93, (median, bad, coverage)  # measured 0.48 %, 5.5 %, 100 %
    # the right camera's depth against the right view rendered by the world itself
    right_truth = make_world("urban", 0).render(seq[1].index, right=True)[1]
    right = provider.compute(seq, 1, "right")
    median, bad, coverage = relative_error(right, right_truth)
    assert median < 0.01 and bad < 0.06 and coverage > 0.92, (median, bad, coverage)
    # and against the left ground truth warped into the right camera
    median, _, coverage = relative_error(right, left_depth_to_right(seq[1].depth, seq.camera))
    assert median < 0.01 and coverage > 0.93
    # the two views differ where they should: the left view's depth is not the right view's
    assert relative_error(left, right_truth)[1] > 2 * relative_error(right, right_truth)[1]


def distorted_rig(seq: Sequence, distortion: tuple[float, ...], angles_deg: tuple[float, float, float]) -> Sequence:
    """``seq`` (a rectified stereo pair with exact depth) re-imaged through lenses with
    ``distortion``, the right camera also rotated by ``angles_deg`` (Rodrigues vector, deg):
    an unrectified pair like EuRoC's whose true depth is known at every raw pixel."""
    cam = seq.camera
    R_lr = cv2.Rodrigues(np.deg2rad(np.array(angles_deg, dtype=np.float64)))[0]
    dist = np.array(distortion, dtype=np.float64)
    size = (cam.width, cam.height)
    # raw pixel -> undistorted ray -> (rotated into the ideal right camera) -> ideal pixel
    maps = {
        "left": cv2.initInverseRectificationMap(cam.K, dist, np.eye(3), cam.K, size, cv2.CV_32FC1),
        "right": cv2.initInverseRectificationMap(cam.K, dist, R_lr, cam.K, size, cv2.CV_32FC1),
    }
    T = np.eye(4)
    T[:3, :3] = R_lr
    T[0, 3] = cam.baseline_m
    lens = Camera(cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height, distortion=tuple(distortion))
    camera = lens.with_stereo(T, right=lens)

    def raw(frame, stream):
        return lambda: cv2.remap(frame.image if stream == "left" else frame.right, *maps[stream], cv2.INTER_LINEAR)

    def raw_depth(frame):
        return lambda: cv2.remap(frame.depth, *maps["left"], cv2.INTER_NEAREST)

    records = [
        FrameRecord(r.index, r.timestamp, r.stem, raw(f, "left"), right=raw(f, "right"), depth=raw_depth(f))
        for r, f in zip(seq.records, seq)
    ]
    return seq.replace(camera=camera, records=records, content_key=f"distorted-{distortion}-{angles_deg}")


def test_stereo_rectifies_and_puts_depth_back_at_raw_pixels():
    seq = distorted_rig(synthetic("indoor"), (-0.28, 0.07, 2e-4, 2e-5), (0.8, -1.5, 0.5))
    truth = seq[1].depth  # exact depth at each raw (distorted) left pixel
    depth = StereoDepth().compute(seq, 1, "left")
    median, bad, coverage = relative_error(depth, truth)
    assert median < 0.02 and bad < 0.04 and coverage > 0.9, (median, bad, coverage)  # measured 1.0 %, 1.8 %, 96.6 %
    # alignment: near depth edges the error is smallest with the truth unshifted (within 1 px)
    log_truth = np.log(np.maximum(truth, 1e-3))
    edges = (np.abs(np.diff(log_truth, axis=1, append=0)) > 0.05) | (np.abs(np.diff(log_truth, axis=0, append=0)) > 0.05)
    edges = cv2.dilate(edges.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    cost = {}
    for dx in range(-3, 4):
        for dy in range(-3, 4):
            shifted = np.roll(truth, (dy, dx), axis=(0, 1))
            ok = edges & (depth > 0) & (shifted > 0)
            cost[dx, dy] = float(np.mean(np.minimum(np.abs(np.log(depth[ok] / shifted[ok])), 0.3)))
    best = min(cost, key=cost.get)
    assert max(abs(best[0]), abs(best[1])) <= 1, best
    assert cost[best] < 0.95 * min(cost[3, 0], cost[-3, 0], cost[0, 3], cost[0, -3])


# -- stereo on real frames -------------------------------------------------------------------
def planar_kitti(kitti07: Path, frames: int = 2, height_m: float = 1.65, wall_m: float = 25.0) -> tuple[Sequence, np.ndarray]:
    """Real KITTI 07 frames as the left views of a known world: the road plane ``height_m``
    below the camera up to a frontal wall at ``wall_m``. The right view is the left image
    shifted row by row by the disparity ``f B / Z`` of that world (exact for row-constant
    disparity), so matching works on real texture, grey levels, size and calibration."""
    seq = open_dataset("kitti", kitti07, max_frames=frames)
    cam = seq.camera
    T = np.eye(4)
    T[0, 3] = 0.5372  # the KITTI grey pair's baseline (m)
    camera = cam.with_stereo(T)
    rows = np.arange(cam.height, dtype=np.float32)
    disparity = np.maximum(camera.baseline_m * (rows - cam.cy) / height_m * cam.fx / cam.fy, cam.fx * camera.baseline_m / wall_m)
    truth = np.repeat((cam.fx * camera.baseline_m / disparity)[:, None], cam.width, axis=1).astype(np.float32)
    map_x = (np.arange(cam.width, dtype=np.float32)[None, :] + disparity[:, None]).astype(np.float32)
    map_y = np.repeat(rows[:, None], cam.width, axis=1)

    def right_view(path):
        return lambda: cv2.remap(read_image(path), map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)

    records = [FrameRecord(r.index, r.timestamp, r.stem, r.image, right=right_view(r.image)) for r in seq.records]
    return seq.replace(camera=camera, sensor="stereo", records=records), truth


def test_stereo_on_real_kitti_texture(shared_data):
    seq, truth = planar_kitti(shared_data / "kitti" / "sequences" / "07")
    provider = select_depth_provider(seq)
    assert isinstance(provider, StereoDepth)
    for stream in ("left", "right"):  # the world is the same seen from either camera
        depth = provider.compute(seq, 1, stream)
        median, bad, coverage = relative_error(depth, truth)
        assert median < 0.02 and bad < 0.02 and coverage > 0.8, (stream, median, bad, coverage)  # measured 0.9 %, 0.4 %, 93 %
    h, w = depth.shape
    road = depth[3 * h // 4 :, w // 3 : 2 * w // 3]
    assert 5.0 < np.median(road[road > 0]) < 30.0
    # the overexposed sky has no texture: no depth there
    sky = depth[:40, 450:650]
    assert np.mean(sky > 0) < 0.2


@pytest.fixture(scope="module")
def euroc(shared_data) -> Sequence:
    path = shared_data / "euroc" / "V1_01_easy_micro"
    if not (path / "mav0").is_dir():
        pytest.skip(f"EuRoC excerpt not found at {path}")
    with pytest.warns(DatasetWarning, match="rows skipped"):
        return open_dataset("euroc", path, stereo=True, max_frames=2)


def tracked(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Corners of grey image ``a`` and where they are in ``b`` (pyramidal Lucas-Kanade,
    kept where tracking back lands within 0.3 px of the start)."""
    p0 = cv2.goodFeaturesToTrack(a, 800, 0.01, 8)
    p1, st1, _ = cv2.calcOpticalFlowPyrLK(a, b, p0, None, winSize=(21, 21), maxLevel=4)
    p2, st2, _ = cv2.calcOpticalFlowPyrLK(b, a, p1, None, winSize=(21, 21), maxLevel=4)
    ok = (st1[:, 0] == 1) & (st2[:, 0] == 1) & (np.linalg.norm(p2 - p0, axis=2)[:, 0] < 0.3)
    return p0[ok, 0].astype(np.float64), p1[ok, 0].astype(np.float64)


def test_stereo_on_real_euroc_reprojects_tracked_points(euroc):
    """EuRoC is unrectified: depth at a raw pixel, back-projected through the distorted lens
    and moved into the other camera, must land on the point tracked there."""
    provider = select_depth_provider(euroc)
    assert isinstance(provider, StereoDepth)
    cam = euroc.camera
    right = cam.right or cam
    grey = [cv2.cvtColor(im, cv2.COLOR_RGB2GRAY) for im in (euroc[0].image, euroc[0].right)]
    cases = {
        "left": (grey[0], grey[1], cam, right, np.linalg.inv(cam.T_lr)),
        "right": (grey[1], grey[0], right, cam, cam.T_lr),
    }
    for stream, (a, b, src_cam, dst_cam, T) in cases.items():
        depth = provider.compute(euroc, 0, stream)
        assert np.mean(depth > 0) > 0.7
        assert np.percentile(depth[depth > 0], 5) > 0.5 and np.percentile(depth[depth > 0], 95) < 10.0  # in the room
        src, dst = tracked(a, b)
        u = np.rint(src).astype(int)
        z = depth[u[:, 1], u[:, 0]]
        ok = z > 0
        assert len(src) > 50 and ok.mean() > 0.9
        rays = cv2.undistortPoints(src[ok, None], src_cam.K, np.array(src_cam.distortion)).reshape(-1, 2)
        points = np.c_[rays, np.ones(len(rays))] * z[ok, None]

        def reprojection(scale: float, points=points, T=T, dst_cam=dst_cam, target=dst[ok]) -> float:
            proj = cv2.projectPoints(points * scale, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], dst_cam.K, np.array(dst_cam.distortion))[0]
            return float(np.median(np.linalg.norm(proj.reshape(-1, 2) - target, axis=1)))

        assert reprojection(1.0) < 0.5, stream  # measured 0.24 px
        assert reprojection(1.05) > 1.5 * reprojection(1.0)  # and 5 % off in depth would show


def border_bands(depth: np.ndarray, width: int = 40) -> np.ndarray:
    """The bottom ``width`` rows and the left and right ``width`` columns of ``depth``."""
    band = np.zeros(depth.shape, bool)
    band[-width:] = band[:, :width] = band[:, -width:] = True
    return depth[band]


def test_stereo_gives_the_euroc_border_depth(euroc):
    """Unknown depth is sky to fog, rain and snow: the curved rectification border, the rows
    only one camera sees and the floor the near foam block hides from the other camera get
    the depth of the nearest surface; the overexposed window, open to the top, stays unknown."""
    provider = StereoDepth()
    for stream in ("left", "right"):
        depth = provider.compute(euroc, 0, stream)
        bands = border_bands(depth)
        assert np.mean(bands == 0) < 0.1, (stream, np.mean(bands == 0))  # measured 1.2 %, 4.6 % (36 %, 31 % unfilled)
        assert np.mean(depth[-40:] == 0) < 0.02, stream  # measured 0 % (62 %, 48 % unfilled)
        assert np.percentile(bands[bands > 0], 5) > 0.3 and np.percentile(bands[bands > 0], 95) < 6.0  # in the room
        assert np.mean(depth[:40, 250:500] == 0) > 0.5  # the window


def test_fill_unmeasurable_keeps_sky_and_fills_the_border():
    h, w = 120, 160
    depth = np.full((h, w), 5.0, np.float32)
    depth[:, 80:] = 6.0  # two walls
    depth[:40, 40:120] = 0.0  # sky, open to the top
    depth[100:, :] = 0.0  # unmatched floor along the bottom
    depth[105:108, 35:75] = 50.0  # a stray mismatch inside it
    depth[60:70, 60:70] = 0.0  # a hole enclosed by depth
    unmeasurable = np.ones((h, w), bool)
    unmeasurable[3:-3, 3:-3] = False  # the border the matching block cannot reach
    depth[unmeasurable] = 0.0
    filled = fill_unmeasurable(depth, unmeasurable)
    assert not filled[:40, 40:120].any()  # the sky stays unknown, the border above it too
    assert not filled[60:70, 60:70].any()
    np.testing.assert_array_equal(filled[:40, :37], 5.0)  # the border beside a wall takes its depth
    np.testing.assert_array_equal(filled[100:, :30], 5.0)
    np.testing.assert_array_equal(filled[100:, 82:], 6.0)  # the nearest wall, never the mismatch
    np.testing.assert_array_equal(filled[105:108, 35:75], 50.0)  # depth that was there stays
    np.testing.assert_array_equal(filled[depth > 0], depth[depth > 0])


# -- stereo availability and options -------------------------------------------------------
def test_stereo_unavailable_reasons(shared_data):
    mono = open_dataset("kitti", shared_data / "kitti" / "sequences" / "07", max_frames=1)
    assert "not a stereo pair" in StereoDepth().unavailable(mono)
    stereo = synthetic("urban")
    no_baseline = stereo.replace(camera=Camera(700, 700, 600, 180, 1240, 376))
    assert "no stereo baseline" in StereoDepth().unavailable(no_baseline)
    T = np.eye(4)
    T[0, 3] = -0.5
    swapped = stereo.replace(camera=Camera(700, 700, 600, 180, 1240, 376).with_stereo(T))
    assert "to the right" in StereoDepth().unavailable(swapped)
    with pytest.raises(ModuleError, match="stereo depth: .*not a stereo pair"):
        StereoDepth().compute(mono, 0, "left")


def test_stereo_options_checked_and_disparity_range():
    for bad in ({"min_depth_m": 0}, {"block_size": 4}, {"mode": "fast"}, {"uniqueness": 120}, {"min_texture": -1}):
        with pytest.raises(ModuleError, match="stereo depth"):
            StereoDepth(**bad)
    seq = synthetic("urban")
    rig = stereo_rig(seq.camera)
    assert rig.rectified and rig.focal == seq.camera.fx
    # numDisparities covers f B / min_depth_m, in steps of 16
    assert StereoDepth(min_depth_m=2.0).num_disparities(rig) == 16 * int(np.ceil(seq.camera.fx * 0.54 / 2.0 / 16))
    assert StereoDepth().num_disparities(rig) == 160  # default: 1/8 of the width
    near = StereoDepth(min_depth_m=2.0).compute(seq, 1, "left")
    assert relative_error(near, seq[1].depth)[0] < 0.01


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
