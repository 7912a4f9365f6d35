"""Frames per second of the synthetic-world renderer on one CPU thread.

Renders frames of both scenes straight from the renderer (no disk cache), after a warm-up
(texture atlas painted, first frames rendered), and prints a Markdown table of the median
time per frame over ``--frames`` frames for left image + depth and for left + right + depth.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_synthetic_render.py
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"  # before numpy is imported

import argparse  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from sal_adapters.synthetic import WORLDS  # noqa: E402


def median_ms(render, frames: range) -> float:
    """Median wall time (ms) of ``render(i)`` over ``frames``."""
    times = []
    for i in frames:
        start = time.perf_counter()
        render(i)
        times.append(time.perf_counter() - start)
    return float(np.median(times) * 1e3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=30, help="timed frames per case (default 30)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    rows = []
    for scene in ("indoor", "urban"):
        world = WORLDS[scene](args.seed)
        for i in range(3):  # warm-up: paints the atlas, fills caches
            world.render(i)
            world.render(i, right=True)
        timed = range(10, 10 + args.frames)
        _, _, _, _, width, height = world.intrinsics
        left = median_ms(world.render, timed)
        both = median_ms(lambda i, world=world: (world.render(i), world.render(i, right=True)), timed)
        rows.append((scene, f"{width}x{height}", "left + depth", left))
        rows.append((scene, f"{width}x{height}", "left + right + depth", both))
    print(
        f"Python {platform.python_version()}, numpy {np.__version__}, OpenCV {cv2.__version__}, {platform.machine()}, 1 thread, median of {args.frames} frames\n"
    )
    print("| scene | size (px) | output | ms / frame | frames / s |")
    print("|---|---|---|---:|---:|")
    for scene, size, output, ms in rows:
        print(f"| {scene} | {size} | {output} | {ms:.1f} | {1000.0 / ms:.1f} |")


if __name__ == "__main__":
    main()
