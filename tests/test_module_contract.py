"""Registry-driven tests: every registered perturbation module keeps the module contract.

A module registered in ``sal.perturbations`` without a case in ``tests/cases_<family>.py``
fails ``test_every_registered_module_has_a_case``.
"""

from __future__ import annotations

import json
from functools import cache

import numpy as np
import pytest
from module_cases import ModuleCase, all_cases

import sal_modules
from pytest_sal.cli.main import main
from sal_adapters import Sequence, open_dataset
from sal_modules import (
    PERTURBATIONS,
    ModuleContext,
    ParameterError,
    create,
    from_json,
    perturb,
)
from sal_modules.depth import NativeDepth

CASES = all_cases()
NAMES = sorted(CASES)
PER_FRAME = [n for n in NAMES if not (sal_modules.module_class(n).whole_sequence or sal_modules.module_class(n).drops_frames)]
LADDERS = [(name, param) for name in NAMES for param in CASES[name].ladder]


@cache
def synthetic(scene: str, sensor: str | None, frames: int) -> Sequence:
    return open_dataset("synthetic", scene=scene, frames=frames, sensor=sensor)


def clean_of(case: ModuleCase) -> Sequence:
    return synthetic(case.scene, case.sensor, case.frames)


def frames_of(sequence: Sequence) -> list[np.ndarray]:
    images = []
    for frame in sequence:
        images.append(frame.image)
        if frame.right is not None:
            images.append(frame.right)
    return images


def difference(clean: Sequence, changed: Sequence) -> float:
    """Mean absolute difference (grey levels) over the kept frames (both cameras of a stereo
    pair), plus one full-scale difference (255) per dropped frame, so dropping frames counts
    as damage too."""
    positions = {r.index: p for p, r in enumerate(clean.records)}
    total, count = 0.0, 0
    for frame in changed:
        original = clean[positions[frame.index]]
        pairs = [(frame.image, original.image)] + ([(frame.right, original.right)] if frame.right is not None else [])
        total += float(np.mean([np.abs(a.astype(np.float32) - b).mean() for a, b in pairs]))
        count += 1
    dropped = len(clean) - len(changed)
    return (total + 255.0 * dropped) / max(count + dropped, 1)


def test_every_registered_module_has_a_case() -> None:
    registered = set(PERTURBATIONS.names()) - {"composite"}
    missing = sorted(registered - set(CASES))
    assert not missing, f"add a ModuleCase for {missing} in tests/cases_<family>.py"
    for name in NAMES:
        searchable = set(sal_modules.module_class(name).searchable())
        assert set(CASES[name].ladder) == searchable, f"{name}: give a ladder for every searchable parameter {sorted(searchable)}"
        for param, values in CASES[name].ladder.items():
            assert len(values) >= 3, f"{name}.{param}: a ladder needs at least 3 severities"


@pytest.mark.parametrize("name", NAMES)
def test_json_round_trip_gives_an_equal_module_with_the_same_output(name: str) -> None:
    case = CASES[name]
    module = create(name, **case.params)
    text = module.to_json()
    again = from_json(text)
    assert again == module and again.to_json() == text and hash(again) == hash(module)
    assert json.loads(text)["version"] == module.version >= 1
    clean = clean_of(case)
    first, second = perturb(clean, module, seed=3), perturb(clean, again, seed=3)
    np.testing.assert_array_equal(first[-1].image, second[-1].image)


@pytest.mark.parametrize("name", NAMES)
def test_same_seed_gives_identical_bytes_and_another_seed_another_pattern(name: str) -> None:
    case = CASES[name]
    module = create(name, **case.params)
    clean = clean_of(case)
    a, b = perturb(clean, module, seed=1), perturb(clean, module, seed=1)
    assert list(a.indices) == list(b.indices)
    for x, y in zip(frames_of(a), frames_of(b)):
        np.testing.assert_array_equal(x, y)
    if case.random:
        c = perturb(clean, module, seed=2)
        same_frames = list(c.indices) == list(a.indices) and all(np.array_equal(x, y) for x, y in zip(frames_of(a), frames_of(c)))
        assert not same_frames, f"{name}: seed 2 gave exactly the pattern of seed 1"


@pytest.mark.parametrize(("name", "param"), LADDERS, ids=[f"{n}.{p}" for n, p in LADDERS])
def test_difference_from_clean_grows_with_severity(name: str, param: str) -> None:
    case = CASES[name]
    clean = clean_of(case)
    values = case.ladder[param]
    module = create(name, **case.params)
    diffs = [difference(clean, perturb(clean, module.with_params(**{param: v}), seed=5)) for v in values]
    assert all(later >= earlier - 1e-6 for earlier, later in zip(diffs, diffs[1:])), f"{name}.{param} {values}: differences {diffs}"
    assert diffs[-1] > diffs[0], f"{name}.{param} {values}: no change in difference {diffs}"


@pytest.mark.parametrize("name", NAMES)
def test_out_of_range_values_name_module_parameter_unit_and_range(name: str) -> None:
    for param, spec in sal_modules.module_class(name).parameters().items():
        if spec.domain not in ("continuous", "integer") or (spec.min is None and spec.max is None):
            continue
        bad = spec.min - 1 if spec.min is not None else spec.max + 1
        with pytest.raises(ParameterError) as info:
            create(name, **{param: bad})
        message = str(info.value)
        assert message.startswith(f"{name}: {param} = ") and spec.allowed() in message, message
        if spec.unit:
            assert spec.unit in message
    with pytest.raises(ParameterError, match=f"{name} has no parameter 'no_such_parameter'"):
        create(name, no_such_parameter=1)


@pytest.mark.parametrize("name", PER_FRAME)
def test_apply_returns_a_new_image_and_leaves_its_input_alone(name: str) -> None:
    """Per-frame modules through the bare contract (setup, apply, cleanup) without perturb()."""
    case = CASES[name]
    clean = clean_of(case)
    module = create(name, **case.params)
    depth = NativeDepth().lookup(clean)
    module.setup(ModuleContext(sequence=clean, seed=1, depth=depth))
    frame = clean[1]
    image = frame.image.copy()
    out = module.apply(image, depth(frame.index, "left") if module.needs_depth else None, frame.index, "left")
    module.cleanup()
    np.testing.assert_array_equal(image, frame.image)
    assert out is not image and out.shape == image.shape and out.dtype == np.uint8


def test_modules_json_lists_every_parameter_with_unit_range_and_direction(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["modules", "--json"]) == 0
    listed = {m["name"]: m for m in json.loads(capsys.readouterr().out)}
    assert set(listed) == set(PERTURBATIONS.names())
    for name in NAMES:
        params = listed[name]["parameters"]
        assert params, name
        for p in params:
            assert {"name", "unit", "default", "min", "max", "searchable", "worse"} <= set(p)
            assert (p["worse"] in ("higher", "lower")) == p["searchable"]
