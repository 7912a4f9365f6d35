"""Light and sensor modules: night (auto-exposure, Poisson noise, lamp colour, ONNX backend),
sensor_noise (ISO) and sun_glare (Stiles-Holladay veil, disc, ghosts)."""

from __future__ import annotations

import math
import sys
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from sal_adapters import DatasetWarning, Sequence, open_dataset
from sal_modules import ModuleContext, ModuleError, create, perturb
from sal_modules.colour import srgb_to_linear
from sal_modules.light.night import auto_exposure
from sal_modules.light.sensor import LUMA, white_balance
from sal_modules.light.sun_glare import GHOSTS, sun_direction


@cache
def urban(frames: int = 2) -> Sequence:
    return open_dataset("synthetic", scene="urban", frames=frames)


def ready(name: str, seed: int = 1, sequence: Sequence | None = None, **params):  # type: ignore[no-untyped-def]
    """A module set up on ``sequence`` (default: the synthetic street)."""
    module = create(name, **params)
    module.setup(ModuleContext(sequence=sequence or urban(), seed=seed))
    return module


def flat(level: int, shape: tuple[int, int] = (300, 400)) -> np.ndarray:
    return np.full((*shape, 3), level, np.uint8)


def linear(image: np.ndarray) -> np.ndarray:
    return srgb_to_linear(image).astype(np.float64)


@pytest.fixture(scope="module")
def kitti(shared_data: Path) -> Sequence:
    return open_dataset("kitti", shared_data / "kitti" / "sequences" / "07", max_frames=41)


@pytest.fixture(scope="module")
def euroc(shared_data: Path) -> Sequence:
    with pytest.warns(DatasetWarning, match="do not exist"):  # the excerpt lists 4 missing right images
        return open_dataset("euroc", shared_data / "euroc" / "V1_01_easy_micro", stereo=True, max_frames=2)


# -- night: auto-exposure and brightness -------------------------------------------------------------


def test_auto_exposure_lengthens_the_exposure_first_then_raises_the_gain() -> None:
    # (lux, t, g, p, f) with daylight 10000 lx, t <= 8, g <= 64: E_min = 10000 / 512 = 19.53 lx
    for lux, t, g, p, f in (
        (20_000, 0.5, 1, 1, 1),
        (10_000, 1, 1, 1, 1),
        (2000, 5, 1, 1, 1),
        (100, 8, 12.5, 0.08, 1),
        (5, 8, 64, 0.004, 0.256),
    ):
        e = auto_exposure(lux, 10_000.0, 8.0, 64.0)
        assert (e.time, e.gain, e.photons, e.brightness) == pytest.approx((t, g, p, f)), lux


@pytest.mark.parametrize("lux", [10_000.0, 2000.0])
def test_night_is_the_identity_while_the_exposure_makes_up_for_the_light(lux: float) -> None:
    image = urban()[1].image
    out = ready("night", illuminance_lux=lux, colour_temperature_k=6500.0).apply(image, None, 1, "left")
    np.testing.assert_array_equal(out, image)


def test_night_keeps_the_mean_down_to_the_limit_and_darkens_linearly_below_it() -> None:
    image = flat(150)
    clean = linear(image).mean()
    limit = 10_000.0 / (8.0 * 64.0)
    for lux in (1000.0, 100.0, 30.0, 20.0, 10.0, 2.0, 0.5):
        module = ready("night", illuminance_lux=lux, colour_temperature_k=6500.0, full_well_e=1e6, read_noise_e=0.0)
        ratio = linear(module.apply(image, None, 0, "left")).mean() / clean
        assert ratio == pytest.approx(min(1.0, lux / limit), rel=0.01), lux


