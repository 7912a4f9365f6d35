"""Weather modules: fog (Koschmieder, heterogeneous patches fixed in the world), rain and snow
(particle sizes, streak geometry, stereo, occlusion, common random numbers), on the synthetic
urban world and on the real KITTI 07 and EuRoC V1_01 excerpts."""

from __future__ import annotations

import warnings
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from sal_adapters import DatasetWarning, Sequence, open_dataset
from sal_modules import ModuleContext, create, perturb
from sal_modules.colour import srgb_decode
from sal_modules.depth import DepthProvider, NativeDepth, select_depth_provider
from sal_modules.weather.fog import (
    Fog,
    estimate_atmospheric_light,
    ray_lengths,
)
from sal_modules.weather.noise import GradientNoise
from sal_modules.weather.precipitation import Particles, Precipitation
from sal_modules.weather.rain import Rain
from sal_modules.weather.snow import Snow

KOSCHMIEDER = 3.912
#: numpy >= 2.0 names it trapezoid; 1.26 (the lowest supported) only has trapz
_trapezoid = getattr(np, "trapezoid", None) or np.trapz


@cache
def urban(frames: int = 3) -> Sequence:
    return open_dataset("synthetic", scene="urban", frames=frames, sensor="stereo")


def ready(module, sequence: Sequence, seed: int = 1, depth=None):  # type: ignore[no-untyped-def]
    """``module`` set up on ``sequence`` as the pipeline would (native depth by default)."""
    module.setup(ModuleContext(sequence=sequence, seed=seed, depth=depth or NativeDepth().lookup(sequence)))
    return module


def linear(image: np.ndarray) -> np.ndarray:
    return srgb_decode(np.asarray(image) / 255.0)


def half_code(code: np.ndarray) -> np.ndarray:
    """Half an sRGB code step around ``code``, in linear radiance (the rounding error)."""
    code = np.asarray(code, dtype=np.float64)
    return 0.5 * (srgb_decode(np.minimum(code + 0.5, 255) / 255) - srgb_decode(np.maximum(code - 0.5, 0) / 255))


