"""Wall time per frame of each SLAM system on the synthetic world, and the share of a trial
spent outside SLAM.

A trial is what the plugin does for one severity: open the (already rendered) dataset,
perturb it (fog at 150 m, computed lazily while the system runs), run the system, score the
trajectory with evo. Timed parts:

* ``track ms/frame``: time inside the system's per-frame tracking calls / frames given;
* ``run s``: the system's ``run()`` (child process start, vocabulary load, frame production in
  the parent, tracking, shutdown and saving for ORB-SLAM3);
* ``trial s``: the whole trial;
* ``SLAM s``: time the system spent on the frames: its tracking calls, plus for paced ORB-SLAM3
  the waits for the sensor clock (the child's tracking loop);
* ``outside SLAM``: ``1 - SLAM time / trial time``: loading, perturbing (what the prefetch thread
  does not overlap), child start-up and vocabulary load, writing and evaluating (target: under
  20 %).

ORB-SLAM3 runs twice: paced at the sensor rate (the default, as the plugin runs it) and fed as
fast as it takes frames (``pace=False``). The depth cache is warm after the first trial, as in
a boundary search. Prints a Markdown table; ``--write`` replaces the systems section of
benchmarks/RESULTS.md. Run from the repository root:

    .venv/bin/python benchmarks/bench_systems.py --write
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from results_file import write_section  # benchmarks/ is on sys.path when run as a script

from pytest_sal.analysis.metrics import evaluate
from sal_adapters import open_dataset
from sal_modules import create as create_module
from sal_modules import perturb
from sal_wrappers import create

#: (label, dataset options) of the synthetic world.
WORLDS: list[tuple[str, dict[str, Any]]] = [
    ("urban stereo 1240x376", {"scene": "urban", "sensor": "stereo"}),
    ("indoor RGB-D 640x480", {"scene": "indoor", "sensor": "rgbd"}),
]
#: (system, options) contenders.
SYSTEMS: list[tuple[str, dict[str, Any]]] = [("reference_vo", {}), ("orbslam3", {"pace": True}), ("orbslam3", {"pace": False})]


def trial(system: str, options: dict[str, Any], world: dict[str, Any], frames: int, workdir: Path) -> dict[str, float]:
    """Time one trial; returns the figures of the table."""
    start = time.perf_counter()
    clean = open_dataset("synthetic", frames=frames, **world)
    foggy = perturb(clean, create_module("fog", visibility_m=150.0), seed=0)
    result = create(system, **options).run(foggy, workdir, timeout=600)
    metrics = evaluate(result, clean.groundtruth)
    trial_s = time.perf_counter() - start
    track_s = result.track_time_s or 0.0
    slam_s = result.info.get("loop_time_s") or track_s
    return {
        "track_ms": 1e3 * track_s / max(result.frames, 1),
        "run_s": result.wall_time_s,
        "slam_s": slam_s,
        "trial_s": trial_s,
        "outside": 1.0 - slam_s / trial_s,
        "tracking_rate": result.tracking_rate,
        "ate_cm": float("nan") if metrics.ate_rmse is None else 100 * metrics.ate_rmse,
        "failure": result.failure or "",
    }


def table(frames: int, repeats: int) -> str:
    lines = [
        "| system | world | track ms/frame | run s | SLAM s | trial s | outside SLAM | tracking rate | ATE RMSE cm |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for label, world in WORLDS:
        clean = open_dataset("synthetic", frames=frames, **world)
        for frame in clean:  # render once: later trials read the disk cache, as in practice
            _ = (frame.image, frame.right, frame.depth)
        for system, options in SYSTEMS:
            name = system + ("" if "pace" not in options else " (paced)" if options["pace"] else " (unpaced)")
            runs = []
            for _ in range(repeats):
                with tempfile.TemporaryDirectory() as workdir:
                    runs.append(trial(system, options, world, frames, Path(workdir)))
            med = {k: float(np.median([r[k] for r in runs])) for k in runs[0] if k != "failure"}
            failures = "; ".join(sorted({r["failure"] for r in runs if r["failure"]}))
            lines.append(
                f"| {name} | {label} | {med['track_ms']:.1f} | {med['run_s']:.1f} | {med['slam_s']:.1f} | {med['trial_s']:.1f} | "
                f"{100 * med['outside']:.0f} % | {med['tracking_rate']:.2f} | {med['ate_cm']:.2f} |" + (f" {failures}" if failures else "")
            )
            print(lines[-1], flush=True)
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=100, help="frames per trial (default 100)")
    parser.add_argument("--repeats", type=int, default=3, help="trials per system and world; the median is shown (default 3)")
    parser.add_argument("--write", action="store_true", help="replace the systems section of benchmarks/RESULTS.md")
    args = parser.parse_args()
    result = table(args.frames, args.repeats)
    header = (
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"numpy {np.__version__}, OpenCV {cv2.__version__}. {args.frames} frames per trial, fog at 150 m, "
        f"median of {args.repeats} trials."
    )
    print(header + "\n\n" + result)
    if args.write:
        write_section("systems", "SLAM systems", header + "\n\n" + result)


if __name__ == "__main__":
    main()
