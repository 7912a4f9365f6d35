"""Fog: Koschmieder's contrast at the visibility distance in linear light, transmission
``exp(-beta r)``, the atmospheric light fixed from the first frame, and heterogeneous patches
(seeded gradient noise) fixed in the world and the same in both eyes, on the synthetic urban world."""

from __future__ import annotations

import numpy as np
import pytest
from weather_scenes import linear, ready, urban

from sal_adapters import Sequence
from sal_modules.colour import srgb_decode
from sal_modules.depth import NativeDepth
from sal_modules.weather.fog import (
    Fog,
    estimate_atmospheric_light,
    ray_lengths,
)
from sal_modules.weather.noise import GradientNoise

KOSCHMIEDER = 3.912
#: numpy >= 2.0 names it trapezoid; 1.26 (the lowest supported) only has trapz
_trapezoid = getattr(np, "trapezoid", None) or np.trapz


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
    seq = urban(11)
    lookup = NativeDepth().lookup(seq)
    index = seq.records[10].index
    depth = lookup(index, "left")
    pose = seq.groundtruth.matrices[10]
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
