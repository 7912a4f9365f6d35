"""A suite of 8 robustness requirements with the deterministic ``reference_vo`` on the synthetic
worlds, run cold (an empty cache) as ``pytest -n 2`` with the local executor and with
``--sal-executor ray`` (a local Ray of 2 CPUs started for the session), without and with
``-n 2``: the wall time of each, the trials and runs, and whether every boundary agrees.

Run from the repository root (each configuration gets a fresh cache and history folder):

    .venv/bin/python benchmarks/bench_ray_suite.py
    .venv/bin/python benchmarks/bench_ray_suite.py --repeat 2 --json /tmp/ray_suite.jsonl
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

#: The suite: 8 requirements over weather, camera and transport modules (the plugin's default
#: worlds: the urban street for weather, the indoor room for the rest).
SUITE = """
import pytest_sal as sal
from pytest_sal import ate_rmse, tracking_rate
from sal_modules import fog, rain, snow, motion_blur, sensor_noise, jpeg, frame_drop, defocus

ROOM = (ate_rmse < 0.05, tracking_rate >= 0.9)


@sal.require(ate_rmse < 1.5, fog.visibility_m >= 25)
def test_fog(sal_outcome): pass

@sal.require(ate_rmse < 0.5, tracking_rate >= 0.9, rain.intensity_mm_h <= 10)
def test_rain(sal_outcome): pass

@sal.require(ate_rmse < 0.5, tracking_rate >= 0.9, snow.intensity_mm_h <= 10)
def test_snow(sal_outcome): pass

@sal.require(ate_rmse < 0.5, tracking_rate >= 0.9, motion_blur.speed_kmh <= 30)
def test_motion_blur(sal_outcome): pass

@sal.require(*ROOM, sensor_noise.iso <= 1600)
def test_noise(sal_outcome): pass

@sal.require(*ROOM, jpeg.quality >= 20)
def test_jpeg(sal_outcome): pass

@sal.require(*ROOM, frame_drop.drop_rate <= 0.3, tolerance=0.05)
def test_frame_drop(sal_outcome): pass

@sal.require(*ROOM, defocus.f_number >= 2)
def test_defocus(sal_outcome): pass
"""

#: (name, extra pytest arguments)
CONFIGURATIONS = (
    ("local -n 2", ["-n", "2"]),
    ("ray, 2 CPUs", ["--sal-executor", "ray"]),
    ("ray, 2 CPUs, -n 2", ["--sal-executor", "ray", "-n", "2"]),
)


def run_suite(folder: Path, name: str, extra: list[str]) -> dict[str, Any]:
    """The suite run once in a fresh cache: wall time (s), trials, runs and each test's boundary."""
    work = Path(tempfile.mkdtemp(prefix="sal-bench-", dir=folder))
    command = [
        sys.executable,
        "-m",
        "pytest",
        "-q",
        "-p",
        "no:cacheprovider",
        str(folder / "test_suite.py"),
        "-o",
        "sal_system=reference_vo",
        f"--sal-cache-dir={work / 'cache'}",
        f"--sal-history-dir={work / 'history'}",
        *extra,
    ]
    start = time.perf_counter()
    done = subprocess.run(command, cwd=folder, capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=os.getcwd()))
    wall = time.perf_counter() - start
    history = sorted((work / "history").glob("*.json"))
    outcomes = json.loads(history[-1].read_text())["outcomes"] if history else []
    boundaries = {o["test_id"].split("::")[-1]: [o["boundary"]["pass_value"], o["boundary"]["fail_value"]] for o in outcomes}
    return {
        "configuration": name,
        "wall_s": round(wall, 1),
        "exit": done.returncode,
        "tests": len(outcomes),
        "trials": sum(len(o["trials"]) for o in outcomes),
        "runs": sum(len(t["runs"]) for o in outcomes for t in o["trials"]),
        "boundaries": boundaries,
        "tail": done.stdout.strip().splitlines()[-1:] if done.returncode else [],
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1, help="rounds of all configurations")
    parser.add_argument("--json", type=Path, help="append one JSON line per suite run")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="sal-ray-suite-"))
    (folder / "test_suite.py").write_text(SUITE)
    results = []
    for _ in range(args.repeat):
        for name, extra in CONFIGURATIONS:
            results.append(run_suite(folder, name, extra))
            print(json.dumps({k: v for k, v in results[-1].items() if k != "boundaries"}), flush=True)
            if args.json:
                with args.json.open("a") as fh:
                    fh.write(json.dumps(results[-1]) + "\n")
    same = all(r["boundaries"] == results[0]["boundaries"] for r in results)
    print(f"\nload average at the end: {os.getloadavg()[0]:.2f}; every boundary the same in every configuration: {same}")
    print("| configuration | wall (s) | tests | trials | runs |\n|---|---:|---:|---:|---:|")
    for r in results:
        print(f"| {r['configuration']} | {r['wall_s']} | {r['tests']} | {r['trials']} | {r['runs']} |")
    return 0 if same and all(r["exit"] in (0, 1) for r in results) else 1


if __name__ == "__main__":
    raise SystemExit(main())