def test_night_darkens_and_relative_noise_grows_as_the_light_falls() -> None:
    image = flat(150)
    means, noise = [], []
    for lux in (1000.0, 200.0, 50.0, 10.0, 2.0):
        out = linear(ready("night", illuminance_lux=lux, colour_temperature_k=6500.0).apply(image, None, 0, "left"))
        means.append(out.mean())
        noise.append(out.std() / out.mean())
    assert all(b <= a * 1.005 for a, b in zip(means, means[1:])) and means[-1] < 0.2 * means[0], means
    assert all(b > 1.3 * a for a, b in zip(noise, noise[1:])), noise


@pytest.mark.parametrize("read_noise_e", [0.0, 5.0])
def test_night_shot_noise_has_poisson_variance_in_electrons(read_noise_e: float) -> None:
    """A flat grey patch at 1000 lx, exposure capped at daylight: p = 0.1 of the photons, gain 10."""
    full_well, lux = 1000.0, 1000.0
    module = ready(
        "night",
        illuminance_lux=lux,
        max_exposure_factor=1.0,
        max_gain=1000.0,
        full_well_e=full_well,
        read_noise_e=read_noise_e,
        colour_temperature_k=6500.0,
    )
    e = module.exposure()
    assert (e.photons, e.gain, e.brightness) == pytest.approx((0.1, 10.0, 1.0))
    image = flat(150, (400, 400))
    level = linear(image).mean()
    out = linear(module.apply(image, None, 0, "left"))
    assert out.mean() == pytest.approx(level, rel=0.005)
    electrons = level * full_well * e.photons  # mean collected electrons (30.5 e-)
    measured = out.var() * (full_well / e.gain) ** 2  # variance in electrons at the sensor
    carried = e.photons * electrons + (e.photons * read_noise_e) ** 2  # what the clean frame already held
    assert measured + carried == pytest.approx(electrons + read_noise_e**2, rel=0.03)


def test_night_lamp_colour_shifts_red_over_blue_with_falling_colour_temperature() -> None:
    image = flat(128)
    ratios = []
    for kelvin in (2000.0, 3000.0, 4500.0, 6500.0, 10_000.0):
        out = linear(ready("night", illuminance_lux=10_000.0, colour_temperature_k=kelvin).apply(image, None, 0, "left"))
        ratios.append(out[..., 0].mean() / out[..., 2].mean())
    assert all(a > b for a, b in zip(ratios, ratios[1:])), ratios
    assert ratios[3] == pytest.approx(1.0, abs=0.01) and ratios[0] > 3.0 and ratios[-1] < 0.9
    gains = white_balance(3000.0)
    assert float(LUMA @ gains) == pytest.approx(1.0, abs=1e-5), "the lamp colour keeps the luminance"


def test_night_noise_follows_the_seed_the_frame_and_the_stream() -> None:
    image = flat(150, (120, 160))
    a, b, c = (ready("night", seed=s) for s in (4, 4, 5))
    first = a.apply(image, None, 0, "left")
    np.testing.assert_array_equal(first, b.apply(image, None, 0, "left"))
    assert np.mean(first != c.apply(image, None, 0, "left")) > 0.5
    assert np.mean(first != a.apply(image, None, 1, "left")) > 0.5, "every frame gets new noise"
    assert np.mean(first != a.apply(image, None, 0, "right")) > 0.5, "the two cameras have independent noise"


def test_night_darker_settings_scale_the_same_noise_pattern() -> None:
    image = flat(150, (200, 200))
    residuals = []
    for lux in (100.0, 30.0):
        out = linear(ready("night", illuminance_lux=lux, colour_temperature_k=6500.0).apply(image, None, 3, "left"))
        residuals.append((out - out.mean()).ravel())
    assert np.corrcoef(*residuals)[0, 1] > 0.95


