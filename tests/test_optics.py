"""Lens and optics modules: soiling, cracked lens, defocus (physics, nesting, per-lens patterns)."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import cv2
import numpy as np
import pytest

from sal_adapters import DatasetWarning, Sequence, open_dataset
from sal_modules import ModuleContext, ParameterError, create, perturb
from sal_modules.optics.cracked_lens import MAX_FORCE_N, grow_cracks
from sal_modules.optics.defocus import circle_of_confusion_px

KITTI_SIZE = (376, 1241)


@cache
def urban(frames: int = 3) -> Sequence:
    return open_dataset("synthetic", scene="urban", frames=frames)


def ready(name: str, seed: int = 1, sequence: Sequence | None = None, **params):  # type: ignore[no-untyped-def]
    """A module set up on ``sequence`` (default: the synthetic street) without depth."""
    module = create(name, **params)
    module.setup(ModuleContext(sequence=sequence or urban(), seed=seed))
    return module


def grey(shape: tuple[int, int] = (376, 1240), level: int = 128) -> np.ndarray:
    return np.full((*shape, 3), level, np.uint8)


def changed(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.any(a != b, axis=2)


# -- lens_soiling ----------------------------------------------------------------------------------


def test_soiling_particles_are_nested_and_zero_particles_change_nothing() -> None:
    image = urban()[0].image
    alphas = [ready("lens_soiling", particles=n).pattern("left", image).alpha for n in (0, 40, 80, 400)]
    assert not alphas[0].any()
    for fewer, more in zip(alphas, alphas[1:]):
        assert np.all(fewer <= more), "the particles of a lower count must be a subset of a higher one"
        assert np.any(more > fewer)
    clean = ready("lens_soiling", particles=0).apply(image, None, 0, "left")
    np.testing.assert_array_equal(clean, image)


def test_soiling_blends_the_dirt_colour_with_gaussian_falloff() -> None:
    module = ready("lens_soiling", particles=1, radius_px=(20, 20), opacity=(0.8, 0.8), colour=(0, 0, 0), blur=0.5)
    alpha = module.pattern("left", grey()).alpha
    peak = np.unravel_index(np.argmax(alpha), alpha.shape)
    assert alpha[peak] == pytest.approx(0.8, abs=0.01)
    # sigma = blur * r = 10 px: one sigma from the centre the coverage is o exp(-1/2)
    y, x = peak
    profile = alpha[y, x : x + 40] if x + 40 < alpha.shape[1] else alpha[y, x - 40 : x][::-1]
    assert profile[10] == pytest.approx(0.8 * np.exp(-0.5), rel=0.05)
    out = module.apply(grey(level=200), None, 0, "left")
    assert out[y, x, 0] == pytest.approx(200 * (1 - alpha[y, x]), abs=1)


def test_soiling_pattern_is_static_per_lens_and_independent_between_lenses() -> None:
    module = ready("lens_soiling", particles=80)
    left = [module.apply(grey(), None, index, "left") for index in (0, 1, 2)]
    right = module.apply(grey(), None, 0, "right")
    for other in left[1:]:
        np.testing.assert_array_equal(other, left[0])
    assert np.mean(changed(left[0], right)) > 0.05, "left and right lenses must get different dirt"


@pytest.mark.parametrize("name", ["lens_soiling", "cracked_lens"])
def test_lens_patterns_follow_the_seed_on_both_lenses(name: str) -> None:
    seq = urban(2)
    a, b, c = (perturb(seq, create(name), seed=s) for s in (4, 4, 5))
    for stream in ("image", "right"):
        np.testing.assert_array_equal(getattr(a[1], stream), getattr(b[1], stream))
        assert not np.array_equal(getattr(a[1], stream), getattr(c[1], stream))
    assert not np.array_equal(changed(a[1].image, seq[1].image), changed(a[1].right, seq[1].right))


def test_soiling_rejects_inverted_ranges() -> None:
    with pytest.raises(ParameterError, match="radius_px"):
        create("lens_soiling", radius_px=(40, 10))
    with pytest.raises(ParameterError, match="opacity"):
        create("lens_soiling", opacity=(0.9, 0.1))


# -- cracked_lens ----------------------------------------------------------------------------------


def test_crack_pattern_is_built_at_the_frame_size() -> None:
    """Its CPU time at 1241x376 (target: well under 1 s) is benchmarks/bench_time_limits.py's."""
    built = ready("cracked_lens").build("left", *KITTI_SIZE)
    assert built is not None  # the default force breaks the glass
    cracks, _ = built
    assert cracks.alpha.shape == KITTI_SIZE and 0.0 < cracks.alpha.mean() < 0.5