# -- fog: Koschmieder --------------------------------------------------------------------------
@pytest.mark.parametrize("airlight", [(0.8, 0.8, 0.8), (0.0, 0.0, 0.0), (0.3, 0.5, 0.9)])
def test_fog_contrast_at_the_visibility_distance_is_two_percent_in_linear_light(airlight) -> None:
    seq = urban(1)
    visibility = 70.0
    fog = ready(Fog(visibility_m=visibility, atmospheric_light=airlight), seq)
    h, w = seq.camera.height, seq.camera.width
    white = (np.arange(w) // 8 % 2 == 0)[None, :].repeat(h, axis=0)
    image = np.where(white[..., None], 255, 0).astype(np.uint8).repeat(3, axis=2)
    depth = (visibility / ray_lengths(seq.camera, (h, w))).astype(np.float32)  # every pixel 70 m away along its ray
    out = fog.apply(image, depth, 0, "left")
    # Koschmieder in linear light, computed independently in float64
    A = srgb_decode(airlight)
    t = np.exp(-KOSCHMIEDER)
    expected = np.where(white[..., None], t + A * (1 - t), A * (1 - t))
    enc = np.where(expected <= 0.0031308, 12.92 * expected, 1.055 * expected ** (1 / 2.4) - 0.055)
    assert np.abs(out.astype(int) - np.rint(255 * enc)).max() == 0
    lin = linear(out)
    contrast = lin[white].mean(axis=0) - lin[~white].mean(axis=0)  # clear contrast: 1 - 0 = 1
    tolerance = half_code(out[white][0]) + half_code(out[~white][0])
    assert np.all(np.abs(contrast - 0.02) <= tolerance + 1e-9), (contrast, tolerance)


def test_fog_changes_nothing_a_millimetre_from_the_lens_and_everything_at_the_sky() -> None:
    seq = urban(1)
    fog = ready(Fog(visibility_m=50.0, atmospheric_light=(1.0, 0.6, 0.0)), seq)
    h, w = seq.camera.height, seq.camera.width
    image = np.random.default_rng(0).integers(0, 256, (h, w, 3), dtype=np.uint8)
    image[0, :256] = np.arange(256)[:, None]  # every code goes through decode, blend, encode
    close = (0.001 / ray_lengths(seq.camera, (h, w))).astype(np.float32)  # 1 mm: 1 - t = 8e-5
    np.testing.assert_array_equal(fog.apply(image, close, 0, "left"), image)
    sky = np.zeros((h, w), np.float32)
    out = fog.apply(image, sky, 0, "left")
    assert np.all(out == np.array([255, 153, 0], np.uint8))  # the given atmospheric light
    finite = ready(Fog(visibility_m=50.0, atmospheric_light=(1.0, 0.6, 0.0), sky_distance_m=10.0), seq)
    partial = finite.apply(image, sky, 0, "left")  # sky 10 m away: t = exp(-3.912 / 5)
    assert 0 < np.abs(partial.astype(int) - image).mean() < np.abs(out.astype(int) - image).mean()


def test_fog_transmission_falls_with_distance_as_exp_minus_beta_r() -> None:
    seq = urban(1)
    fog = ready(Fog(visibility_m=100.0, atmospheric_light=(0.5, 0.5, 0.5)), seq)
    depth = NativeDepth().lookup(seq)(0, "left")
    t = fog.transmission(depth, 0, "left")
    r = depth * ray_lengths(seq.camera, depth.shape)
    valid = depth > 0
    np.testing.assert_allclose(t[valid], np.exp(-KOSCHMIEDER / 100.0 * r[valid]), rtol=1e-4, atol=1e-6)
    assert t[~valid].max() < 1e-30  # sky: infinitely far
    # the Euclidean distance, not the depth: corners are farther than the centre at equal depth
    assert ray_lengths(seq.camera, depth.shape)[0, 0] > 1.2


def test_estimated_atmospheric_light_comes_from_the_first_frame_and_stays_fixed() -> None:
    seq = urban(3)
    lookup = NativeDepth().lookup(seq)
    fog = ready(Fog(visibility_m=30.0), seq)
    first = seq[0]
    np.testing.assert_allclose(fog.airlight, estimate_atmospheric_light(first.image, lookup(first.index, "left")))
    sky_linear = linear(first.image)[lookup(first.index, "left") <= 0]
    # among the brightest sky colours (the dark-channel choice), not the mean sky
    assert fog.airlight.min() > np.percentile(sky_linear.min(axis=1), 90) - 1e-3
    colours = []
    for frame in (seq[0], seq[2]):
        depth = lookup(frame.index, "left")
        out = fog.apply(frame.image, depth, frame.index, "left")
        sky = out[depth <= 0]
        assert len(np.unique(sky, axis=0)) == 1
        colours.append(sky[0])
    np.testing.assert_array_equal(colours[0], colours[1])


# -- fog: heterogeneous ------------------------------------------------------------------------
def test_gradient_noise_is_smooth_zero_mean_unit_deviation_and_seeded() -> None:
    noise = GradientNoise(np.random.default_rng(4))
    points = np.random.default_rng(5).random((200_000, 3)) * 64
    values = noise(points)
    assert abs(values.mean()) < 0.02 and 0.95 < values.std() < 1.05
    step = noise(points[:1000] + 1e-3) - noise(points[:1000])
    assert np.abs(step).max() < 0.05  # smooth: a thousandth of a cell moves it by little
    np.testing.assert_array_equal(GradientNoise(np.random.default_rng(4))(points[:10]), values[:10])
    assert not np.allclose(GradientNoise(np.random.default_rng(6))(points[:10]), values[:10])


def test_heterogeneous_fog_with_zero_heterogeneity_is_the_homogeneous_fog() -> None:
    seq = urban(2)
    lookup = NativeDepth().lookup(seq)
    frame = seq[1]
    depth = lookup(frame.index, "left")
    plain = ready(Fog(visibility_m=50.0), seq).apply(frame.image, depth, frame.index, "left")
    zero = ready(Fog(visibility_m=50.0, heterogeneity=0.0, noise_scale_m=5.0), seq).apply(frame.image, depth, frame.index, "left")
    np.testing.assert_array_equal(plain, zero)
    patchy = ready(Fog(visibility_m=50.0, heterogeneity=0.8, noise_scale_m=5.0), seq)
    assert np.abs(patchy.apply(frame.image, depth, frame.index, "left").astype(int) - plain).mean() > 1.0
    ratio = (
        patchy.optical_depth(depth, frame.index, "left")[depth > 0]
        / ready(Fog(visibility_m=50.0), seq).optical_depth(depth, frame.index, "left")[depth > 0]
    )
    assert 0.85 < ratio.mean() < 1.2 and ratio.std() > 0.05  # patches around the same mean density


def _reference_optical_depth(
    fog: Fog, pose: np.ndarray, sequence: Sequence, depth: np.ndarray, us: np.ndarray, vs: np.ndarray
) -> np.ndarray:
    """beta * integral of the density along each pixel's ray in world coordinates (dense trapezoid)."""
    cam = sequence.camera
    rays = np.stack([(us - cam.cx) / cam.fx, (vs - cam.cy) / cam.fy, np.ones(len(us))], axis=1)
    lengths = np.linalg.norm(rays, axis=1)
    distance = depth[vs, us] * lengths
    s = np.linspace(0.0, 1.0, 1500)[None, :] * distance[:, None]
    world = pose[:3, 3] + s[..., None] * ((rays / lengths[:, None]) @ pose[:3, :3].T)[:, None, :]
    return KOSCHMIEDER / fog.visibility_m * _trapezoid(fog.density(world), s, axis=1)


def test_heterogeneous_fog_patches_are_fixed_in_the_world_frame_to_frame() -> None:
    """The fast optical depth matches a dense integration through the world-fixed density on a
    frame the camera has moved to; ignoring the poses (patches glued to the camera) does not."""
    seq = urban(5)
    lookup = NativeDepth().lookup(seq)
    index = seq.records[4].index
    depth = lookup(index, "left")
    pose = seq.groundtruth.matrices[4]
    assert np.linalg.norm(pose[:3, 3]) > 3.0  # the camera moved several metres
    vs, us = np.nonzero(depth > 0)
    pick = np.random.default_rng(0).choice(len(us), 200, replace=False)
    us, vs = us[pick], vs[pick]
    errors = {}
    for name, sequence in (("world", seq), ("camera", seq.replace(groundtruth=None))):
        fog = ready(Fog(visibility_m=40.0, heterogeneity=1.0, noise_scale_m=5.0), sequence, seed=2)
        reference = _reference_optical_depth(fog, pose, seq, depth, us, vs)
        errors[name] = np.abs(fog.optical_depth(depth, index, "left")[vs, us] / reference - 1.0)
    assert np.median(errors["world"]) < 0.03 and np.percentile(errors["world"], 90) < 0.08, errors["world"]
    assert np.median(errors["camera"]) > 4 * np.median(errors["world"])
    # with poses the same depth map gets other patches at another place; without, the same ones
    fog = ready(Fog(visibility_m=40.0, heterogeneity=1.0, noise_scale_m=5.0), seq, seed=2)
    glued = ready(Fog(visibility_m=40.0, heterogeneity=1.0, noise_scale_m=5.0), seq.replace(groundtruth=None), seed=2)
    first = seq.records[0].index
    valid = depth > 0
    moved = np.abs(fog.optical_depth(depth, index, "left")[valid] - fog.optical_depth(depth, first, "left")[valid])
    assert moved.mean() > 0.1
    np.testing.assert_array_equal(glued.optical_depth(depth, index, "left"), glued.optical_depth(depth, first, "left"))


def test_heterogeneous_fog_is_the_same_fog_in_both_eyes() -> None:
    """The right camera traces its rays from its own centre through the same world density."""
    seq = urban(2)
    lookup = NativeDepth().lookup(seq)
    index = seq.records[1].index
    fog = ready(Fog(visibility_m=40.0, heterogeneity=1.0, noise_scale_m=5.0), seq, seed=2)
    depth = lookup(index, "right")
    pose = seq.groundtruth.matrices[1] @ seq.camera.T_lr
    vs, us = np.nonzero(depth > 0)
    pick = np.random.default_rng(1).choice(len(us), 150, replace=False)
    reference = _reference_optical_depth(fog, pose, seq, depth, us[pick], vs[pick])
    error = np.abs(fog.optical_depth(depth, index, "right")[vs[pick], us[pick]] / reference - 1.0)
    assert np.median(error) < 0.03


# -- rain and snow: particle physics ------------------------------------------------------------
def test_rain_extinction_matches_the_empirical_law_and_snow_hides_more() -> None:
    rain, snow = Rain(), Snow()
    for rate in (1.0, 10.0, 100.0, 300.0):
        empirical = 0.312 * rate**0.67 / 1000.0  # km^-1 -> m^-1
        assert rain.extinction(rate) == pytest.approx(empirical, rel=0.2)
    for rate in (0.5, 2.0, 10.0):
        assert snow.extinction(rate) > 5 * rain.extinction(rate)
    assert snow.extinction(1.0) < snow.extinction(5.0) < snow.extinction(20.0)


def test_fall_speeds_and_size_distributions() -> None:
    rain, snow = Rain(), Snow()
    np.testing.assert_allclose(rain.fall_speed(np.array([1.0, 2.0, 5.0])), 9.65 - 10.3 * np.exp(-0.6 * np.array([1.0, 2.0, 5.0])))
    assert np.all((snow.fall_speed(np.array([0.3, 1.0, 3.0])) > 0.8) & (snow.fall_speed(np.array([0.3, 1.0, 3.0])) < 1.5))
    assert rain.size_distribution(25.0) == pytest.approx((8000.0, 4.1 * 25.0**-0.21))
    assert snow.size_distribution(2.0) == pytest.approx((3800.0 * 2.0**-0.87, 2.55 * 2.0**-0.48))
    # the rank <-> size map is the inverse of the number of particles above a size
    y = rain.number_above(25.0, np.array([0.5, 1.0, 3.0]))
    np.testing.assert_allclose(rain.diameter_of_rank(25.0, y), [0.5, 1.0, 3.0], rtol=1e-9)


def test_rain_drops_are_nested_across_intensities_and_grow() -> None:
    seq = urban(2)
    weak, strong = (ready(Rain(intensity_mm_h=r), seq, seed=3) for r in (50.0, 200.0))
    a, b = weak.particles(1), strong.particles(1)
    assert 500 < len(a) < len(b)
    assert np.isin(a.ids, b.ids).all()
    order_a, order_b = np.argsort(a.ids), np.argsort(b.ids)
    shared = np.isin(b.ids[order_b], a.ids)
    np.testing.assert_array_equal(a.position[order_a], b.position[order_b][shared])
    assert np.all(b.diameter_mm[order_b][shared] > a.diameter_mm[order_a])
    depth = NativeDepth().lookup(seq)(1, "left")
    alpha_weak, alpha_strong = weak.coverage(a, depth, "left"), strong.coverage(b, depth, "left")
    for threshold in (0.002, 0.02):
        covered = alpha_weak > threshold
        assert covered.sum() > 1000 and np.all(alpha_strong[covered] > threshold)


def test_snow_flakes_large_enough_to_see_are_nested_across_intensities() -> None:
    seq = urban(2)
    weak, strong = (ready(Snow(intensity_mm_h=r), seq, seed=3) for r in (1.0, 5.0))
    a, b = weak.particles(1), strong.particles(1)
    assert 200 < len(a) < len(b)
    assert np.isin(a.ids, b.ids).mean() > 0.99


@pytest.mark.parametrize(("name", "rates"), [("rain", (5.0, 25.0, 100.0, 300.0)), ("snow", (0.3, 1.0, 4.0, 15.0))])
def test_heavier_precipitation_changes_the_image_more(name: str, rates) -> None:
    seq = urban(2)
    frame = seq[1]
    depth = NativeDepth().lookup(seq)(frame.index, "left")
    diffs = []
    for rate in rates:
        module = ready(create(name, intensity_mm_h=rate), seq)
        diffs.append(np.abs(module.apply(frame.image, depth, frame.index, "left").astype(np.float32) - frame.image).mean())
    assert all(b > a for a, b in zip(diffs, diffs[1:])), diffs


@pytest.mark.parametrize("name", ["rain", "snow"])
def test_same_seed_identical_bytes_other_seed_other_particles(name: str) -> None:
    seq = urban(2)
    module = create(name)
    a, b, c = (perturb(seq, module, seed=s) for s in (7, 7, 8))
    for x, y, z in zip(a, b, c):
        np.testing.assert_array_equal(x.image, y.image)
        np.testing.assert_array_equal(x.right, y.right)
        assert not np.array_equal(x.image, z.image)


# -- rain and snow: one particle at a known place -----------------------------------------------
def one_particle(z: float, diameter_mm: float, x: float = 0.0, y: float = 0.0) -> Particles:
    return Particles(ids=np.zeros(1, np.int64), position=np.array([[x, y, z]]), diameter_mm=np.array([diameter_mm]), drift_mps=np.zeros(1))


def streak_extent(alpha: np.ndarray) -> tuple[float, float, float]:
    """Length (px, rows above half the plateau), centroid column and row of one vertical streak."""
    rows = alpha.sum(axis=1)
    length = float((rows > 0.5 * rows.max()).sum())
    v, u = np.mgrid[: alpha.shape[0], : alpha.shape[1]]
    return length, float((alpha * u).sum() / alpha.sum()), float((alpha * v).sum() / alpha.sum())


@pytest.mark.parametrize("exposure_ms", [5.0, 20.0])
def test_streak_length_is_fall_speed_times_exposure_times_focal_over_depth(exposure_ms: float) -> None:
    seq = urban(1)
    rain = ready(Rain(exposure_ms=exposure_ms, aperture_mm=0.0), seq)
    z, d = 2.0, 3.0
    sky = np.zeros((seq.camera.height, seq.camera.width), np.float32)
    alpha = rain.coverage(one_particle(z, d), sky, "left")
    length, u, v = streak_extent(alpha)
    expected = float(rain.fall_speed(np.array([d]))[0]) * exposure_ms / 1000.0 * seq.camera.fx / z
    assert length == pytest.approx(expected, abs=1.5)
    assert u == pytest.approx(seq.camera.cx, abs=0.5) and v == pytest.approx(seq.camera.cy, abs=0.5)
    # the exposure-integrated coverage is the drop's projected area, whatever the exposure
    width = d / 1000.0 * seq.camera.fx / z
    assert alpha.sum() == pytest.approx(np.pi / 4 * width**2, rel=0.1)


def test_sub_pixel_drops_cover_less_and_snow_streaks_are_short() -> None:
    seq = urban(1)
    sky = np.zeros((seq.camera.height, seq.camera.width), np.float32)
    rain = ready(Rain(aperture_mm=0.0), seq)
    far = rain.coverage(one_particle(6.0, 1.0), sky, "left")
    width = 1e-3 * seq.camera.fx / 6.0
    assert width < 0.2 and far.sum() == pytest.approx(np.pi / 4 * width**2, rel=0.1) and far.max() < 0.01
    snow = ready(Snow(aperture_mm=0.0, exposure_ms=20.0), seq)
    flake, drop = (
        snow.coverage(one_particle(2.0, 1.0), sky, "left"),
        ready(Rain(aperture_mm=0.0, exposure_ms=20.0), seq).coverage(one_particle(2.0, 3.0), sky, "left"),
    )
    assert streak_extent(flake)[0] < 0.25 * streak_extent(drop)[0]
    big = ready(Snow(aperture_mm=0.0), seq).coverage(one_particle(2.0, 2.0), sky, "left")
    assert big.max() > 0.5  # a 7 mm flake at 2 m in 5 ms: a nearly opaque soft dot


def test_wind_tilts_streaks_and_defocus_spreads_near_drops() -> None:
    seq = urban(1)
    sky = np.zeros((seq.camera.height, seq.camera.width), np.float32)
    calm = ready(Rain(aperture_mm=0.0, exposure_ms=20.0), seq).coverage(one_particle(2.0, 3.0), sky, "left")
    windy = ready(Rain(aperture_mm=0.0, exposure_ms=20.0, wind_mps=8.0), seq).coverage(one_particle(2.0, 3.0), sky, "left")
    v, u = np.mgrid[: sky.shape[0], : sky.shape[1]]

    def slope(alpha: np.ndarray) -> float:
        w = alpha / alpha.sum()
        cu, cv = (w * u).sum(), (w * v).sum()
        return float((w * (u - cu) * (v - cv)).sum() / (w * (v - cv) ** 2).sum())  # du/dv

    speed = float(Rain().fall_speed(np.array([3.0]))[0])
    assert abs(slope(calm)) < 0.02 and slope(windy) == pytest.approx(8.0 / speed, rel=0.1)
    sharp = ready(Rain(aperture_mm=0.0), seq).coverage(one_particle(0.3, 2.0), sky, "left")
    blurred = ready(Rain(aperture_mm=4.0), seq).coverage(one_particle(0.3, 2.0), sky, "left")
    assert blurred.max() < 0.6 * sharp.max() and (blurred > 1e-3).sum() > 1.5 * (sharp > 1e-3).sum()
    assert blurred.sum() == pytest.approx(sharp.sum(), rel=0.1)  # defocus spreads, it does not remove


def test_both_eyes_see_the_same_drop_with_the_disparity_of_its_depth() -> None:
    seq = urban(1)
    rain = ready(Rain(aperture_mm=0.0), seq)
    sky = np.zeros((seq.camera.height, seq.camera.width), np.float32)
    for z in (1.5, 4.0):
        _, ul, vl = streak_extent(rain.coverage(one_particle(z, 3.0, x=0.3), sky, "left"))
        _, ur, vr = streak_extent(rain.coverage(one_particle(z, 3.0, x=0.3), sky, "right"))
        assert ul - ur == pytest.approx(seq.camera.fx * seq.camera.baseline_m / z, abs=0.5)
        assert vl == pytest.approx(vr, abs=0.2)
    # and the whole per-frame drop set is drawn once, for both streams
    rain = ready(Rain(), seq)
    assert rain.particles(0) is rain.particles(0)


def test_drops_behind_a_surface_are_hidden() -> None:
    seq = urban(1)
    rain = ready(Rain(aperture_mm=0.0), seq)
    shape = (seq.camera.height, seq.camera.width)
    drop = one_particle(2.0, 3.0)
    assert rain.coverage(drop, np.full(shape, 1.5, np.float32), "left").max() == 0.0
    assert rain.coverage(drop, np.full(shape, 2.5, np.float32), "left").max() > 0.02
    wall = np.full(shape, 50.0, np.float32)
    wall[: int(seq.camera.cy)] = 1.5  # a near surface over the streak's upper half
    split = rain.coverage(drop, wall, "left")
    rows = split.sum(axis=1)
    # hidden rows are 0 but for the far tail of the blur on the row 4 px above the edge
    # (1.2e-07 with OpenCV 5, 1.0e-06 with OpenCV 4.9's kernel); a visible row is > 0.02
    assert rows[: int(seq.camera.cy) - 3].max() <= 1e-5 and rows[int(seq.camera.cy) + 1 :].max() > 0.02  # (2 px of blur)
    # the real drop pool: a surface 1 m away hides every drop behind it
    many = ready(Rain(intensity_mm_h=100.0), seq).particles(0)
    near = rain.coverage(many, np.full(shape, 1.0, np.float32), "left")
    free = rain.coverage(many, np.zeros(shape, np.float32), "left")
    assert 0 < near.sum() < 0.5 * free.sum()


def test_drop_brightness_comes_from_the_scene_and_flakes_are_white() -> None:
    seq = urban(1)
    frame = seq[0]
    shape = (seq.camera.height, seq.camera.width)
    depth = np.full(shape, 100.0, np.float32)
    black = np.zeros(shape + (3,), np.uint8)
    rain, snow = ready(Rain(intensity_mm_h=100.0), seq), ready(Snow(intensity_mm_h=5.0), seq)
    drop = rain.particle_radiance(frame.image, rain.airlight)
    assert np.all(drop > linear(frame.image).reshape(-1, 3).mean(axis=0) - 1e-6)  # brighter than the mean scene (sky half)
    assert np.all(drop < rain.airlight + 1e-6)
    np.testing.assert_allclose(snow.particle_radiance(black, snow.airlight), 0.9 * snow.airlight)
    # on a black background, rain brightens only where drops fall; snow covers more, whiter
    lit_rain = rain.apply(black, depth, 0, "left").astype(int)
    lit_snow = snow.apply(black, depth, 0, "left").astype(int)
    assert lit_snow.max() > 150 and lit_snow.max() > lit_rain.max()


@pytest.mark.parametrize("name", ["rain", "snow"])
def test_particle_pool_stays_small(name: str) -> None:
    """Particles too small or far to see are haze, not drawn: the pool stays small."""
    seq = urban(1)
    module: Precipitation = ready(create(name), seq)  # type: ignore[assignment]
    assert 100 < len(module.particles(0)) < 30_000


# -- real data --------------------------------------------------------------------------------
class FlatWorldDepth(DepthProvider):
    """Depth of a flat road 1.65 m below the camera up to 40 m, and a wall at 40 m above it
    (the KITTI excerpt is monocular: no stereo depth)."""

    name = "test_flat_world"

    def caches(self, stream: str) -> bool:
        return False

    def unavailable(self, sequence: Sequence) -> str | None:
        return None

    def compute(self, sequence: Sequence, position: int, stream: str) -> np.ndarray:
        cam = sequence.camera
        v = np.arange(cam.height, dtype=np.float32)[:, None] - cam.cy
        road = np.where(v > 0, 1.65 * cam.fy / np.maximum(v, 1e-3), np.inf)
        return np.broadcast_to(np.minimum(road, 40.0), (cam.height, cam.width)).astype(np.float32)


@pytest.fixture(scope="module")
def kitti(shared_data: Path) -> Sequence:
    return open_dataset("kitti", shared_data / "kitti" / "sequences" / "07", max_frames=2)


@pytest.fixture(scope="module")
def euroc(shared_data: Path) -> Sequence:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DatasetWarning)  # cam1 lists 4 missing files (known)
        return open_dataset("euroc", shared_data / "euroc" / "V1_01_easy_micro", stereo=True, start=40, max_frames=1)


