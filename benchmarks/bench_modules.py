"""Milliseconds per frame of every perturbation module, beside albumentations and imagecorruptions.

Runs on one core (thread variables set before numpy loads, ``cv2.setNumThreads(1)``) on the
same frames for every contender: synthetic urban frames padded to KITTI's 1241x376 and
synthetic indoor frames at 640x480, with their exact depth (the right camera of the stereo
pair, so that stereo_desync, which changes only that camera, does its work). Our modules are timed through
``apply`` after ``setup`` (per-sequence work such as crack patterns is reported apart);
``bandwidth`` is timed as encode + decode of a whole sequence divided by its frames. Peers are
called with comparable settings (see PEERS). Prints a Markdown table, and with ``--write``
replaces the module section of benchmarks/RESULTS.md.

The peers pull opencv-python next to our headless OpenCV, so use a separate environment:

    python3 -m venv .venv-bench && .venv-bench/bin/pip install -e '.[all,bench]'
    .venv-bench/bin/python benchmarks/bench_modules.py --write
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"  # before numpy is imported

import argparse  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from dataclasses import replace  # noqa: E402
from typing import Any  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from results_file import write_section  # noqa: E402  (benchmarks/ is on sys.path when run as a script)

from sal_adapters import FrameRecord, Sequence, open_dataset  # noqa: E402
from sal_modules import (  # noqa: E402
    PERTURBATIONS,
    ModuleContext,
    SequencePerturbation,
    create,
)
from sal_modules.depth import NativeDepth, StereoDepth  # noqa: E402

#: Moderate settings of our modules (the work per frame, not the look, matters here).
SETTINGS: dict[str, dict[str, Any]] = {
    "fog": {"visibility_m": 50.0},
    "fog (heterogeneous)": {"visibility_m": 50.0, "heterogeneity": 0.5},
    "rain": {"intensity_mm_h": 25.0},
    "snow": {"intensity_mm_h": 5.0},
    "night": {"illuminance_lux": 5.0},
    "sensor_noise": {"iso": 1600},
    "sun_glare": {},
    "lens_soiling": {"particles": 40},
    "cracked_lens": {},
    "defocus": {"focal_length_mm": 12.0, "f_number": 2.0, "focus_distance_m": 2.0},  # ~4 px blur radius far away
    "motion_blur": {"speed_kmh": 50.0, "exposure_ms": 20.0},  # streaks up to ~35 px near the edges
    "rolling_shutter": {"readout_ms": 30.0},
    "stereo_desync": {"delay_ms": 50.0},
    "jpeg": {"quality": 30},
    "bandwidth": {"target_mbps": 1.0},
    "frame_drop": {"drop_rate": 0.3},
}


def _albumentations(name: str, **kwargs: Any) -> Callable[[np.ndarray], np.ndarray]:
    import albumentations as A

    transform = getattr(A, name)(p=1.0, **kwargs)
    return lambda image: transform(image=image)["image"]


def _imagecorruptions(name: str, severity: int = 3) -> Callable[[np.ndarray], np.ndarray]:
    if not hasattr(np, "float_"):
        np.float_ = np.float64  # imagecorruptions 1.1.2 still uses the alias NumPy 2 removed
    from imagecorruptions import corrupt

    return lambda image: corrupt(image, corruption_name=name, severity=severity)


#: Peer transforms doing comparable work: (label, factory).
PEERS: dict[str, list[tuple[str, Callable[[], Callable[[np.ndarray], np.ndarray]]]]] = {
    "fog": [
        ("albumentations RandomFog", lambda: _albumentations("RandomFog", fog_coef_range=(0.3, 0.3))),
        ("imagecorruptions fog", lambda: _imagecorruptions("fog")),
    ],
    "rain": [("albumentations RandomRain", lambda: _albumentations("RandomRain"))],
    "snow": [
        ("albumentations RandomSnow", lambda: _albumentations("RandomSnow")),
        ("imagecorruptions snow", lambda: _imagecorruptions("snow")),
    ],
    "night": [
        ("albumentations RandomBrightnessContrast", lambda: _albumentations("RandomBrightnessContrast", brightness_limit=(-0.5, -0.5))),
        ("imagecorruptions brightness", lambda: _imagecorruptions("brightness")),
    ],
    "sensor_noise": [
        ("albumentations ISONoise", lambda: _albumentations("ISONoise")),
        ("imagecorruptions shot_noise", lambda: _imagecorruptions("shot_noise")),
    ],
    "sun_glare": [("albumentations RandomSunFlare", lambda: _albumentations("RandomSunFlare"))],
    "lens_soiling": [
        ("albumentations Spatter (mud)", lambda: _albumentations("Spatter", mode="mud")),
        ("imagecorruptions spatter", lambda: _imagecorruptions("spatter")),
    ],
    "defocus": [
        ("albumentations Defocus (radius 4 px)", lambda: _albumentations("Defocus", radius=(4, 4))),
        ("imagecorruptions defocus_blur", lambda: _imagecorruptions("defocus_blur")),
    ],
    "motion_blur": [
        ("albumentations MotionBlur (31 px kernel)", lambda: _albumentations("MotionBlur", blur_limit=(31, 31))),
        ("imagecorruptions motion_blur", lambda: _imagecorruptions("motion_blur")),
    ],
    "jpeg": [
        ("albumentations ImageCompression", lambda: _albumentations("ImageCompression", quality_range=(30, 30))),
        ("imagecorruptions jpeg_compression", lambda: _imagecorruptions("jpeg_compression")),
    ],
}


def bench_frames(scene: str, frames: int, width: int | None = None) -> Sequence:
    """Synthetic frames decoded into memory, optionally padded on the right to ``width``."""
    source = open_dataset("synthetic", scene=scene, frames=frames, sensor="stereo")
    pad = 0 if width is None else width - source.camera.width

    def widen(array: np.ndarray) -> np.ndarray:
        return cv2.copyMakeBorder(array, 0, 0, 0, pad, cv2.BORDER_REPLICATE) if pad else array

    records = []
    for frame in source:
        left, right, depth = widen(frame.image), widen(frame.right), widen(frame.depth)
        records.append(FrameRecord(frame.index, frame.timestamp, frame.record.stem, lambda a=left: a, lambda a=right: a, lambda a=depth: a))
    camera = replace(source.camera, width=source.camera.width + pad)
    return source.replace(records=records, camera=camera, content_key=f"bench:{scene}:{camera.width}")


#: Rounds of ``count`` timed calls; the best round's median is reported (see ``median_ms``).
ROUNDS = 3


def median_ms(call: Callable[[int], Any], count: int) -> float:
    """Wall time (ms) of ``call(i)``, i in 0..count-1: the median of each of ``ROUNDS`` rounds,
    and the lowest of those. On a shared machine the load drifts by tens of percent within a
    minute; as with ``timeit``, the best round is the one least disturbed."""
    best = float("inf")
    for _ in range(ROUNDS):
        times = []
        for i in range(count):
            start = time.perf_counter()
            call(i)
            times.append(time.perf_counter() - start)
        best = min(best, float(np.median(times)))
    return best * 1e3


def time_module(label: str, sequence: Sequence, repeats: int) -> tuple[float, float]:
    """(setup ms, ms per frame) of one of our modules on ``sequence``."""
    name = label.split(" ")[0]
    module = create(name, **SETTINGS[label])
    depth = NativeDepth().lookup(sequence)
    start = time.perf_counter()
    module.setup(ModuleContext(sequence=sequence, seed=1, depth=depth))
    setup_ms = (time.perf_counter() - start) * 1e3
    frames = [(f.index, f.right, depth(f.index, "right")) for f in sequence]  # right: stereo_desync changes only it
    if isinstance(module, SequencePerturbation):
        start = time.perf_counter()
        module.prepare("right", ((i, image) for i, image, _ in frames))
        for i, _, _ in frames:
            module.result(i, "right")
        per_frame = (time.perf_counter() - start) * 1e3 / len(frames)
    else:
        for index, image, depth_map in frames[:3]:  # warm-up: buffers, tables, page faults
            module.apply(image, depth_map, index, "right")
        per_frame = median_ms(
            lambda k: module.apply(frames[k % len(frames)][1], frames[k % len(frames)][2], frames[k % len(frames)][0], "right"), repeats
        )
    module.cleanup()
    return setup_ms, per_frame


def time_peer(factory: Callable[[], Callable[[np.ndarray], np.ndarray]], sequence: Sequence, repeats: int) -> float | str:
    try:
        transform = factory()
        images = [f.right for f in sequence]
        for image in images[:3]:
            transform(image)
        return median_ms(lambda k: transform(images[k % len(images)]), repeats)
    except Exception as exc:  # a peer that cannot run here is reported, not fatal
        return f"failed: {type(exc).__name__}: {str(exc)[:60]}"


def table(repeats: int, frames: int) -> str:
    sizes = {"1241x376": bench_frames("urban", frames, width=1241), "640x480": bench_frames("indoor", frames)}
    available = set(PERTURBATIONS.names())
    lines = [
        "| module | contender | 1241x376 ms/frame | 640x480 ms/frame | setup ms (1241x376) |",
        "|---|---|---:|---:|---:|",
    ]
    for label in SETTINGS:
        if label.split(" ")[0] not in available:
            continue
        ours = {size: time_module(label, seq, repeats) for size, seq in sizes.items()}
        lines.append(
            f"| {label} | **pytest-sal** | **{ours['1241x376'][1]:.1f}** | **{ours['640x480'][1]:.1f}** | {ours['1241x376'][0]:.0f} |"
        )
        for peer, factory in PEERS.get(label, []):
            cells = [time_peer(factory, seq, repeats) for seq in sizes.values()]
            shown = [f"{c:.1f}" if isinstance(c, float) else c for c in cells]
            lines.append(f"| {label} | {peer} | {shown[0]} | {shown[1]} | |")
        print(lines[-1], flush=True)
    lines += ["", "| depth provider | 1241x376 ms/frame | 640x480 ms/frame |", "|---|---:|---:|"]
    stereo = [
        median_ms(lambda k, seq=seq: StereoDepth().compute(seq, k % len(seq), "left"), max(3, repeats // 4)) for seq in sizes.values()
    ]
    lines.append(f"| stereo SGBM (3-way, hole filling), per stream | {stereo[0]:.1f} | {stereo[1]:.1f} |")
    return "\n".join(lines)


def main() -> None:
    global ROUNDS
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20, help="timed calls per contender and size (default 20)")
    parser.add_argument("--frames", type=int, default=12, help="distinct frames cycled through (default 12)")
    parser.add_argument(
        "--rounds", type=int, default=ROUNDS, help=f"rounds per contender and size; the best round's median is reported (default {ROUNDS})"
    )
    parser.add_argument("--write", action="store_true", help="replace the module section of benchmarks/RESULTS.md")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    ROUNDS = max(1, args.rounds)
    result = table(args.repeats, args.frames)
    header = (
        f"Machine: {platform.machine()}, {os.cpu_count()} cores (one used), Python {platform.python_version()}, "
        f"numpy {np.__version__}, OpenCV {cv2.__version__}. Median of {args.repeats} calls over {args.frames} frames, "
        f"best of {ROUNDS} rounds."
    )
    print(header + "\n\n" + result)
    if args.write:
        write_section("modules", "Perturbation modules", header + "\n\n" + result)


if __name__ == "__main__":
    main()
