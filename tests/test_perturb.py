"""The chain and the lazy perturbation pipeline, with small test-only modules."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import ClassVar

import numpy as np
import pytest

from sal_adapters import Camera, FrameRecord, Sequence, open_dataset, write_sequence
from sal_modules import (
    PERTURBATIONS,
    Composite,
    DepthUnavailable,
    ModuleContext,
    ModuleError,
    Param,
    ParameterError,
    Perturbation,
    SequencePerturbation,
    create,
    from_dict,
    perturb,
)


class Gain(Perturbation):
    """Multiply by ``factor`` (clipped)."""

    name = "test_gain"
    summary = "test: multiply"
    factor = Param(2.0, min=0.0, max=10.0, searchable=True, worse="higher")
    calls: ClassVar[int] = 0

    def apply(self, image, depth, index, stream):  # type: ignore[no-untyped-def]
        type(self).calls += 1
        return np.clip(image.astype(np.float32) * self.factor, 0, 255).astype(np.uint8)


class Square(Perturbation):
    """Paint a black square of ``size`` px in the top-left corner."""

    name = "test_square"
    summary = "test: black square"
    size = Param(20, domain="integer", unit="px", min=0, max=1000, searchable=True, worse="higher")
    value = Param(0, domain="integer", min=0, max=255)

    def apply(self, image, depth, index, stream):  # type: ignore[no-untyped-def]
        out = image.copy()
        out[: self.size, : self.size] = self.value
        return out


class DropOdd(Perturbation):
    """Drop odd dataset indices."""

    name = "test_drop_odd"
    summary = "test: drop odd frames"
    drops_frames = True

    def keep_frame(self, index: int) -> bool:
        return index % 2 == 0

    def apply(self, image, depth, index, stream):  # type: ignore[no-untyped-def]
        return image if self.keep_frame(index) else None


class Recorder(SequencePerturbation):
    """Whole-sequence step that records what it was given and returns it inverted."""

    name = "test_recorder"
    summary = "test: record and invert"
    seen: ClassVar[list[tuple[int, float]]] = []

    def setup(self, context: ModuleContext) -> None:
        super().setup(context)
        self._frames: dict[tuple[str, int], np.ndarray] = {}

    def prepare(self, stream: str, frames: Iterable[tuple[int, np.ndarray]]) -> None:
        for index, image in frames:
            type(self).seen.append((index, float(image[:20, :20].mean())))
            self._frames[(stream, index)] = 255 - image

    def is_prepared(self, stream: str) -> bool:
        return any(key[0] == stream for key in getattr(self, "_frames", {}))

    def result(self, index: int, stream: str) -> np.ndarray:
        return self._frames[(stream, index)]


class NeedsDepth(Perturbation):
    name = "test_needs_depth"
    summary = "test: needs depth"
    needs_depth = True

    def apply(self, image, depth, index, stream):  # type: ignore[no-untyped-def]
        assert depth is not None and depth.shape == image.shape[:2]
        return image.copy()


class Forgetful(Perturbation):
    """Returns None without declaring drops_frames."""

    name = "test_forgetful"
    summary = "test: drops without saying so"

    def apply(self, image, depth, index, stream):  # type: ignore[no-untyped-def]
        return None


TEST_MODULES = (Gain, Square, DropOdd, Recorder, NeedsDepth, Forgetful)


@pytest.fixture(autouse=True)
def registered() -> Iterator[None]:
    for cls in TEST_MODULES:
        PERTURBATIONS.register(cls.name, cls)
    Recorder.seen.clear()
    yield
    for cls in TEST_MODULES:
        PERTURBATIONS.unregister(cls.name)


@pytest.fixture(scope="module")
def urban() -> Sequence:
    return open_dataset("synthetic", scene="urban", frames=6)


def test_chain_order_matters_and_keeps_earlier_effects(urban: Sequence) -> None:
    white_then_gain = perturb(urban, Square(value=100) >> Gain(factor=2.0))[0].image
    gain_then_white = perturb(urban, Gain(factor=2.0) >> Square(value=100))[0].image
    assert (white_then_gain[:20, :20] == 200).all() and (gain_then_white[:20, :20] == 100).all()
    clean = urban[0].image
    np.testing.assert_array_equal(white_then_gain[30:, 30:], np.clip(clean[30:, 30:].astype(int) * 2, 0, 255))


def test_child_parameters_are_addressable_by_name_position_or_bare_name() -> None:
    chain = Gain() >> Square
    assert isinstance(chain, Composite) and chain.label() == "test_gain>>test_square"
    assert chain.param("size") == chain.param("test_square.size") == chain.param("test_square@1.size")
    changed = chain.with_params(size=5, **{"test_gain.factor": 3.0})
    assert changed.steps[1].size == 5 and changed.steps[0].factor == 3.0 and chain.steps[1].size == 20
    twice = Square() >> Square(size=3)
    with pytest.raises(ParameterError, match="no parameter 'size'; addresses: test_square@0.size"):
        twice.with_params(size=1)
    assert twice.with_params(**{"test_square@1.size": 7}).steps == (Square(), Square(size=7))
    assert (Gain >> Square()).label() == "test_gain>>test_square"  # class >> instance
    assert len((chain >> Gain).steps) == 3  # chains flatten


def test_composite_round_trips_through_json_and_create() -> None:
    chain = Gain(factor=1.5) >> Square(size=4)
    assert from_dict(chain.to_dict()) == chain
    assert create("composite", steps=[{"module": "test_gain", "params": {"factor": 1.5}}, Square(size=4)]) == chain
    with pytest.raises(ParameterError, match="at least one module"):
        Composite([])
    with pytest.raises(ParameterError, match="unknown keys"):
        from_dict({"module": "test_gain", "parms": {}})


def test_perturb_is_lazy_and_the_original_module_is_untouched(urban: Sequence) -> None:
    module = Gain()
    Gain.calls = 0
    out = perturb(urban, module)
    assert Gain.calls == 0 and module.context is None
    out[2].image
    assert Gain.calls == 1
    assert out.kind == urban.kind and out.sensor == "stereo" and out.camera == urban.camera
    assert out.name == f"{urban.name}+test_gain"


def test_dropped_frames_leave_sequence_timestamps_and_groundtruth(urban: Sequence) -> None:
    out = perturb(urban, Gain() >> DropOdd())
    assert list(out.indices) == [0, 2, 4]
    np.testing.assert_array_equal(out.timestamps, urban.timestamps[[0, 2, 4]])
    np.testing.assert_array_equal(out.groundtruth.positions, urban.groundtruth.positions[[0, 2, 4]])


def test_fingerprint_depends_on_source_chain_and_seed(urban: Sequence) -> None:
    base = perturb(urban, Gain(), seed=1).fingerprint
    assert base == perturb(urban, Gain(), seed=1).fingerprint
    assert base != perturb(urban, Gain(), seed=2).fingerprint
    assert base != perturb(urban, Gain(factor=3.0), seed=1).fingerprint
    assert base != urban.fingerprint


def test_whole_sequence_step_sees_exactly_the_frames_of_earlier_steps(urban: Sequence) -> None:
    out = perturb(urban, DropOdd() >> Square(value=50) >> Recorder())
    np.testing.assert_array_equal(out[1].image[:20, :20], 255 - 50)
    assert [index for index, _ in Recorder.seen[:3]] == [0, 2, 4]  # left stream: kept frames only
    assert all(mean == 50 for _, mean in Recorder.seen)  # the square painted before it
    Recorder.seen.clear()
    out = perturb(urban, Recorder() >> DropOdd())
    out[0].image
    assert [index for index, _ in Recorder.seen] == list(range(6))  # drops after it: all frames


def test_perturbed_sequence_is_written_in_the_dataset_layout(urban: Sequence, tmp_path) -> None:  # type: ignore[no-untyped-def]
    out = perturb(urban, DropOdd() >> Square(value=255))
    copy = open_dataset("synthetic", write_sequence(out, tmp_path / "copy"))
    assert list(copy.indices) == [0, 2, 4]
    np.testing.assert_array_equal(copy[1].image, out[1].image)
    assert (copy[1].right[:20, :20] == 255).all()


def test_undeclared_drop_is_an_error_naming_the_module(urban: Sequence) -> None:
    with pytest.raises(ModuleError, match="test_forgetful dropped frame 0 in apply"):
        perturb(urban, Forgetful())[0].image


def test_apply_before_setup_and_depth_without_a_provider_are_clear_errors() -> None:
    image = np.zeros((4, 4, 3), np.uint8)
    with pytest.raises(ModuleError, match="call prepare"):
        Recorder().apply(image, None, 0, "left")
    camera = Camera(fx=10, fy=10, cx=2, cy=2, width=4, height=4)
    mono = Sequence(kind="folder", name="tiny", camera=camera, sensor="mono", fps=10, records=[FrameRecord(0, 0.0, "0", lambda: image)])
    with pytest.raises(DepthUnavailable, match=r"test_needs_depth needs depth .*'tiny'.*native: .*no depth maps"):
        perturb(mono, NeedsDepth())
    with pytest.raises(ModuleError, match="needs depth"):
        NeedsDepth().setup(ModuleContext(sequence=mono))


def test_depth_of_the_clean_frame_reaches_depth_aware_modules(urban: Sequence) -> None:
    out = perturb(urban, Square() >> NeedsDepth())
    assert out[0].image.shape == (376, 1240, 3) and out[0].right.shape == (376, 1240, 3)


def test_rng_depends_on_seed_and_keys_only(urban: Sequence) -> None:
    a = ModuleContext(sequence=urban, seed=4).rng("rain", "left", 3).random(3)
    assert np.array_equal(a, ModuleContext(sequence=urban, seed=4).rng("rain", "left", 3).random(3))
    assert not np.array_equal(a, ModuleContext(sequence=urban, seed=4).rng("rain", "right", 3).random(3))
    assert not np.array_equal(a, ModuleContext(sequence=urban, seed=5).rng("rain", "left", 3).random(3))


def test_class_attribute_is_the_declared_parameter_and_instances_are_read_only() -> None:
    assert Square.size.unit == "px" and Square.size.qualname == "test_square.size"
    module = Square(size=3)
    assert module.size == 3 and module.params == {"size": 3, "value": 0}
    with pytest.raises(AttributeError, match="read-only"):
        module.size = 4  # type: ignore[misc]
    with pytest.raises(ParameterError, match=r"test_square: size = 2.5 px is not valid; size must be an integer in 0 .. 1000 px"):
        Square(size=2.5)