# -- night: ONNX backend ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def onnx_models(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    from onnx_models import image_model

    root = tmp_path_factory.mktemp("onnx")
    return {
        "identity": image_model(root / "identity.onnx"),
        "half": image_model(root / "half.onnx", gain=0.5),
        "fixed": image_model(root / "fixed.onnx", size=(64, 96)),
        "broken": _write(root / "broken.onnx", b"not a model"),
    }


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def translate(model: Path, image: np.ndarray, **params) -> np.ndarray:  # type: ignore[no-untyped-def]
    module = ready("night", model=str(model), illuminance_lux=10_000.0, **params)
    return module.apply(image, None, 0, "left")


def test_onnx_identity_model_in_minus_one_to_one_returns_the_input(onnx_models: dict[str, Path]) -> None:
    image = urban()[1].image  # 1240 x 376: multiples of 8, no resizing
    out = translate(onnx_models["identity"], image)
    assert np.abs(out.astype(int) - image).max() <= 1, "denormalisation must be 0.5 y + 0.5 (not y + 0.5)"


@pytest.mark.parametrize(("value_range", "expected"), [("-1..1", lambda i: 0.5 * i + 0.25), ("0..1", lambda i: 0.5 * i)])
def test_onnx_half_model_gives_the_exact_scaled_image(onnx_models: dict[str, Path], value_range: str, expected) -> None:  # type: ignore[no-untyped-def]
    image = urban()[1].image
    out = translate(onnx_models["half"], image, model_range=value_range)
    want = np.round(255.0 * expected(image / 255.0))
    assert np.abs(out - want).max() <= 1


@pytest.mark.parametrize("model", ["identity", "fixed"])
def test_onnx_model_input_is_resized_and_the_output_resized_back(onnx_models: dict[str, Path], model: str) -> None:
    image = urban()[1].image[100:161, 300:401]  # 61 x 101: not a multiple of 8
    out = translate(onnx_models[model], image)
    assert out.shape == image.shape
    assert np.abs(out.astype(int) - image).mean() < (4 if model == "identity" else 12)


def test_onnx_backend_still_adds_the_noise_of_the_light_level(onnx_models: dict[str, Path]) -> None:
    image = flat(150, (96, 128))
    out = ready("night", model=str(onnx_models["identity"]), illuminance_lux=5.0).apply(image, None, 0, "left")
    lin = linear(out)
    assert lin.std() > 0.01 and lin.mean() == pytest.approx(linear(image).mean(), rel=0.05), (
        "the network decides brightness, the sensor adds noise"
    )


