"""The synthetic world: camera rate, size and streams per sensor, motion of the urban and indoor
cameras, seeded rendering, exact depth and poses, stereo disparity, texture and sky, and the
renderer against brute-force ray casting."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from synthetic_sequences import rgbd

from sal_adapters import (
    Sequence,
    open_dataset,
)
from sal_adapters.synthetic import WORLDS
from sal_adapters.synthetic.geometry import BoxBuilder
from sal_adapters.synthetic.render import Renderer, Stage, sun_light

SCENES = ("urban", "indoor")
#: fx, fy, cx, cy, width, height, fps, baseline (m), depth scale
SPEC = {
    "urban": (718.856, 718.856, 607.1928, 185.2157, 1240, 376, 10.0, 0.54, None),
    "indoor": (525.0, 525.0, 319.5, 239.5, 640, 480, 30.0, 0.1, 5000.0),
}


def grey(rgb: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float64)


def bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear samples of a 2-D array at float coordinates (inside the image)."""
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    img = image.astype(np.float64)
    return (
        img[y0, x0] * (1 - fx) * (1 - fy)
        + img[y0, x0 + 1] * fx * (1 - fy)
        + img[y0 + 1, x0] * (1 - fx) * fy
        + img[y0 + 1, x0 + 1] * fx * fy
    )