def test_crack_path_choice_does_not_depend_on_the_force() -> None:
    """Growing the cracks only down to T / F gives exactly the edges of the full network that
    break at F: the force decides how far the cracks run, never where."""
    module = ready("cracked_lens", points=4000, neighbour_radius_px=50.0)
    full = module.network("left", *KITTI_SIZE)
    impact = int(np.argmin(np.sum((full.points - (620.5, 188.0)) ** 2, axis=1)))
    angle = np.radians(35.0)
    previous: set[tuple[int, int]] = set()
    for force in (200.0, 350.0, 500.0, 1000.0, 3000.0):
        direct = grow_cracks(full.points, impact, np.array([np.cos(angle), np.sin(angle)]), 50.0, 300.0 / force)
        grown = {tuple(e) for e in direct.edges[direct.primary]}
        active = full.active(force, 300.0) & full.primary
        assert grown == {tuple(e) for e in full.edges[active]}
        every = {tuple(e) for e in full.edges[full.active(force, 300.0)]}
        assert previous < every, f"the cracks at a lower force must be a strict subset of those at {force} N"
        previous = every


def test_below_the_break_threshold_only_the_impact_star_cracks() -> None:
    module = ready("cracked_lens", impact_force_n=250.0, break_threshold_n=300.0)
    net = module.network("left", *KITTI_SIZE)
    impact = net.points[net.edges[np.isinf(net.factor)][0, 0]]

    def reach(force: float) -> float:
        ends = net.points[net.edges[net.active(force, 300.0)].ravel()]
        return float(np.hypot(*(ends - impact).T).max())

    assert reach(250.0) <= 65.0 + 1e-9, "below the threshold the cracks stay within the neighbour radius"
    assert reach(400.0) > 300.0, "above the threshold the cracks run across the glass"
    assert not net.active(0.0, 300.0).any()


def test_changed_pixel_share_grows_with_the_impact_force() -> None:
    image = urban()[0].image
    shares = []
    for force in (0.0, 200.0, 400.0, 800.0, 2000.0, MAX_FORCE_N):
        out = ready("cracked_lens", impact_force_n=force).apply(image, None, 0, "left")
        shares.append(float(np.mean(changed(out, image))))
    assert shares[0] == 0.0
    assert all(b > a for a, b in zip(shares, shares[1:])), shares
    assert 0.01 < shares[1] < 0.1 and shares[-1] > 0.5, shares


def test_crack_pattern_is_static_per_lens_and_independent_between_lenses() -> None:
    module = ready("cracked_lens")
    left = [module.apply(grey(), None, index, "left") for index in (0, 2)]
    right = module.apply(grey(), None, 0, "right")
    np.testing.assert_array_equal(left[0], left[1])
    assert np.mean(changed(left[0], right)) > 0.05


# -- defocus ---------------------------------------------------------------------------------------


def defocus(depth: np.ndarray, **params):  # type: ignore[no-untyped-def]
    module = create("defocus", **params)
    module.setup(ModuleContext(sequence=urban(), seed=0, depth=lambda index, stream: depth))
    return module


def rms_blur_radius(row: np.ndarray) -> float:
    """2 sigma of the line spread (derivative of a step edge's profile): r for a disk of radius r."""
    lsf = np.diff(row.astype(np.float64))
    x = np.arange(lsf.size)
    mean = (lsf * x).sum() / lsf.sum()
    return float(2 * np.sqrt((lsf * (x - mean) ** 2).sum() / lsf.sum()))


