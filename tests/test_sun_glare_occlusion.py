"""sun_glare sees the sun only through open sky: a facade in front of it hides the disc, the
veil and the ghosts (issue 11, "Physics without depth"); a mono sequence without a depth
source is an error that names the providers."""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from sal_adapters import Sequence, open_dataset
from sal_modules import ModuleContext, ModuleError, create, perturb
from sal_modules.colour import srgb_to_linear
from sal_modules.depth import NativeDepth
from sal_modules.errors import DepthUnavailable
from sal_modules.light.sun_glare import GHOST_FADE_DEG, sky_mask, sun_direction

KLUX = 50.0  # the low sun


@cache
def street() -> Sequence:
    """The synthetic street seen by a stereo pair, with exact depth (0 = sky)."""
    return open_dataset("synthetic", scene="urban", frames=5, sensor="stereo")


def sun_pixel(sequence: Sequence, azimuth_deg: float, elevation_deg: float) -> tuple[float, float]:
    camera = sequence.camera
    d = sun_direction(azimuth_deg, elevation_deg)
    return camera.cx + camera.fx * d[0] / d[2], camera.cy + camera.fy * d[1] / d[2]


def near(shape: tuple[int, int], centre: tuple[float, float], radius: float) -> np.ndarray:
    y, x = np.indices(shape)
    return np.hypot(x - centre[0], y - centre[1]) < radius


def glare_on(sequence: Sequence, **params):  # type: ignore[no-untyped-def]
    module = create("sun_glare", sun_illuminance_klux=KLUX, **params)
    module.setup(ModuleContext(sequence=sequence, seed=0, depth=NativeDepth().lookup(sequence)))
    return module


def test_a_sun_behind_a_facade_leaves_every_frame_as_it_was() -> None:
    clean = street()
    x, y = sun_pixel(clean, 20.0, 8.0)
    for frame in clean:  # precondition: the sun projects onto a near facade in every frame
        assert 0 < frame.depth[round(y), round(x)] < 100.0
    out = perturb(clean, create("sun_glare", sun_illuminance_klux=KLUX, sun_azimuth_deg=20.0, sun_elevation_deg=8.0), seed=0)
    disc = near(clean[0].image.shape[:2], (x, y), 40.0)
    for before, after in zip(clean, out):
        # no disc, no bloom, no ghosts and no veil: an occluded sun sends no light into the lens
        np.testing.assert_array_equal(after.image[disc], before.image[disc])
        np.testing.assert_array_equal(after.image, before.image)
        np.testing.assert_array_equal(after.right, before.right)


def test_a_sun_in_the_sky_draws_its_disc_and_veils_the_frame() -> None:
    clean = street()
    x, y = sun_pixel(clean, 0.0, 8.0)
    out = perturb(clean, create("sun_glare", sun_illuminance_klux=KLUX, sun_azimuth_deg=0.0, sun_elevation_deg=8.0), seed=0)
    disc = near(clean[0].image.shape[:2], (x, y), 2.0)
    for before, after in zip(clean, out):
        assert np.all(before.depth[disc] == 0), "precondition: the sun is in the sky"
        assert np.all(after.image[disc] == 255)
        assert np.abs(after.image.astype(int) - before.image).mean() > 20.0
        assert np.abs(after.right.astype(int) - before.right).mean() > 20.0


