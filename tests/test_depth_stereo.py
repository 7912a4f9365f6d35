"""Stereo depth (semi-global matching) against exact depth: the synthetic urban world (left and
right views), the synthetic indoor world re-imaged through distorted, rotated lenses (the
rectification round trip back to raw pixels), and a real KITTI 07 frame turned into a stereo
pair of a known planar world (the excerpt has no right camera). On the real EuRoC pair, points
tracked from one camera to the other must reproject where the depth puts them; the border
bands, filling unmeasurable pixels, unavailable reasons and options."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from depth_sequences import planar_kitti, synthetic

from sal_adapters import Sequence, open_dataset
from sal_adapters.camera import Camera
from sal_adapters.sequence import FrameRecord
from sal_adapters.synthetic import make_world
from sal_modules.depth import (
    StereoDepth,
    left_depth_to_right,
    select_depth_provider,
)
from sal_modules.depth.stereo_fill import fill_unmeasurable
from sal_modules.depth.stereo_rig import stereo_rig
from sal_modules.errors import ModuleError

#: the shared fixtures (euroc)
pytest_plugins = ["depth_sequences"]


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