# -- camera, sensors, motion ---------------------------------------------------------------------
@pytest.mark.parametrize("scene", SCENES)
@pytest.mark.parametrize("sensor", ["mono", "stereo", "rgbd"])
def test_camera_rate_size_and_streams_per_sensor(scene: str, sensor: str) -> None:
    fx, fy, cx, cy, width, height, fps, baseline, depth_scale = SPEC[scene]
    seq = open_dataset("synthetic", scene=scene, frames=3, sensor=sensor)
    cam = seq.camera
    assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height) == (fx, fy, cx, cy, width, height)
    assert cam.depth_scale == depth_scale and seq.fps == fps and seq.sensor == sensor
    np.testing.assert_array_equal(seq.timestamps, np.arange(3) / fps)
    frame = seq[1]
    assert frame.image.shape == (height, width, 3) and frame.image.dtype == np.uint8
    if sensor == "stereo":
        assert cam.baseline_m == pytest.approx(baseline)
        np.testing.assert_allclose(cam.T_lr, [[1, 0, 0, baseline], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
        assert frame.right.shape == (height, width, 3)
    else:
        assert cam.baseline_m is None and frame.right is None
    # ground-truth depth comes with every sensor (depth-aware perturbations use it)
    assert frame.depth.shape == (height, width) and frame.depth.dtype == np.float32


def test_default_sensor_is_stereo_outdoors_and_rgbd_indoors() -> None:
    assert open_dataset("synthetic", scene="urban", frames=2).sensor == "stereo"
    assert open_dataset("synthetic", scene="indoor", frames=2).sensor == "rgbd"


def test_urban_camera_drives_forward_at_4_m_per_s_1_65_m_above_the_road() -> None:
    seq = rgbd("urban", 21)
    steps = np.linalg.norm(np.diff(seq.groundtruth.positions, axis=0), axis=1) * seq.fps
    assert np.all((steps > 3.5) & (steps < 4.5)) and np.mean(steps) == pytest.approx(4.0, abs=0.3)
    travel = seq.groundtruth.positions[-1]
    assert travel[2] / np.linalg.norm(travel) > 0.998  # straight ahead, along the first camera's z
    # Road points at the bottom centre: Y (camera frame, down) is the camera height.
    depth = seq[0].depth
    v = np.arange(340, 372)[:, None]
    height = (v - seq.camera.cy) / seq.camera.fy * depth[340:372, 560:680]
    assert np.median(height) == pytest.approx(1.65, abs=0.05)


def test_indoor_camera_is_hand_held_speed() -> None:
    gt = open_dataset("synthetic", scene="indoor", frames=301).groundtruth  # 10 s, nothing rendered
    speed = np.linalg.norm(np.diff(gt.positions, axis=0), axis=1) * 30.0
    assert 0.3 < speed.mean() < 0.6 and speed.max() < 1.2
    relative = np.linalg.inv(gt.matrices[:-1]) @ gt.matrices[1:]
    angles = np.degrees(np.arccos(np.clip((np.trace(relative[:, :3, :3], axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert angles.max() < 1.0 and angles.sum() > 2.0


# -- determinism ------------------------------------------------------------------------------------
@pytest.mark.parametrize("scene", SCENES)
def test_same_seed_renders_bit_identical_frames(scene: str) -> None:
    first, second = WORLDS[scene](3), WORLDS[scene](3)  # fresh worlds: atlas painted twice
    (rgb1, depth1), (rgb2, depth2) = first.render(4), second.render(4)
    assert np.array_equal(rgb1, rgb2) and np.array_equal(depth1, depth2)
    assert first.groundtruth(np.arange(5)).allclose(second.groundtruth(np.arange(5)), atol=0.0)


@pytest.mark.parametrize("scene", SCENES)
def test_other_seed_gives_other_world_and_path(scene: str) -> None:
    a, b = rgbd(scene, 11, seed=0), rgbd(scene, 11, seed=1)
    assert np.abs(grey(a[0].image) - grey(b[0].image)).mean() > 15
    assert not np.array_equal(WORLDS[scene](0).atlas.image, WORLDS[scene](1).atlas.image)
    assert np.abs(a.groundtruth.positions[10] - b.groundtruth.positions[10]).max() > 0.01


def test_frame_does_not_depend_on_the_number_of_frames(tmp_path: Path) -> None:
    short = open_dataset("synthetic", scene="indoor", frames=3, cache_dir=tmp_path / "a")
    long = open_dataset("synthetic", scene="indoor", frames=20, cache_dir=tmp_path / "b")
    assert np.array_equal(short[2].image, long[2].image) and np.array_equal(short[2].depth, long[2].depth)
    assert short.groundtruth.allclose(long.groundtruth.select([0, 1, 2]), atol=0.0)


# -- physics: depth, stereo, texture ----------------------------------------------------------------
def reprojection(seq: Sequence, i: int, j: int, poses: np.ndarray, max_depth: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """Relative depth error and grey-value difference of frame i's pixels moved into frame j."""
    K, fi, fj = seq.camera.K, seq[i], seq[j]
    height, width = fi.depth.shape
    v, u = np.mgrid[3 : height - 3 : 5, 3 : width - 3 : 5]
    z = fi.depth[v, u].astype(np.float64)
    keep = (z > 0) & (z < max_depth)
    u, v, z = u[keep], v[keep], z[keep]
    points = np.linalg.inv(K) @ np.stack([u, v, np.ones_like(u)]) * z
    T = np.linalg.inv(poses[j]) @ poses[i]
    moved = T[:3, :3] @ points + T[:3, 3:]
    uj, vj = (K @ moved)[:2] / moved[2]
    inside = (moved[2] > 0.1) & (uj > 1) & (uj < width - 2) & (vj > 1) & (vj < height - 2)
    inverse = np.divide(1.0, fj.depth, out=np.zeros_like(fj.depth), where=fj.depth > 0)
    sampled = bilinear(inverse, uj[inside], vj[inside])
    predicted = moved[2][inside]
    error = np.abs(1.0 / np.maximum(sampled, 1e-9) - predicted) / predicted
    photometric = np.abs(grey(fi.image)[v[inside], u[inside]] - bilinear(grey(fj.image), uj[inside], vj[inside]))
    return error, photometric


@pytest.mark.parametrize(("scene", "i", "j"), [("urban", 0, 2), ("urban", 6, 4), ("indoor", 0, 12), ("indoor", 20, 9)])
def test_depth_and_poses_agree_between_frames(scene: str, i: int, j: int) -> None:
    """Back-project frame i with its depth and ground-truth pose, project into frame j: the
    depth there is the moved point's z (1 %) and the colour matches."""
    seq = rgbd(scene, 21)
    error, photometric = reprojection(seq, i, j, seq.groundtruth.matrices)
    assert len(error) > 2000
    good = error < 0.01
    assert good.mean() > 0.9  # the rest: occlusions and depth edges
    assert np.median(photometric[good]) < 3.0 and np.percentile(photometric[good], 75) < 8.0
    wrong = seq.groundtruth.matrices.copy()
    wrong[j] = seq.groundtruth.matrices[j + 5 if j + 5 < len(seq) else j - 5]
    assert (reprojection(seq, i, j, wrong)[0] < 0.01).mean() < 0.5  # the check can fail


@pytest.mark.parametrize("scene", SCENES)
def test_right_image_is_left_image_shifted_by_disparity(scene: str) -> None:
    """Left pixel (u, v) at depth Z appears in the right image at u - fx * b / Z."""
    stereo = open_dataset("synthetic", scene=scene, frames=3, sensor="stereo")
    depth = rgbd(scene, 3)[1].depth
    left, right = grey(stereo[1].image), grey(stereo[1].right)
    v, u = np.mgrid[2 : depth.shape[0] - 2 : 3, 2 : depth.shape[1] - 2 : 3]
    z = depth[v, u]
    u_right = u - stereo.camera.fx * stereo.camera.baseline_m / np.where(z > 0, z, np.inf)
    keep = (z > 0) & (u_right > 1)
    target = left[v[keep], u[keep]]
    at_disparity = np.abs(target - bilinear(right, u_right[keep], v[keep].astype(float)))
    at_zero = np.abs(target - right[v[keep], u[keep]])
    assert np.median(at_disparity) < 1.5 and np.mean(at_disparity < 8) > 0.9
    assert np.mean(at_zero) > 3 * np.mean(at_disparity)


@pytest.mark.parametrize("scene", SCENES)
def test_orb_finds_features_everywhere_but_in_the_sky(scene: str) -> None:
    """8 x 6 grid: ORB (2000 features) hits >= 75 % of the cells without sky (>= 70 % in every
    frame; the shaded side of the urban street holds fewer, as KITTI's shade does) and no cell that is all sky; no feature lies in the sky farther than 8 px from
    structure (the lens blur's reach, 3 px, plus ORB's coarse pyramid levels)."""
    seq = rgbd(scene, 31)
    coverage = []
    for frame in (seq[0], seq[15], seq[30]):
        keypoints = cv2.ORB_create(2000).detect(cv2.cvtColor(frame.image, cv2.COLOR_RGB2GRAY), None)
        xy = np.array([k.pt for k in keypoints])
        height, width = frame.depth.shape
        rows, cols = (xy[:, 1] * 6 // height).astype(int), (xy[:, 0] * 8 // width).astype(int)
        counts = np.zeros((6, 8), int)
        np.add.at(counts, (rows, cols), 1)
        sky = frame.depth == 0
        cells = [[sky[r * height // 6 : (r + 1) * height // 6, c * width // 8 : (c + 1) * width // 8] for c in range(8)] for r in range(6)]
        sky_share = np.array([[cell.mean() for cell in row] for row in cells])
        assert counts[sky_share == 1.0].sum() == 0
        structure = cv2.dilate((~sky).astype(np.uint8), np.ones((17, 17), np.uint8)).astype(bool)
        assert structure[xy[:, 1].astype(int), xy[:, 0].astype(int)].all()
        coverage.append((counts[sky_share < 0.1] > 0).mean())
    assert min(coverage) >= 0.7 and np.mean(coverage) >= 0.75, coverage
    if scene == "urban":
        assert (seq[0].depth == 0).mean() > 0.03  # there is a sky
    else:
        assert (seq[0].depth > 0).all()  # a closed room


def test_sky_is_smooth_overexposed_and_without_depth() -> None:
    """The exposure is set for the sunlit street, so the sky is near white and mostly clipped
    (as KITTI's); away from structure (the lens blur reaches 3 px) it has no edges."""
    frame = rgbd("urban", 1)[0]
    sky = cv2.erode((frame.depth == 0).astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    image = grey(frame.image)
    gradient = np.abs(cv2.Sobel(image, cv2.CV_64F, 1, 0)) + np.abs(cv2.Sobel(image, cv2.CV_64F, 0, 1))
    assert sky.sum() > 5000 and gradient[sky].max() <= 16  # 8-bit steps of a smooth ramp
    assert np.median(image[sky]) >= 250 and image[sky].min() >= 200


def test_sunlight_is_ambient_plus_the_cosine_towards_the_sun() -> None:
    light = sun_light((0.0, -1.0, -1.0), sun=1.0, ambient=0.1)  # up and towards -z, 45 degrees
    cos45 = np.sqrt(0.5)
    assert light == pytest.approx((0.1, 0.1, 0.1 + cos45, 0.1, 0.1 + cos45, 0.1))  # -x +x -y +y -z +z


def test_the_urban_street_is_lit_by_face_and_blurred_by_the_lens() -> None:
    """Unblurred, every lit pixel is the unlit texture times its face's sRGB gain
    ``E ** (1 / 2.2)`` (clipped): the shaded side at 0.04 of the exposure's white is 0.23 as
    bright; with the lens, the frame is the unblurred one through a Gaussian of 0.8 px."""
    world = WORLDS["urban"](0)
    pose = world.pose(1.0)
    stage = world.stage(pose[:3, 3])
    sharp = Renderer(world.camera("mono"), world.atlas)
    unlit = sharp.render(Stage(stage.groups, sky_tile=stage.sky_tile), pose)[0].astype(np.float64)
    lit = sharp.render(Stage(stage.groups, sky_tile=stage.sky_tile, light=stage.light, sky_light=stage.sky_light), pose)[0]
    gains = np.asarray(stage.light) ** (1 / 2.2)
    usable = (unlit > 40) & (unlit < 200) & (lit < 250)
    ratio = lit[usable] / unlit[usable]
    near = np.min(np.abs(ratio[:, None] / gains[None, :] - 1.0), axis=1)
    assert np.mean(near < 0.03) > 0.97  # the rest: 8-bit rounding of dark texels
    assert gains.min() == pytest.approx(0.04 ** (1 / 2.2)) and gains.max() < 1.0
    assert np.mean(np.abs(ratio - gains.min()) < 0.02) > 0.1  # the shaded side: 13 % of these pixels
    blurred = world.renderer.render(stage, pose)[0]
    expected = cv2.GaussianBlur(sharp.render(stage, pose)[0], (0, 0), 0.8)
    np.testing.assert_array_equal(blurred, expected)


def test_atlas_levels_are_box_filtered_and_gutters_wrap() -> None:
    atlas = WORLDS["indoor"](0).atlas
    base = atlas.tile("poster0").astype(np.float64)
    half = base.reshape(128, 2, 128, 2, 3).mean(axis=(1, 3))
    assert np.abs(atlas.tile("poster0", 1) - half).max() <= 1.0
    x0, y0 = (int(v) for v in atlas.origin[atlas.index("poster0")])
    np.testing.assert_array_equal(atlas.image[y0 - 1, x0 : x0 + 256], atlas.image[y0 + 255, x0 : x0 + 256])
    np.testing.assert_array_equal(atlas.image[y0 : y0 + 256, x0 + 256], atlas.image[y0 : y0 + 256, x0])


def test_renderer_depth_of_planes_is_exact() -> None:
    """A wall 3 m ahead and a floor 1.5 m below a level camera: Z = 3 and Z = fy * 1.5 / (v - cy)."""
    world = WORLDS["indoor"](0)
    b = BoxBuilder()
    b.add((-1.0, -1.0, 3.0), (1.0, 0.5, 3.5), {"-z": (0, 128, 128)})
    b.add((-20.0, 1.5, 0.5), (20.0, 1.6, 60.0), {"-y": (1, 128, 128)})
    renderer = Renderer(world.camera("mono"), world.atlas)
    _, depth = renderer.render(Stage(groups=(b.build(),)), np.eye(4))
    cam = world.camera("mono")
    wall = np.zeros(depth.shape, bool)
    u0, u1 = cam.cx - cam.fx / 3.0, cam.cx + cam.fx / 3.0
    v0, v1 = cam.cy - cam.fy / 3.0, cam.cy + cam.fy * 0.5 / 3.0
    wall[int(np.ceil(v0)) : int(np.floor(v1)) + 1, int(np.ceil(u0)) : int(np.floor(u1)) + 1] = True
    np.testing.assert_allclose(depth[wall], 3.0, rtol=1e-5)
    drawn = np.abs(depth - 3.0) < 1e-4
    assert (drawn & ~wall).sum() <= 2 * (wall.shape[0] + wall.shape[1])  # half-pixel silhouette
    rows = np.arange(int(v1) + 2, depth.shape[0])
    expected = cam.fy * 1.5 / (rows - cam.cy)
    np.testing.assert_allclose(depth[rows, 20], expected, rtol=1e-5)


def test_renderer_matches_brute_force_ray_casting_of_boxes() -> None:
    """Painter's order and analytic depth agree with per-pixel ray/box intersection."""
    world = WORLDS["indoor"](0)
    rng = np.random.default_rng(5)
    b = BoxBuilder()
    lows, highs = [], []
    for gx in range(4):
        for gz in range(3):
            lo = np.array([gx * 1.5 - 3.0, rng.uniform(-1.5, 0.5), 2.0 + gz * 1.5]) + rng.uniform(0, 0.3, 3)
            hi = lo + rng.uniform(0.3, 1.1, 3)
            b.add(lo, hi, {name: (int(rng.integers(5)), 128, 128) for name in ("-x", "+x", "-y", "+y", "-z", "+z")})
            lows.append(lo)
            highs.append(hi)
    cam = world.camera("mono")
    pose = np.eye(4)
    pose[:3, 3] = (0.2, -0.4, -0.5)
    _, depth = Renderer(cam, world.atlas).render(Stage(groups=(b.build(),)), pose)
    v, u = np.mgrid[0 : cam.height : 4, 0 : cam.width : 4]
    rays = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones(u.shape)], axis=-1)
    best = np.full(u.shape, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for lo, hi in zip(lows, highs):
            t0, t1 = (lo - pose[:3, 3]) / rays, (hi - pose[:3, 3]) / rays
            near, far = np.minimum(t0, t1).max(axis=-1), np.maximum(t0, t1).min(axis=-1)
            hit = (near <= far) & (near > 0)
            best = np.where(hit & (near < best), near, best)
    expected = np.where(np.isfinite(best), best, 0.0)
    agree = np.abs(depth[v, u] - expected) <= 1e-4 * np.maximum(expected, 1.0)
    assert (expected > 0).mean() > 0.2 and agree.mean() > 0.98