def test_a_sun_on_a_roof_edge_shows_only_its_visible_part_and_dims_veil_and_ghosts() -> None:
    clean = street()
    frame = clean[2]
    image, depth = frame.image, frame.depth
    row = 84
    x_edge = int(np.flatnonzero(depth[row] == 0).min())  # the first sky pixel left of the street's gap
    elevation = math.degrees(math.atan((clean.camera.cy - row) / clean.camera.fy))
    azimuth = math.degrees(math.atan((x_edge - clean.camera.cx) / clean.camera.fx))
    module = glare_on(clean, sun_azimuth_deg=azimuth, sun_elevation_deg=elevation)
    visible = module.visibility(depth, frame.index, "left")
    assert 0.2 < visible < 0.9
    out = module.apply(image, depth, frame.index, "left")
    sun = (clean.camera.cx + clean.camera.fx * math.tan(math.radians(azimuth)), float(row))
    disc = near(depth.shape, sun, 2.5)
    assert np.all(out[disc & (depth == 0)] == 255), "the disc shows on the sky pixels"
    # away from the sun (no saturation) the added light is the unoccluded glare times V
    unoccluded = module.glare(frame.index, "left", *depth.shape)
    added = srgb_to_linear(out).astype(np.float64) - srgb_to_linear(image)
    far = ~near(depth.shape, sun, 300.0) & (out < 250).all(axis=2)
    ratio = added[far].sum() / unoccluded[far].sum()
    assert ratio == pytest.approx(visible, rel=0.05)


def test_facade_pixels_inside_the_disc_never_saturate_while_the_sky_beside_them_does() -> None:
    clean = street()
    frame = clean[2]
    depth = frame.depth
    row = 84
    x_edge = int(np.flatnonzero(depth[row] == 0).min())
    elevation = math.degrees(math.atan((clean.camera.cy - row) / clean.camera.fy))
    for x in (x_edge - 1, x_edge + 1):
        azimuth = math.degrees(math.atan((x - clean.camera.cx) / clean.camera.fx))
        module = glare_on(clean, sun_azimuth_deg=azimuth, sun_elevation_deg=elevation, veil_factor=0.0, ghost_reflectance=0.0)
        out = module.apply(frame.image, depth, frame.index, "left")
        lit = (out == 255).all(axis=2) & ~(frame.image == 255).all(axis=2)
        assert lit.any() and not (lit & (depth > 0)).any(), x


def test_depth_beyond_sky_depth_counts_as_sky() -> None:
    clean = street()
    frame = clean[0]
    x, y = sun_pixel(clean, 20.0, 8.0)
    wall = frame.depth[round(y), round(x)]
    behind = glare_on(clean, sun_azimuth_deg=20.0, sun_elevation_deg=8.0, sky_depth_m=float(wall) + 5.0)
    beyond = glare_on(clean, sun_azimuth_deg=20.0, sun_elevation_deg=8.0, sky_depth_m=max(1.0, float(wall) - 5.0))
    assert behind.visibility(frame.depth, frame.index, "left") == 0.0
    assert beyond.visibility(frame.depth, frame.index, "left") == 1.0
    out = beyond.apply(frame.image, frame.depth, frame.index, "left")
    assert np.all(out[round(y), round(x)] == 255)
    depth = np.array([0.0, np.inf, np.nan, 5.0, 999.0, 1000.0, 2e4], np.float32)
    assert sky_mask(depth, 1000.0).tolist() == [True, True, True, False, False, True, True]


def test_a_sun_just_outside_the_image_is_judged_by_the_border_and_far_outside_counts_as_seen() -> None:
    clean = street()
    camera = clean.camera
    shape = (camera.height, camera.width)
    wall, sky = np.full(shape, 10.0, np.float32), np.zeros(shape, np.float32)
    for outside in (0.0, 2.5, 5.0, 20.0):  # deg seen from the principal point: atan(px beyond the border / f)
        x = camera.width + camera.fx * math.tan(math.radians(outside))
        module = glare_on(clean, sun_azimuth_deg=math.degrees(math.atan((x - camera.cx) / camera.fx)), sun_elevation_deg=0.0)
        trust = max(0.0, 1.0 - outside / GHOST_FADE_DEG)
        assert module.visibility(wall, 0, "left") == pytest.approx(1.0 - trust, abs=0.02), outside
        assert module.visibility(sky, 0, "left") == 1.0


