"""Motion and timing modules: motion_blur, rolling_shutter, stereo_desync.

Physics is checked against closed forms (streak length of a point, shear of a panning
image) and against the synthetic world's renderer (frames rendered at the exact times a
blurred, rolling or late camera would see), then on the real KITTI 07 and EuRoC excerpts.
"""

from __future__ import annotations

import warnings
from functools import cache, partial

import cv2
import numpy as np
import pytest

from sal_adapters import Sequence, open_dataset
from sal_adapters.camera import Camera
from sal_adapters.sequence import FrameRecord
from sal_adapters.synthetic import make_world
from sal_modules import ModuleContext, ModuleError, create, perturb
from sal_modules.depth import DepthProvider


@cache
def urban(frames: int = 4, sensor: str = "stereo") -> Sequence:
    return open_dataset("synthetic", scene="urban", frames=frames, sensor=sensor)


def mad(a: np.ndarray, b: np.ndarray) -> float:
    """Mean absolute difference (grey levels)."""
    return float(np.abs(a.astype(np.float32) - b.astype(np.float32)).mean())


def render_urban(t: float, offset: np.ndarray | None = None, right: bool = False) -> np.ndarray:
    """The urban world (seed 0) seen at time ``t`` (s), the camera moved by ``offset`` (4x4,
    in its own frame) and optionally from the right camera."""
    world = make_world("urban", 0)
    pose = world.pose(t)
    if right:
        pose = pose @ world.T_left_right
    if offset is not None:
        pose = pose @ offset
    rgb, _ = world.renderer.render(world.stage(pose[:3, 3]), pose)
    return rgb


def single_frame(image: np.ndarray, camera: Camera) -> Sequence:
    return Sequence(
        kind="synthetic",
        name="probe",
        camera=camera,
        sensor="mono",
        fps=10.0,
        records=[FrameRecord(index=0, timestamp=0.0, stem="000000", image=lambda: image)],
    )


def blur_once(image: np.ndarray, depth: np.ndarray, camera: Camera, **params: float) -> np.ndarray:
    """``motion_blur`` through the bare contract on one image with a given depth map."""
    module = create("motion_blur", **params)
    module.setup(ModuleContext(sequence=single_frame(image, camera), depth=lambda index, stream: depth))
    return module.apply(image, depth, 0, "left")


# -- motion_blur -----------------------------------------------------------------------------

PROBE = Camera(fx=300.0, fy=300.0, cx=100.0, cy=80.0, width=480, height=360)


@pytest.mark.parametrize(
    ("speed_kmh", "exposure_ms", "depth_m", "offset"),
    [
        (36.0, 50.0, 5.0, (200, 0)),
        (72.0, 40.0, 12.0, (300, 0)),
        (50.0, 30.0, 4.0, (0, 180)),
        (54.0, 50.0, 6.0, (300, 0)),
        (30.0, 30.0, 8.0, (300, 0)),
    ],
    ids=["22px", "21px-far", "21px-vertical", "43px", "10px"],
)
def test_motion_blur_smears_a_point_over_the_predicted_segment_with_box_weights(speed_kmh, exposure_ms, depth_m, offset):
    """A bright point at p on a wall at depth Z streaks from p to c + (p - c) Z / (Z - dz):
    length |p - c| dz / (Z - dz), with uniform brightness (box weights, not triangular)."""
    image = np.zeros((PROBE.height, PROBE.width, 3), np.uint8)
    px, py = int(PROBE.cx) + offset[0], int(PROBE.cy) + offset[1]
    image[py, px] = 255
    depth = np.full(image.shape[:2], depth_m, np.float32)
    out = blur_once(image, depth, PROBE, speed_kmh=speed_kmh, exposure_ms=exposure_ms)[..., 0].astype(np.float32)
    dz = speed_kmh / 3.6 * exposure_ms / 1000.0
    predicted = np.hypot(*offset) * dz / (depth_m - dz)
    profile = out[py, px:] if offset[1] == 0 else out[py:, px]  # along the radial line, outward
    plateau = float(np.median(profile[profile > 0][: int(predicted)]))
    lit = np.nonzero(profile >= plateau / 2)[0]
    assert lit[0] == 0 and np.all(np.diff(lit) == 1)  # one segment that starts at the point
    assert lit[-1] == pytest.approx(predicted, abs=1.0)  # and ends where the point is at the end of the exposure
    interior = profile[1 : int(predicted) - 1]
    assert interior.max() <= 1.35 * interior.min()  # flat: a triangular profile peaks at twice its flanks
    assert profile[: int(predicted) + 3].sum() == pytest.approx(255.0 * (1 + dz / depth_m / 2), rel=0.1)  # light is kept


