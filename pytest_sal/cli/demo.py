"""``sal demo``: render the synthetic world and show what was made.

Grows with later parts of the product (perturbation, SLAM run, boundary search); today it
renders both scenes, reports camera, ground truth and render speed, and writes contact sheets.
"""

from __future__ import annotations

import time
from pathlib import Path

from tqdm.auto import tqdm

from pytest_sal.report.contact_sheet import contact_sheet
from sal_adapters import open_dataset
from sal_adapters.images import write_image

__all__ = ["DEMO_SCENES", "run_demo"]

#: (scene, sensor) pairs the demo renders.
DEMO_SCENES: tuple[tuple[str, str], ...] = (("urban", "stereo"), ("indoor", "rgbd"))


def run_demo(frames: int, seed: int, out_dir: Path) -> list[Path]:
    """Render each demo scene, print a summary and write ``<out_dir>/<scene>.png``; returns the
    written image paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for scene, sensor in DEMO_SCENES:
        seq = open_dataset("synthetic", scene=scene, frames=frames, seed=seed, sensor=sensor)
        began = time.perf_counter()
        for frame in tqdm(seq, total=len(seq), desc=f"rendering {scene}", unit="frame", leave=False):
            _ = (frame.image, frame.right, frame.depth)  # decode or render (and cache) every part
        seconds = time.perf_counter() - began
        cam = seq.camera
        gt = seq.groundtruth
        sheet = out_dir / f"{scene}.png"
        write_image(sheet, contact_sheet(seq))
        written.append(sheet)
        baseline = "" if cam.baseline_m is None else f", baseline {cam.baseline_m:.2f} m"
        print(f"{seq.name}: {len(seq)} {sensor} frames {cam.width}x{cam.height} px at {seq.fps:g} Hz, fx {cam.fx:.1f} px{baseline}")
        if gt is not None:
            speed = gt.path_length() / max(seq.timestamps[-1] - seq.timestamps[0], 1e-9)
            print(f"  ground truth: {len(gt)} poses, path {gt.path_length():.2f} m, mean speed {speed:.2f} m/s")
        print(f"  ready in {seconds:.2f} s ({len(seq) / max(seconds, 1e-9):.1f} frames/s, rendered or read from the cache)")
        print(f"  cache: {seq.source}")
        print(f"  preview: {sheet}")
    return written
