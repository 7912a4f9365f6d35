"""Transport modules: bandwidth (H.264/H.265 CBR through PyAV), jpeg and frame_drop.

Bit rates, frame order and chains on the synthetic world and the real KITTI / EuRoC excerpts;
JPEG quality and chroma subsampling; nested frame drops and their round trip through the
writer and reader of every dataset kind.
"""

from __future__ import annotations

import builtins
import dataclasses
import shutil
import warnings
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, ClassVar

import cv2
import numpy as np
import pytest

from sal_adapters import (
    DatasetWarning,
    Sequence,
    open_dataset,
    write_sequence,
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
from sal_modules.transport.frame_drop import FrameDrop
from sal_modules.transport.jpeg import Jpeg


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


# -- data ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def urban() -> Sequence:
    """36 mono frames (3.6 s at 10 Hz) of the synthetic street, decoded once."""
    return cached(open_dataset("synthetic", scene="urban", frames=36, sensor="mono"))


@pytest.fixture(scope="module")
def kitti(shared_data: Path) -> Sequence:
    """40 real KITTI 07 frames (1226x370 grey, 9.6 Hz), decoded once."""
    return cached(open_dataset("kitti", shared_data / "kitti" / "sequences" / "07", max_frames=40))


def cached(sequence: Sequence) -> Sequence:
    """``sequence`` with its left images decoded once and kept in memory."""
    images = [frame.image for frame in sequence]
    records = [dataclasses.replace(r, image=lambda image=image: image) for r, image in zip(sequence.records, images)]
    return sequence.replace(records=records)


def encoded(sequence: Sequence, **params: Any) -> Bandwidth:
    """A bandwidth module with the left stream of ``sequence`` prepared (the bare contract)."""
    module = create("bandwidth", **params)
    module.setup(ModuleContext(sequence=sequence, seed=0))
    module.prepare("left", ((frame.index, frame.image) for frame in sequence))
    return module


def decoded(module: Bandwidth, sequence: Sequence) -> list[np.ndarray]:
    return [module.result(frame.index, "left") for frame in sequence]


def mad(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a.astype(np.float32) - b.astype(np.float32)).mean())


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


# -- jpeg ----------------------------------------------------------------------------------
def jpeg_of(sequence: Sequence, image: np.ndarray, **params: Any) -> np.ndarray:
    module = create("jpeg", **params)
    module.setup(ModuleContext(sequence=sequence))
    return module.apply(image, None, 0, "left")


def test_jpeg_lower_quality_gives_larger_difference(urban: Sequence) -> None:
    image = urban[3].image
    errors = [mad(jpeg_of(urban, image, quality=q), image) for q in (95, 75, 50, 25, 5)]
    assert all(later > earlier for earlier, later in zip(errors, errors[1:])), errors
    assert errors[-1] > 3 * errors[0]


def test_jpeg_quality_100_is_nearly_identical(urban: Sequence, kitti: Sequence) -> None:
    image = urban[3].image
    assert cv2.PSNR(jpeg_of(urban, image, quality=100, chroma_subsampling="4:4:4"), image) > 45.0
    grey = kitti[5].image
    out = jpeg_of(kitti, grey, quality=100)
    assert cv2.PSNR(out, grey) > 45.0 and np.array_equal(out[..., 0], out[..., 2])  # grey stays grey


def test_jpeg_chroma_subsampling_is_honoured(urban: Sequence) -> None:
    """One-pixel red/blue stripes survive only where chroma keeps full resolution."""
    columns = np.zeros((64, 64, 3), np.uint8)
    columns[:, 0::2] = (200, 30, 30)
    columns[:, 1::2] = (30, 30, 200)
    rows = columns.transpose(1, 0, 2).copy()
    error = {
        (name, mode): mad(jpeg_of(urban, pattern, quality=95, chroma_subsampling=mode), pattern)
        for name, pattern in (("columns", columns), ("rows", rows))
        for mode in ("4:4:4", "4:2:2", "4:2:0")
    }
    assert error["columns", "4:4:4"] < 5 < error["columns", "4:2:2"] and error["columns", "4:2:0"] > 5  # halved width
    assert error["rows", "4:4:4"] < 5 and error["rows", "4:2:2"] < 5 < error["rows", "4:2:0"]  # 4:2:0 halves height


def test_jpeg_is_deterministic_and_leaves_its_input_alone(urban: Sequence) -> None:
    image = urban[0].image.copy()
    first, second = jpeg_of(urban, image, quality=20), jpeg_of(urban, image, quality=20)
    np.testing.assert_array_equal(first, second)
    np.testing.assert_array_equal(image, urban[0].image)
    assert isinstance(create("jpeg"), Jpeg)


# -- frame_drop ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def long_street() -> Sequence:
    """2000 frames; frame_drop decides from the index alone, so no image is rendered."""
    return open_dataset("synthetic", scene="urban", frames=2000, sensor="mono")


def dropped(sequence: Sequence, seed: int = 7, **params: Any) -> set[int]:
    return set(sequence.indices.tolist()) - set(perturb(sequence, create("frame_drop", **params), seed=seed).indices.tolist())


def test_frame_drop_sets_are_nested_across_rates(long_street: Sequence) -> None:
    low, mid, high = (dropped(long_street, drop_rate=rate) for rate in (0.1, 0.3, 0.6))
    assert low < mid < high
    assert dropped(long_street, seed=8, drop_rate=0.3) != mid