def test_onnx_backend_errors_name_the_file_and_the_extra(
    onnx_models: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    missing = tmp_path / "nowhere" / "day2night.onnx"
    with pytest.raises(ModuleError, match=f"night: model file {missing} does not exist"):
        ready("night", model=str(missing))
    with pytest.raises(ModuleError, match="cannot load ONNX model .*broken.onnx"):
        ready("night", model=str(onnx_models["broken"]))
    monkeypatch.setitem(sys.modules, "onnxruntime", None)
    with pytest.raises(ModuleError, match=r"pip install 'pytest-sal\[onnx\]'"):
        ready("night", model=str(onnx_models["identity"]))


# -- sensor_noise -------------------------------------------------------------------------------------


def test_iso_noise_variance_and_mean_follow_the_sensor_model() -> None:
    image = flat(150, (300, 300))
    level = linear(image).mean()
    full_well, read_noise = 10_000.0, 2.5
    stds = []
    for iso in (400.0, 1600.0, 6400.0):
        out = linear(ready("sensor_noise", iso=iso).apply(image, None, 0, "left"))
        g = iso / 100.0
        predicted = (g - 1) * level / full_well + (g * g - 1) * read_noise**2 / full_well**2
        assert out.var() == pytest.approx(predicted, rel=0.05), iso
        assert out.mean() == pytest.approx(level, rel=0.005), iso
        stds.append(out.std())
    assert stds[0] < stds[1] < stds[2]


@pytest.mark.parametrize("iso", [50.0, 100.0])
def test_iso_at_or_below_the_base_iso_adds_nothing(iso: float) -> None:
    image = urban()[0].image
    np.testing.assert_array_equal(ready("sensor_noise", iso=iso).apply(image, None, 0, "left"), image)


# -- sun_glare ----------------------------------------------------------------------------------------


def all_sky(index: int, stream: str) -> np.ndarray:
    """A depth lookup that says "sky" everywhere (0 = no depth): nothing hides the sun."""
    return np.zeros((376, 1240), np.float32)


def sky_of(image: np.ndarray) -> np.ndarray:
    """An all-sky depth map (0 = no depth) of ``image``'s size."""
    return np.zeros(image.shape[:2], np.float32)


def glare_module(sequence: Sequence | None = None, depth=all_sky, **params):  # type: ignore[no-untyped-def]
    """sun_glare set up on ``sequence`` (default: the synthetic street) with a depth lookup."""
    module = create("sun_glare", **params)
    module.setup(ModuleContext(sequence=sequence or urban(), seed=1, depth=depth))
    return module


def angles_deg(module, stream: str, height: int, width: int, index: int = 0) -> np.ndarray:  # type: ignore[no-untyped-def]
    camera = module.context.camera_for(stream)
    x = (np.arange(width) - camera.cx) / camera.fx
    y = (np.arange(height)[:, None] - camera.cy) / camera.fy
    rays = np.stack(np.broadcast_arrays(x[None, :], y, np.ones((height, width))))
    rays /= np.linalg.norm(rays, axis=0)
    d = module.direction(index, stream)
    return np.degrees(np.arccos(np.clip(np.tensordot(d, rays, 1), -1, 1)))


def test_veiling_glare_follows_the_stiles_holladay_law() -> None:
    module = glare_module(sun_illuminance_klux=20.0, sun_azimuth_deg=10.0, sun_elevation_deg=5.0, veil_factor=1.0, ghost_reflectance=0.0)
    height, width = 376, 1240
    glare = module.glare(0, "left", height, width) @ LUMA.astype(np.float32)
    theta = angles_deg(module, "left", height, width)
    e_pupil = 20_000.0 * math.cos(math.radians(10.0)) * math.cos(math.radians(5.0))
    expected = 10.0 * e_pupil / theta**2 / (10_000.0 / math.pi)
    ring = theta > 2.0
    np.testing.assert_allclose(glare[ring], expected[ring], rtol=0.01)


def test_glare_is_brighter_closer_to_the_sun_on_the_image() -> None:
    module = glare_module(sun_azimuth_deg=15.0, sun_elevation_deg=5.0)
    image = flat(60, (376, 1240))
    added = linear(module.apply(image, sky_of(image), 0, "left")) - linear(image)
    theta = angles_deg(module, "left", 376, 1240)
    near, middle, far = (added[(theta > lo) & (theta < hi)].mean() for lo, hi in ((10, 12), (20, 22), (35, 37)))
    assert near > middle > far > 0


def test_stronger_sun_changes_the_image_more() -> None:
    frame = urban()[0]
    image, depth = frame.image, frame.depth  # the default sun (straight ahead, 8 deg up) is in the sky
    diffs = [
        np.abs(glare_module(sun_illuminance_klux=k).apply(image, depth, 0, "left").astype(int) - image).mean()
        for k in (0.0, 5.0, 20.0, 60.0, 150.0)
    ]
    assert diffs[0] == 0 and all(b > a for a, b in zip(diffs, diffs[1:])), diffs


def test_sun_outside_the_view_still_veils_and_behind_the_camera_does_nothing() -> None:
    image = flat(60, (376, 1240))
    out = glare_module(sun_azimuth_deg=70.0, sun_elevation_deg=5.0).apply(image, sky_of(image), 0, "left")
    added = linear(out) - linear(image)
    assert added.min() > 0, "every pixel gets veiling glare"
    assert added[:, -100:].mean() > 2 * added[:, :100].mean(), "more glare on the side of the sun"
    assert out.max() < 255, "no disc, no bloom and no ghosts with the sun 29 deg outside the view"
    behind = glare_module(sun_azimuth_deg=120.0).apply(image, sky_of(image), 0, "left")
    np.testing.assert_array_equal(behind, image)


def test_sun_disc_saturates_where_the_sun_projects_and_ghosts_lie_on_the_line_through_the_centre() -> None:
    module = glare_module(sun_azimuth_deg=20.0, sun_elevation_deg=8.0, veil_factor=0.0)
    camera = urban().camera
    d = sun_direction(20.0, 8.0)
    sun = np.array([camera.cx + camera.fx * d[0] / d[2], camera.cy + camera.fy * d[1] / d[2]])
    image = flat(20, (376, 1240))
    out = module.apply(image, sky_of(image), 0, "left")
    assert np.all(out[int(round(sun[1])), int(round(sun[0]))] == 255)
    glare = module.glare(0, "left", 376, 1240).sum(axis=2)
    centre = np.array([camera.cx, camera.cy])
    for t, *_ in GHOSTS:
        x, y = np.round(centre + t * (sun - centre)).astype(int)
        if 0 <= x < 1240 and 0 <= y < 376:
            assert glare[y, x] > 0.01, t
    assert glare[30, 30] == 0 and glare[350, 1200] == 0, "nothing off the flare line without veil"


def test_glare_is_static_over_frames_unless_it_follows_the_pose(kitti: Sequence) -> None:
    image = urban()[0].image
    module = glare_module()
    np.testing.assert_array_equal(module.apply(image, sky_of(image), 0, "left"), module.apply(image, sky_of(image), 1, "left"))
    follow = glare_module(sequence=kitti, sun_azimuth_deg=0.0, sun_elevation_deg=5.0, follow_pose=True)
    yaw = math.degrees(math.atan2(kitti.groundtruth.matrices[40][0, 2], kitti.groundtruth.matrices[40][2, 2]))
    d = follow.direction(40, "left")
    assert math.degrees(math.atan2(d[0], d[2])) == pytest.approx(-yaw, abs=0.5), "the sun stays put while the car turns"
    assert math.degrees(math.asin(-d[1])) == pytest.approx(5.0, abs=1.0)


def test_follow_pose_needs_ground_truth(euroc: Sequence) -> None:
    with pytest.raises(ModuleError, match="follow_pose needs per-frame ground-truth poses"):
        glare_module(sequence=euroc, follow_pose=True)


# -- real frames --------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["kitti", "euroc"])
def test_light_modules_on_real_grey_frames(kind: str, kitti: Sequence, euroc: Sequence) -> None:
    seq = {"kitti": kitti, "euroc": euroc}[kind]
    clean = seq[1].image
    night = perturb(seq, create("night", illuminance_lux=2.0), seed=1)[1]
    iso = perturb(seq, create("sensor_noise", iso=6400.0), seed=1)[1]
    glare = glare_module(sequence=seq, sun_azimuth_deg=-10.0)  # all sky: the grey path of the glare
    glare_left = glare.apply(clean, sky_of(clean), seq[1].index, "left")
    for out in (night.image, iso.image, glare_left):
        assert out.shape == clean.shape and out.dtype == np.uint8
        assert np.array_equal(out[..., 0], out[..., 2]), "a grey camera stays grey"
    assert linear(night.image).mean() < 0.25 * linear(clean).mean()
    assert 2.0 < np.abs(iso.image.astype(int) - clean).mean() < 20.0
    assert linear(glare_left).mean() > linear(clean).mean() + 0.05
    if seq.sensor == "stereo":
        right = seq[1].right
        assert np.mean(night.right != right) > 0.3 and not np.array_equal(night.image, night.right)
        glare_right = glare.apply(right, sky_of(right), seq[1].index, "right")
        assert np.array_equal(glare_right[..., 0], glare_right[..., 2])
        assert linear(glare_right).mean() > linear(right).mean() + 0.05