@pytest.mark.parametrize(
    ("name", "params"), [("fog", {"visibility_m": 40.0}), ("rain", {"intensity_mm_h": 100.0}), ("snow", {"intensity_mm_h": 3.0})]
)
def test_weather_on_real_kitti_frames(kitti: Sequence, name: str, params) -> None:
    out = perturb(kitti, create(name, **params), seed=1, depth=FlatWorldDepth())
    clean = kitti[1].image
    image = out[1].image
    assert image.shape == clean.shape and image.dtype == np.uint8
    assert np.array_equal(image[..., 0], image[..., 2])  # grey in, grey out
    change = np.abs(image.astype(int) - clean)
    far, near = change[: int(kitti.camera.cy)].mean(), change[-60:].mean()
    assert far > near > 0  # the wall at 40 m fades more than the road a few metres away


def test_weather_on_the_real_euroc_stereo_pair_with_stereo_depth(euroc: Sequence) -> None:
    """Unrectified real stereo (rotation between the cameras): depth from semi-global matching,
    and one drop lands in the right image where the calibration projects it."""
    out = perturb(euroc, create("fog", visibility_m=8.0), seed=1, depth="stereo")
    frame, clean = out[0], euroc[0]
    for image, original in ((frame.image, clean.image), (frame.right, clean.right)):
        assert image.shape == original.shape and np.abs(image.astype(int) - original).mean() > 5
    rain = ready(Rain(aperture_mm=0.0), euroc, depth=select_depth_provider(euroc, "stereo").lookup(euroc))
    sky = np.zeros((euroc.camera.height, euroc.camera.width), np.float32)
    point = np.array([0.2, -0.1, 1.5])
    _, ur, vr = streak_extent(rain.coverage(one_particle(point[2], 3.0, x=point[0], y=point[1]), sky, "right"))
    right = euroc.camera.right
    in_right = np.linalg.inv(euroc.camera.T_lr) @ np.append(point, 1.0)
    assert ur == pytest.approx(right.fx * in_right[0] / in_right[2] + right.cx, abs=0.6)
    assert vr == pytest.approx(right.fy * in_right[1] / in_right[2] + right.cy, abs=0.6)
    rainy = perturb(euroc, create("rain", intensity_mm_h=100.0), seed=1, depth="stereo")[0]
    assert np.abs(rainy.right.astype(int) - clean.right).mean() > 0.2