def test_motion_blur_at_zero_speed_is_the_identity_and_any_speed_changes_the_image():
    clean = urban(2)
    assert np.array_equal(perturb(clean, create("motion_blur", speed_kmh=0.0), seed=1)[1].image, clean[1].image)
    slow = perturb(clean, create("motion_blur", speed_kmh=1.0, exposure_ms=10.0), seed=1)[1].image
    assert not np.array_equal(slow, clean[1].image)  # 2.8 mm of travel: no silent no-op for small blur


def test_motion_blur_grows_with_speed_and_with_exposure():
    clean = urban(2)
    module = create("motion_blur")

    def damage(**params: float) -> float:
        return mad(perturb(clean, module.with_params(**params), seed=1)[1].image, clean[1].image)

    by_speed = [damage(speed_kmh=v, exposure_ms=20.0) for v in (5.0, 20.0, 60.0, 150.0, 400.0)]
    by_exposure = [damage(speed_kmh=50.0, exposure_ms=t) for t in (1.0, 5.0, 20.0, 80.0, 300.0)]
    assert all(b > a for a, b in zip(by_speed, by_speed[1:])), by_speed
    assert all(b > a for a, b in zip(by_exposure, by_exposure[1:])), by_exposure


def test_motion_blur_leaves_the_sky_alone_and_blurs_near_things_most():
    clean = urban(2)
    depth = clean[1].depth
    out = perturb(clean, create("motion_blur", speed_kmh=80.0, exposure_ms=30.0), seed=1)[1].image
    sky = depth == 0
    assert sky.mean() > 0.01
    assert np.array_equal(out[sky], clean[1].image[sky])
    change = np.abs(out.astype(np.float32) - clean[1].image).mean(axis=2)
    near, far = (depth > 0) & (depth < 8), depth > 40
    assert change[near].mean() > 3 * change[far].mean()


def test_motion_blur_matches_the_average_of_frames_rendered_along_the_exposure():
    """Ground truth: the urban world rendered from 16 camera positions spread over dz."""
    clean = urban(2)
    travel_m = 100.0 / 3.6 * 0.050  # 100 km/h for 50 ms
    steps = 16
    truth = np.zeros(clean[1].image.shape, np.float64)
    for i in range(steps):
        offset = np.eye(4)
        offset[2, 3] = (i + 0.5) / steps * travel_m
        truth += render_urban(1 / clean.fps, offset)
    truth /= steps
    out = perturb(clean, create("motion_blur", speed_kmh=100.0, exposure_ms=50.0), seed=1)[1].image
    assert mad(clean[1].image, truth) > 10  # 13.3 measured (a smooth street: fewer, softer edges to smear)
    # 0.19 measured; a streak 25 % too short or too long gives 0.27 or 0.31
    assert mad(out, truth) < 0.23 * mad(clean[1].image, truth)


class GroundPlane(DepthProvider):
    """KITTI has no depth: a flat road 1.65 m under the camera, nothing (0) above the horizon."""

    name = "ground_plane"

    def caches(self, stream: str) -> bool:
        return False

    def unavailable(self, sequence: Sequence) -> str | None:
        return None

    def compute(self, sequence: Sequence, position: int, stream: str) -> np.ndarray:
        camera = sequence.camera
        below = np.arange(camera.height, dtype=np.float32)[:, None] - np.float32(camera.cy)
        depth = np.where(below > 2, camera.fy * 1.65 / np.maximum(below, 1.0), 0.0).astype(np.float32)
        return np.repeat(depth, camera.width, axis=1)


@pytest.fixture(scope="module")
def kitti07(shared_data) -> Sequence:
    return open_dataset("kitti", shared_data / "kitti" / "sequences" / "07").select(range(40, 46))


@pytest.fixture(scope="module")
def euroc(shared_data) -> Sequence:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # cam1/data.csv lists 4 missing files (the adapter's tests check that)
        return open_dataset("euroc", shared_data / "euroc" / "V1_01_easy_micro", stereo=True).select(range(14, 20))  # it moves most here


def test_motion_blur_on_real_kitti_blurs_the_road_and_keeps_what_has_no_depth(kitti07):
    out = perturb(kitti07, create("motion_blur", speed_kmh=60.0, exposure_ms=30.0), depth=GroundPlane())
    clean, blurred = kitti07[2].image, out[2].image
    horizon = int(kitti07.camera.cy) + 2
    assert np.array_equal(blurred[:horizon], clean[:horizon])
    assert mad(blurred[-60:], clean[-60:]) > 3  # the road near the car streaks
    assert np.array_equal(blurred[..., 0], blurred[..., 2])  # grey stays grey