def test_defocus_blur_of_a_step_edge_matches_the_thin_lens_circle_of_confusion() -> None:
    # by hand: f = 12 mm, N = 2, S = 1 m, d = 4 m, pitch 5 um
    # c = f^2 / (N (S - f)) |d - S| / d = 144 / (2 * 988) * 3000 / 4000 = 0.054656 mm = 10.931 px
    expected_radius = 144 / (2 * 988) * 0.75 / 0.005 / 2
    depth = np.full((120, 400), 4.0, np.float32)
    module = defocus(depth, f_number=2.0, focus_distance_m=1.0, focal_length_mm=12.0, pixel_pitch_um=5.0)
    assert float(module.blur_radius_px(depth)[0, 0]) == pytest.approx(expected_radius, rel=1e-4)
    assert float(circle_of_confusion_px(np.float32(0.0), 2.0, 1.0, 12.0, 5.0)) == pytest.approx(144 / (2 * 988) / 0.005, rel=1e-4)
    step = np.zeros((120, 400, 3), np.uint8)
    step[:, 200:] = 250
    out = module.apply(step, depth, 0, "left")
    assert rms_blur_radius(out[60, :, 0]) == pytest.approx(expected_radius, rel=0.1)


def test_defocus_keeps_the_focus_plane_sharp_in_front_of_a_blurred_background() -> None:
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (200, 300, 3), dtype=np.uint8)
    depth = np.full((200, 300), 50.0, np.float32)
    depth[:, :150] = 2.0  # the left half is at the focus distance
    out = defocus(depth, f_number=1.0, focus_distance_m=2.0, focal_length_mm=12.0).apply(image, depth, 0, "left")
    np.testing.assert_array_equal(out[:, :150], image[:, :150])
    assert np.abs(out[:, 170:].astype(int) - image[:, 170:]).mean() > 30


def test_lower_f_number_gives_more_blur() -> None:
    frame = urban()[0]
    depth = frame.depth
    sharpness = []
    for n in (16.0, 8.0, 4.0, 2.0, 1.0):
        out = defocus(depth, f_number=n, focal_length_mm=8.0).apply(frame.image, depth, frame.index, "left")
        sharpness.append(float(cv2.Laplacian(cv2.cvtColor(out, cv2.COLOR_RGB2GRAY), cv2.CV_32F).var()))
    assert all(b < a for a, b in zip(sharpness, sharpness[1:])), sharpness


def test_defocus_rejects_a_focus_distance_inside_the_focal_length() -> None:
    with pytest.raises(ParameterError, match="focus_distance_m"):
        create("defocus", focus_distance_m=0.05, focal_length_mm=60.0)


# -- real frames -----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def real_sequences(shared_data: Path) -> dict[str, Sequence]:
    with pytest.warns(DatasetWarning, match="do not exist"):  # the excerpt lists 4 missing right images
        euroc = open_dataset("euroc", shared_data / "euroc" / "V1_01_easy_micro", stereo=True, max_frames=2)
    return {"kitti": open_dataset("kitti", shared_data / "kitti" / "sequences" / "07", max_frames=2), "euroc": euroc}


@pytest.mark.parametrize("kind", ["kitti", "euroc"])
def test_lens_effects_on_real_frames(real_sequences: dict[str, Sequence], kind: str) -> None:
    seq = real_sequences[kind]
    for module, low, high in ((create("lens_soiling", particles=80), 0.2, 0.95), (create("cracked_lens"), 0.2, 0.95)):
        out = perturb(seq, module, seed=3)
        for stream in ("image", "right") if seq.sensor == "stereo" else ("image",):
            clean, dirty = getattr(seq[1], stream), getattr(out[1], stream)
            assert dirty.shape == clean.shape and dirty.dtype == np.uint8
            assert low < np.mean(changed(dirty, clean)) < high, (module.name, stream)
        if seq.sensor == "stereo":
            assert not np.array_equal(changed(out[1].image, seq[1].image), changed(out[1].right, seq[1].right))


def test_defocus_on_a_real_frame_blurs_the_far_field_more(real_sequences: dict[str, Sequence]) -> None:
    frame = real_sequences["kitti"][1]
    height, width = frame.image.shape[:2]
    depth = np.full((height, width), 3.0, np.float32)
    depth[: height // 2] = 100.0  # upper half far away, lower half at the focus distance
    out = defocus(depth, f_number=1.0, focus_distance_m=3.0, focal_length_mm=12.0).apply(frame.image, depth, frame.index, "left")
    difference = np.abs(out.astype(int) - frame.image).mean(axis=(1, 2))
    assert difference[: height // 2 - 20].mean() > 5 and np.all(difference[height // 2 :] == 0)
