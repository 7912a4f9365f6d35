"""The bandwidth module (H.264/H.265 CBR through PyAV): bit rates on the synthetic world and the
real KITTI excerpt, PSNR, identical bytes, frame count and order, random access, odd sizes, grey
and stereo streams, chains with earlier steps and frame drops, and clear errors."""

from __future__ import annotations

import builtins
import dataclasses
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, ClassVar

import cv2
import numpy as np
import pytest
from transport_sequences import cached, mad

from sal_adapters import (
    Sequence,
    open_dataset,
)
from sal_modules import (
    PERTURBATIONS,
    ModuleContext,
    ModuleError,
    Param,
    ParameterError,
    Perturbation,
    create,
    perturb,
)
from sal_modules.transport.bandwidth import Bandwidth

#: the shared fixtures (kitti, urban)
pytest_plugins = ["transport_sequences"]


# -- test-only modules ---------------------------------------------------------------------
class BlackSquare(Perturbation):
    """Paints a black square at the top left (stands in for lens soiling in a chain)."""

    name = "test_black_square"
    summary = "test: black square"
    size = Param(120, domain="integer", unit="px", min=1, max=1000)

    def apply(self, image, depth, index, stream):  # type: ignore[no-untyped-def]
        out = image.copy()
        out[: self.size, : self.size] = 0
        return out


class SpyBandwidth(Bandwidth):
    """``bandwidth`` that records which frame indices its encoder was given."""

    name = "test_spy_bandwidth"
    seen: ClassVar[dict[str, list[int]]] = {}
    last: ClassVar[list[Bandwidth]] = []

    def prepare(self, stream: str, frames: Iterable[tuple[int, np.ndarray]]) -> None:
        type(self).last[:] = [self]
        seen = type(self).seen.setdefault(stream, [])

        def spy() -> Iterator[tuple[int, np.ndarray]]:
            for index, image in frames:
                seen.append(index)
                yield index, image

        super().prepare(stream, spy())


@pytest.fixture
def registered() -> Iterator[None]:
    for cls in (BlackSquare, SpyBandwidth):
        PERTURBATIONS.register(cls.name, cls)
    SpyBandwidth.seen.clear()
    yield
    for cls in (BlackSquare, SpyBandwidth):
        PERTURBATIONS.unregister(cls.name)


def encoded(sequence: Sequence, **params: Any) -> Bandwidth:
    """A bandwidth module with the left stream of ``sequence`` prepared (the bare contract)."""
    module = create("bandwidth", **params)
    module.setup(ModuleContext(sequence=sequence, seed=0))
    module.prepare("left", ((frame.index, frame.image) for frame in sequence))
    return module


def decoded(module: Bandwidth, sequence: Sequence) -> list[np.ndarray]:
    return [module.result(frame.index, "left") for frame in sequence]


def psnr(clean: Sequence, images: list[np.ndarray]) -> float:
    return float(np.mean([cv2.PSNR(frame.image, image) for frame, image in zip(clean, images)]))


# -- bandwidth: bit rate -------------------------------------------------------------------
@pytest.mark.parametrize("target", [0.5, 2.0])
def test_bandwidth_hits_the_target_rate_on_the_synthetic_street(urban: Sequence, target: float) -> None:
    module = encoded(urban, target_mbps=target)
    duration = len(urban) / urban.fps
    from_bytes = 8 * len(module.bitstream("left")) / duration / 1e6
    assert module.measured_mbps["left"] == pytest.approx(from_bytes)
    assert module.measured_mbps["left"] == pytest.approx(target, rel=0.10)


@pytest.mark.parametrize("target", [0.5, 2.0])
def test_bandwidth_hits_the_target_on_real_kitti_at_its_own_frame_rate(kitti: Sequence, target: float) -> None:
    assert kitti.fps == pytest.approx(9.615, abs=0.01)
    module = encoded(kitti, target_mbps=target)
    assert module.measured_mbps["left"] == pytest.approx(target, rel=0.10)
    # bits per frame follow the sequence's rate: R / f bits each, so ~3.1x fewer at 30 Hz
    at_30 = encoded(kitti.replace(fps=30.0), target_mbps=target)
    per_frame = len(module.bitstream("left")) / len(at_30.bitstream("left"))
    assert per_frame == pytest.approx(30.0 / kitti.fps, rel=0.10)
    # a short clip may overshoot by at most the buffer: 8 sum(b) <= R T + B (B = 0.5 s at R)
    assert at_30.measured_mbps["left"] <= target * (1 + 0.5 / (len(kitti) / 30.0))


def test_bandwidth_lower_rate_gives_lower_psnr(urban: Sequence) -> None:
    quality = [psnr(urban, decoded(encoded(urban, target_mbps=rate), urban)) for rate in (4.0, 1.0, 0.25)]
    assert quality[0] > quality[1] + 1.0 > quality[2] + 2.0, quality
    assert quality[0] > 28.0, quality


def test_bandwidth_same_input_gives_identical_bytes(urban: Sequence) -> None:
    first, second = encoded(urban, target_mbps=1.0), encoded(urban, target_mbps=1.0)
    assert first.bitstream("left") == second.bitstream("left")
    assert first.bitstream("left") != encoded(urban, target_mbps=1.5).bitstream("left")


# -- bandwidth: frames ---------------------------------------------------------------------
def test_bandwidth_keeps_frame_count_and_order(kitti: Sequence) -> None:
    out = perturb(kitti, create("bandwidth", target_mbps=1.0))
    assert list(out.indices) == list(kitti.indices)
    np.testing.assert_array_equal(out.timestamps, kitti.timestamps)
    images = [frame.image for frame in out]
    for i, image in enumerate(images):
        assert image.shape == kitti[i].image.shape and image.dtype == np.uint8
        own = mad(image, kitti[i].image)
        for j in (i - 1, i + 1):
            if 0 <= j < len(kitti):
                assert own < mad(image, kitti[j].image), f"decoded frame {i} looks like input {j}"