# -- rolling_shutter -------------------------------------------------------------------------


def panning(shift_px: int, frames: int = 4, fps: float = 10.0, size: tuple[int, int] = (240, 320)) -> Sequence:
    """A mono sequence whose image moves right by ``shift_px`` per frame (a rolled texture)."""
    h, w = size
    noise = np.random.default_rng(7).uniform(0, 255, (h, w)).astype(np.float32)
    texture = cv2.normalize(cv2.GaussianBlur(noise, (0, 0), 2.5), None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    rgb = np.repeat(texture[..., None], 3, axis=2)
    camera = Camera(fx=300.0, fy=300.0, cx=w / 2, cy=h / 2, width=w, height=h)
    records = [
        FrameRecord(index=i, timestamp=i / fps, stem=f"{i:06d}", image=partial(np.roll, rgb, i * shift_px, 1)) for i in range(frames)
    ]
    return Sequence(kind="synthetic", name=f"panning-{shift_px}px", camera=camera, sensor="mono", fps=fps, records=records)


def band_shift(clean: np.ndarray, out: np.ndarray, rows: slice, margin: int = 20) -> float:
    """Horizontal shift d (px) with ``out(x) ~ clean(x - d)`` over a band of rows (Gauss-Newton
    on the grey levels, borders left out)."""
    reference = clean[rows, :, 0].astype(np.float32)
    target = out[rows, margin:-margin, 0].astype(np.float32)
    xs = np.arange(margin, clean.shape[1] - margin, dtype=np.float32)
    grid_x, grid_y = np.meshgrid(xs, np.arange(reference.shape[0], dtype=np.float32))
    d = 0.0
    for _ in range(20):
        shifted = cv2.remap(reference, grid_x - np.float32(d), grid_y, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
        gradient = np.gradient(shifted, axis=1)
        d -= float(np.sum((target - shifted) * gradient) / np.sum(gradient * gradient))
    return d


def test_rolling_shutter_with_zero_readout_is_the_identity():
    clean = urban(3)
    out = perturb(clean, create("rolling_shutter", readout_ms=0.0))
    assert np.array_equal(out[1].image, clean[1].image) and np.array_equal(out[1].right, clean[1].right)


@pytest.mark.parametrize("readout_ms", [50.0, 100.0, 200.0])
def test_rolling_shutter_shears_a_panning_image_in_proportion_to_readout(readout_ms):
    """Image velocity v = 8 px per frame at 10 Hz = 80 px/s: row r is displaced by
    v (r/H - 1/2) readout, so the top band moves left and the bottom band right."""
    clean = panning(8)
    out = perturb(clean, create("rolling_shutter", readout_ms=readout_ms))
    h = clean.camera.height
    for position in (0, 1, 3):  # first, middle and last frame (one neighbour at the ends)
        for rows in (slice(0, h // 8), slice(7 * h // 8, h)):
            expected = 80.0 * float(np.mean(np.arange(h)[rows] / h - 0.5)) * readout_ms / 1000.0
            assert band_shift(clean[position].image, out[position].image, rows) == pytest.approx(expected, abs=0.3)


@pytest.mark.parametrize("stream", ["left", "right"])
def test_rolling_shutter_matches_rows_rendered_at_their_own_times(stream):
    """Ground truth: the urban world rendered band by band at each band's exposure time."""
    clean = urban(3)
    readout, bands, h = 100.0, 24, clean.camera.height
    image_of = (lambda frame: frame.image) if stream == "left" else (lambda frame: frame.right)
    truth = np.empty_like(image_of(clean[1]))
    for b in range(bands):
        rows = slice(b * h // bands, (b + 1) * h // bands)
        t = 1 / clean.fps + (np.mean(np.arange(h)[rows]) / h - 0.5) * readout / 1000.0
        truth[rows] = render_urban(t, right=stream == "right")[rows]
    baseline = mad(image_of(clean[1]), truth)
    assert baseline > 4  # 6.1 measured (4 m/s: 0.4 m of travel over the readout)
    for motion, share in (("poses", 0.38), ("flow", 0.5)):  # measured 0.28-0.33 and 0.41-0.44
        out = perturb(clean, create("rolling_shutter", readout_ms=readout, motion=motion))
        assert mad(image_of(out[1]), truth) < share * baseline, motion


def test_rolling_shutter_picks_poses_with_depth_else_flow_and_says_what_poses_need():
    context = ModuleContext(sequence=urban(3))
    module = create("rolling_shutter")
    module.setup(context)
    assert module.uses_poses  # synthetic: per-frame ground truth and native depth
    mono = panning(4)
    module.setup(ModuleContext(sequence=mono))
    assert not module.uses_poses
    with pytest.raises(ModuleError, match=r"rolling_shutter: motion='poses' needs per-frame ground-truth poses and depth"):
        create("rolling_shutter", motion="poses").setup(ModuleContext(sequence=mono))
    with pytest.raises(ModuleError, match="at least 2 frames"):
        module.setup(ModuleContext(sequence=mono.select([0])))


def test_rolling_shutter_grows_with_readout_on_real_kitti_and_euroc(kitti07, euroc):
    for sequence in (kitti07, euroc):
        damage = [mad(perturb(sequence, create("rolling_shutter", readout_ms=r))[2].image, sequence[2].image) for r in (50.0, 100.0, 200.0)]
        assert 0 < damage[0] < damage[1] < damage[2], (sequence.name, damage)
    out = perturb(euroc, create("rolling_shutter", readout_ms=150.0))[2]
    assert out.right.shape == euroc[2].right.shape and not np.array_equal(out.right, euroc[2].right)


# -- stereo_desync ---------------------------------------------------------------------------


def test_stereo_desync_with_zero_delay_is_the_identity():
    clean = urban(3)
    out = perturb(clean, create("stereo_desync", delay_ms=0.0))
    for k in range(3):
        assert np.array_equal(out[k].image, clean[k].image) and np.array_equal(out[k].right, clean[k].right)


def test_stereo_desync_by_one_frame_period_gives_the_next_right_frame_and_keeps_the_left():
    clean = urban(4)
    out = perturb(clean, create("stereo_desync", delay_ms=100.0))  # 10 Hz
    for k in range(3):
        assert np.array_equal(out[k].right, clean[k + 1].right)
        assert np.array_equal(out[k].image, clean[k].image)
    assert not np.array_equal(out[3].right, clean[3].right)  # past the end: extrapolated motion
    assert np.array_equal(out.timestamps, clean.timestamps)


@pytest.mark.parametrize("delay_ms", [30.0, 50.0, 170.0])
def test_stereo_desync_between_frames_matches_the_right_camera_rendered_late(delay_ms):
    clean = urban(4)
    truth = render_urban(1 / clean.fps + delay_ms / 1000.0, right=True)
    out = perturb(clean, create("stereo_desync", delay_ms=delay_ms))[1]
    before = int(np.floor(1 + delay_ms / 100.0))  # the clean right frames around the capture time
    nearest_frame = min(mad(clean[before].right, truth), mad(clean[before + 1].right, truth))
    assert mad(out.right, truth) < 0.6 * nearest_frame
    assert np.array_equal(out.image, clean[1].image)


@pytest.mark.parametrize(("scene", "sensor"), [("urban", "mono"), ("indoor", "rgbd")])
def test_stereo_desync_refuses_a_sequence_without_a_right_camera(scene, sensor):
    clean = open_dataset("synthetic", scene=scene, frames=2, sensor=sensor)
    with pytest.raises(ModuleError, match=rf"stereo_desync needs a stereo sequence; .* is {sensor}"):
        perturb(clean, create("stereo_desync"))


def test_stereo_desync_must_come_before_steps_that_change_the_right_image():
    clean = urban(3)
    first = perturb(clean, create("stereo_desync", delay_ms=40.0) >> create("rolling_shutter", readout_ms=50.0))
    assert first[1].right.shape == clean[1].right.shape
    late = perturb(clean, create("rolling_shutter", readout_ms=50.0) >> create("stereo_desync", delay_ms=40.0))
    with pytest.raises(ModuleError, match="put stereo_desync first in the chain"):
        late[1].right


def test_stereo_desync_on_real_euroc_and_kitti(euroc, kitti07):
    one_period = perturb(euroc, create("stereo_desync", delay_ms=50.0))  # 20 Hz, timestamps jitter by 128 ns
    assert np.array_equal(one_period[1].right, euroc[2].right)
    between = perturb(euroc, create("stereo_desync", delay_ms=20.0))[1]
    assert np.array_equal(between.image, euroc[1].image)
    assert mad(between.right, euroc[1].right) > 0 and not np.array_equal(between.right, euroc[2].right)
    with pytest.raises(ModuleError, match="kitti/07' is mono"):
        perturb(kitti07, create("stereo_desync"))
