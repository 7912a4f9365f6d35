"""Every registered module on the real excerpts: EuRoC V1_01 stereo (depth from semi-global
matching) and KITTI 07 (grey, left camera only: depth from a user-supplied monocular ONNX
model, here a tiny one built by the test)."""

from __future__ import annotations

import warnings
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from module_cases import all_cases
from onnx_models import depth_model

import sal_modules
from sal_adapters import DatasetWarning, Sequence, open_dataset
from sal_modules import ModuleError, create, perturb

CASES = all_cases()
NAMES = sorted(CASES)


@cache
def euroc(root: Path) -> Sequence:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DatasetWarning)  # 4 missing cam1 files, reported by the adapter tests
        return open_dataset("euroc", root / "euroc" / "V1_01_easy_micro", stereo=True, start=30, max_frames=8)


@cache
def kitti(root: Path) -> Sequence:
    return open_dataset("kitti", root / "kitti" / "sequences" / "07", start=20, max_frames=8)


def assert_perturbed_like_the_dataset(clean: Sequence, out: Sequence, name: str) -> None:
    """Same camera, kind and sensor; grey stays grey; something changed (or frames dropped)."""
    assert (out.kind, out.sensor, out.camera) == (clean.kind, clean.sensor, clean.camera)
    positions = {r.index: p for p, r in enumerate(clean.records)}
    changed = len(out) < len(clean)
    for frame in out:
        original = clean[positions[frame.index]]
        for image, reference in ((frame.image, original.image), (frame.right, original.right)):
            if reference is None:
                continue
            assert image.shape == reference.shape and image.dtype == np.uint8, name
            assert (image[..., 0] == image[..., 1]).all() and (image[..., 1] == image[..., 2]).all(), f"{name}: grey input must stay grey"
            changed |= not np.array_equal(image, reference)
    assert changed, f"{name} changed nothing"


@pytest.mark.parametrize("name", NAMES)
def test_every_module_on_euroc_stereo(name: str, shared_data: Path) -> None:
    clean = euroc(shared_data)
    out = perturb(clean, create(name, **CASES[name].params), seed=1, depth="stereo")
    assert_perturbed_like_the_dataset(clean, out, name)


@pytest.mark.parametrize("name", NAMES)
def test_every_module_on_kitti_mono_with_a_monocular_depth_model(name: str, shared_data: Path, tmp_path: Path) -> None:
    clean = kitti(shared_data)
    model = depth_model(tmp_path / "depth.onnx", gain=0.0, offset=12.0)  # a flat 12 m scene
    module = create(name, **CASES[name].params)
    if name == "stereo_desync":
        with pytest.raises(ModuleError, match="stereo_desync .*mono"):
            perturb(clean, module, seed=1, depth=str(model))
        return
    out = perturb(clean, module, seed=1, depth=str(model))
    assert_perturbed_like_the_dataset(clean, out, name)
    if sal_modules.module_class(name).needs_depth:
        with pytest.raises(sal_modules.DepthUnavailable, match="kitti/07"):
            perturb(clean, module, seed=1)  # no stereo, no depth maps, no model: one clear error


@pytest.mark.parametrize("name", ["rain", "snow"])
def test_precipitation_indoors_keeps_unknown_depth_in_the_room(name: str, shared_data: Path) -> None:
    """EuRoC's overexposed window and part of the wall have no stereo depth. Taken as the 1 km
    cloud base they turn to the airlight; with the room's size (sky_distance_m=4) they stay
    about as they are, while the measured pixels are perturbed the same either way."""
    from sal_modules.depth import StereoDepth

    clean = euroc(shared_data)
    depth = StereoDepth().compute(clean, 0, "left")
    unknown = depth <= 0
    assert 0.01 < unknown.mean() < 0.5  # the window and the border: a real share of the frame
    original = clean[0].image.astype(np.float64)
    outdoors, indoors = (
        perturb(clean, create(name, intensity_mm_h=10.0, **extra), seed=1, depth="stereo")[0].image.astype(np.float64)
        for extra in ({}, {"sky_distance_m": 4.0})
    )
    change_out, change_in = (np.abs(img - original).mean(axis=2) for img in (outdoors, indoors))
    assert change_in[unknown].mean() < 0.3 * change_out[unknown].mean()
    assert change_in[~unknown].mean() == pytest.approx(change_out[~unknown].mean(), rel=0.05)