def test_bandwidth_random_access_matches_sequential_decoding(urban: Sequence) -> None:
    module = encoded(urban, target_mbps=1.0, gop_frames=10)
    sequential = [image.copy() for image in decoded(module, urban)]
    for position in (33, 4, 4, 25, 12, 35, 0):
        np.testing.assert_array_equal(module.result(urban[position].index, "left"), sequential[position])


def test_bandwidth_pads_odd_sizes_and_crops_them_back(kitti: Sequence) -> None:
    width, height = 1225, 369
    records = [dataclasses.replace(r, image=lambda r=r: kitti[r.index].image[:height, :width]) for r in kitti.records[:12]]
    odd = kitti.replace(records=records, camera=dataclasses.replace(kitti.camera, width=width, height=height), groundtruth=None)
    module = encoded(odd, target_mbps=20.0)
    images = decoded(module, odd)
    assert all(image.shape == (height, width, 3) for image in images)
    assert psnr(odd, images) > 35.0
    # the last column and row are real picture, not the padding
    for frame, image in zip(odd, images):
        assert mad(image[:, -1], frame.image[:, -1]) < 6.0 and mad(image[-1], frame.image[-1]) < 6.0


def test_bandwidth_keeps_grey_datasets_grey(shared_data: Path) -> None:
    euroc = cached(open_dataset("euroc", shared_data / "euroc" / "V1_01_easy_micro", max_frames=40))
    assert euroc.grayscale and euroc.fps == 20.0
    module = encoded(euroc, target_mbps=1.0)
    assert module.measured_mbps["left"] == pytest.approx(1.0, rel=0.10)
    images = decoded(module, euroc)
    assert all(np.array_equal(image[..., 0], image[..., 1]) and np.array_equal(image[..., 0], image[..., 2]) for image in images)
    assert psnr(euroc, images) > 30.0


def test_bandwidth_stereo_streams_are_coded_separately() -> None:
    stereo = open_dataset("synthetic", scene="urban", frames=8)
    out = perturb(stereo, create("bandwidth", target_mbps=2.0))
    for clean, frame in zip(stereo, out):
        assert mad(frame.image, clean.image) < mad(frame.image, clean.right)
        assert mad(frame.right, clean.right) < mad(frame.right, clean.image)


# -- bandwidth: chains ---------------------------------------------------------------------
def test_bandwidth_codes_what_earlier_steps_produced(urban: Sequence, registered: None) -> None:
    clean = urban.select(range(8))
    assert clean[0].image[:120, :120].mean() > 40
    out = perturb(clean, create("test_black_square") >> create("bandwidth", target_mbps=1.0))
    for frame in out:
        assert frame.image[8:112, 8:112].mean() < 8.0  # the square went through the codec
        assert frame.image[200:, 400:].mean() > 40.0


def test_frame_drop_before_bandwidth_encodes_only_kept_frames(urban: Sequence, registered: None) -> None:
    out = perturb(urban, create("frame_drop", drop_rate=0.3) >> create("test_spy_bandwidth", target_mbps=1.0), seed=4)
    kept = list(out.indices)
    assert 0 < len(kept) < len(urban)
    images = [frame.image for frame in out]
    assert SpyBandwidth.seen == {"left": kept}
    positions = {index: p for p, index in enumerate(urban.indices)}
    for index, image in zip(kept, images):
        own = mad(image, urban[positions[index]].image)
        assert all(own < mad(image, urban[p].image) for p in (positions[index] - 1, positions[index] + 1) if 0 <= p < len(urban))
    # x264 rate control follows the time stamps: the link still carries the target rate
    assert SpyBandwidth.last[0].measured_mbps["left"] == pytest.approx(1.0, rel=0.15)


def test_bandwidth_h265_and_capped_variable_rate(urban: Sequence) -> None:
    clip = urban.select(range(20))
    hevc = encoded(clip, target_mbps=1.0, codec="h265", preset="ultrafast")
    assert hevc.bitstream("left")[:4] == b"\x00\x00\x00\x01"
    assert hevc.measured_mbps["left"] == pytest.approx(1.0, rel=0.10)
    assert psnr(clip, decoded(hevc, clip)) > 22.0
    capped = encoded(clip, target_mbps=1.0, max_mbps=3.0, buffer_mbit=1.0)
    assert capped.measured_mbps["left"] <= 1.0 + 1.0 / (len(clip) / clip.fps) + 0.05


def test_bandwidth_errors_are_clear(urban: Sequence, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(ParameterError, match=r"bandwidth: max_mbps = 1 Mbit/s is below target_mbps = 2 Mbit/s"):
        create("bandwidth", target_mbps=2.0, max_mbps=1.0)
    module = create("bandwidth")
    module.setup(ModuleContext(sequence=urban))
    with pytest.raises(ModuleError, match=r"call prepare\('left', frames\) first"):
        module.apply(urban[0].image, None, 0, "left")
    module.prepare("left", ((f.index, f.image) for f in urban.select([0, 1])))
    with pytest.raises(ModuleError, match="frame 5 was not among the frames"):
        module.result(5, "left")
    real_import = builtins.__import__

    def no_av(name: str, *args: Any, **kwargs: Any) -> Any:
        if name == "av":
            raise ImportError("No module named 'av'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_av)
    with pytest.raises(ModuleError, match=r"pip install 'pytest-sal\[video\]'"):
        create("bandwidth").setup(ModuleContext(sequence=urban))