def test_stronger_sun_in_the_sky_changes_the_frame_more_and_an_occluded_one_not_at_all() -> None:
    clean = street()
    frame = clean[1]

    def change(klux: float, azimuth: float) -> float:
        module = glare_on(clean, sun_azimuth_deg=azimuth, sun_elevation_deg=8.0)
        module = module.with_params(sun_illuminance_klux=klux)
        module.setup(ModuleContext(sequence=clean, seed=0, depth=NativeDepth().lookup(clean)))
        return float(np.abs(module.apply(frame.image, frame.depth, frame.index, "left").astype(int) - frame.image).mean())

    seen = [change(k, 0.0) for k in (5.0, 20.0, 60.0, 150.0)]
    assert all(b > a for a, b in zip(seen, seen[1:])), seen
    assert [change(k, 20.0) for k in (5.0, 150.0)] == [0.0, 0.0]


def test_apply_without_depth_or_with_a_mismatched_map_is_an_error() -> None:
    clean = street()
    module = glare_on(clean)
    image = clean[0].image
    with pytest.raises(ModuleError, match="sun_glare needs the depth"):
        module.apply(image, None, 0, "left")
    with pytest.raises(ModuleError, match="does not match"):
        module.apply(image, np.zeros((10, 10), np.float32), 0, "left")
    with pytest.raises(ModuleError, match="sun_glare needs depth"):
        create("sun_glare").setup(ModuleContext(sequence=clean, seed=0))


# -- real KITTI 07, mono ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def kitti_mono(shared_data: Path) -> Sequence:
    return open_dataset("kitti", shared_data / "kitti", sequence="07", max_frames=61)


def test_mono_kitti_without_a_depth_source_says_sun_glare_needs_depth(kitti_mono: Sequence, monkeypatch: pytest.MonkeyPatch) -> None:
    """The issue's frame: at 50 klx the sun (20 deg right, 8 deg up) falls on the shaded facade
    of the house on the right of frame 60. Without depth nothing can tell facade from sky (a
    bright smooth region at the top is as often a wall), so the module refuses instead of
    drawing the sun on the wall."""
    monkeypatch.delenv("SAL_DEPTH_MODEL", raising=False)
    assert kitti_mono.sensor == "mono" and kitti_mono[60].depth is None
    with pytest.raises(DepthUnavailable) as info:
        perturb(kitti_mono, create("sun_glare", sun_illuminance_klux=KLUX, sun_azimuth_deg=20.0, sun_elevation_deg=8.0), seed=0)
    message = str(info.value)
    for part in ("sun_glare needs depth", "native:", "stereo:", "depth='model.onnx'", "SAL_DEPTH_MODEL"):
        assert part in message, message


def test_mono_kitti_with_a_depth_source_hides_the_sun_behind_the_facade(kitti_mono: Sequence) -> None:
    """With depth (here a stand-in map: the right house's facade at 12 m, everything above
    the roof line open sky) the disc at the issue's position is not drawn on the facade."""
    frame = kitti_mono[60]
    image = frame.image
    x, y = sun_pixel(kitti_mono, 20.0, 8.0)
    depth = np.zeros(image.shape[:2], np.float32)
    depth[:, 830:] = 12.0  # the house on the right, from its left wall to the image border
    module = create("sun_glare", sun_illuminance_klux=KLUX, sun_azimuth_deg=20.0, sun_elevation_deg=8.0)
    module.setup(ModuleContext(sequence=kitti_mono, seed=0, depth=lambda index, stream: depth))
    facade = near(image.shape[:2], (x, y), 40.0)
    out = module.apply(image, depth, frame.index, "left")
    assert np.abs(out.astype(int) - image)[facade].mean() == 0.0
    open_sky = module.apply(image, np.zeros_like(depth), frame.index, "left")
    assert np.abs(open_sky.astype(int) - image)[facade].mean() > 100.0, "the same sun in open sky floods the region"