@pytest.mark.parametrize("rate", [0.05, 0.3, 0.6])
def test_frame_drop_rate_within_binomial_tolerance(long_street: Sequence, rate: float) -> None:
    n = len(long_street)
    count = len(dropped(long_street, drop_rate=rate))
    assert abs(count - n * rate) <= 4 * np.sqrt(n * rate * (1 - rate)), (count, n * rate)


def test_frame_drop_periodic_drops_exactly_every_period_th_frame(long_street: Sequence) -> None:
    assert dropped(long_street, mode="periodic", period=7) == set(range(6, 2000, 7))
    assert dropped(long_street, mode="periodic", period=1) == set(range(2000))


def test_frame_drop_is_searched_in_its_own_unit_a_share_of_the_frames() -> None:
    # one unit for drop_rate in create(), YAML, the DSL and reports: a share 0 .. 1
    scale = FrameDrop.drop_rate.search_space()
    assert (scale.domain, scale.min, scale.max, scale.unit, scale.scale) == ("continuous", 0.0, 1.0, "", "linear")
    assert create("frame_drop", drop_rate=0.3).drop_rate == 0.3
    assert FrameDrop.drop_rate.worse == "higher"
    with pytest.raises(ParameterError, match="drop_rate"):
        create("frame_drop", drop_rate=1.5)


def tum_fr1_xyz(shared_data: Path, root: Path, frames: int = 30) -> Path:
    """The first rows of the real fr1_xyz lists, with small placeholder images."""
    src = shared_data / "trajectories" / "tum_fr1_xyz_txt"
    folder = root / "rgbd_dataset_freiburg1_xyz"
    for sub in ("rgb", "depth"):
        (folder / sub).mkdir(parents=True)
    for name, rows in (("rgb.txt", frames), ("depth.txt", frames), ("groundtruth.txt", 10 * frames)):
        lines = (src / name).read_text().splitlines(True)
        (folder / name).write_text("".join(lines[: 3 + rows]))
    rng = np.random.default_rng(1)
    for name, depth in (("rgb.txt", False), ("depth.txt", True)):
        for line in (folder / name).read_text().splitlines()[3:]:
            image = np.full((6, 8), 5000, np.uint16) if depth else rng.integers(0, 256, (6, 8, 3), dtype=np.uint8)
            assert cv2.imwrite(str(folder / line.split()[1]), image)
    return folder


def open_kind(kind: str, shared_data: Path, root: Path) -> Sequence:
    if kind == "kitti":
        return open_dataset("kitti", shared_data / "kitti" / "sequences" / "07", max_frames=12)
    if kind == "tum":
        with pytest.warns(DatasetWarning, match="have no depth map"):
            return open_dataset("tum", tum_fr1_xyz(shared_data, root))
    if kind == "euroc":
        with pytest.warns(DatasetWarning, match=r"cam1/data\.csv: .* rows skipped"):
            return open_dataset("euroc", shared_data / "euroc" / "V1_01_easy_micro", stereo=True, start=20, max_frames=16)
    if kind == "folder":
        copy = root / "fr3"
        shutil.copytree(shared_data / "tum_rgbd_samples" / "fr3_long_office_household_4frames_pyslam", copy)
        return open_dataset("folder", copy, intrinsics=(535.4, 539.2, 320.1, 247.6))
    return open_dataset("synthetic", scene="indoor", frames=10)


@pytest.mark.parametrize("kind", ["kitti", "tum", "euroc", "folder", "synthetic"])
def test_dropped_frames_vanish_from_every_dataset_layout(kind: str, shared_data: Path, tmp_path: Path) -> None:
    clean = open_kind(kind, shared_data, tmp_path)
    out = perturb(clean, create("frame_drop", mode="periodic", period=2), seed=1)
    positions = [p for p, index in enumerate(clean.indices) if (index + 1) % 2 != 0]
    assert list(out.indices) == [clean.records[p].index for p in positions] and 0 < len(out) < len(clean)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the written copy reopens without complaint
        back = open_dataset(kind, write_sequence(out, tmp_path / "out"), **({"stereo": True} if clean.sensor == "stereo" else {}))
    assert len(back) == len(positions) and back.sensor == clean.sensor
    np.testing.assert_array_equal(back.timestamps, clean.timestamps[positions])
    for frame, p in zip(back, positions):
        np.testing.assert_array_equal(frame.image, clean[p].image)
        if clean.sensor == "stereo":
            np.testing.assert_array_equal(frame.right, clean[p].right)
        if clean.sensor == "rgbd":
            np.testing.assert_array_equal(frame.depth, clean[p].depth)
    if clean.groundtruth_is_per_frame:
        assert back.groundtruth_is_per_frame
        np.testing.assert_allclose(back.groundtruth.positions, clean.groundtruth.positions[positions], atol=1e-9)
    elif clean.groundtruth is not None:  # a trajectory at its own rate is kept whole
        assert back.groundtruth.allclose(clean.groundtruth, atol=1e-9)


def test_random_drops_keep_the_frame_rate_of_a_reopened_copy(shared_data: Path, tmp_path: Path) -> None:
    """KITTI stores no rate: it is measured from times.txt, and the gaps left by dropped
    frames must not lower it (a SLAM config or a later bandwidth step reads it)."""
    clean = open_dataset("kitti", shared_data / "kitti" / "sequences" / "07", max_frames=60)
    out = perturb(clean, create("frame_drop", drop_rate=0.6), seed=2)
    back = open_dataset("kitti", write_sequence(out, tmp_path / "out"))
    assert len(back) < len(clean) and back.fps == pytest.approx(clean.fps, rel=0.01)
