"""ORB-SLAM3 on KITTI 07 (mono, 140 frames, paced at the sensor rate) beside N other ORB-SLAM3
runs: does each run keep up with the sensor clock, and when not, is it re-paced and marked?

For each of ``--runs`` runs (one after the other) it prints: frames tracked, whether the first
attempt fell behind, the attempts and final pace, whether the result still fell behind
(``RunResult.fell_behind``), the first attempt's late frames and max lateness, overrun, CPU
per wall second and load averages, and the wall time. ``--load N`` starts
``shared/tools/oversubscribe.py N`` (N more ORB-SLAM3 runs of KITTI 07, forever) first and
ends its process group afterwards. Run from the repository root:

    .venv/bin/python benchmarks/bench_load.py --runs 4 --load 7 --json /tmp/load7.jsonl
    .venv/bin/python benchmarks/bench_load.py --runs 3 --load 0
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from sal_adapters import open_dataset
from sal_wrappers import create

SHARED = Path(__file__).resolve().parents[2] / "shared"
DATA = SHARED / "data" / "kitti"
OVERSUBSCRIBE = SHARED / "tools" / "oversubscribe.py"


def one_run(workdir: Path, **options: Any) -> dict[str, Any]:
    """One KITTI 07 run; the figures of the table."""
    sequence = open_dataset("kitti", str(DATA), sequence="07")
    result = create("orbslam3", **options).run(sequence, workdir, timeout=600)
    attempts = result.info.get("attempts") or [{"load": result.load, "pace": result.load.get("pace")}]
    first = attempts[0]["load"]
    return {
        "tracked": result.tracked,
        "frames": result.frames,
        "first_fell_behind": bool(first.get("fell_behind")),
        "first_late": f"{first.get('late_frames')}/{first.get('frames')}",
        "first_lateness_max_ms": first.get("lateness_ms_max"),
        "first_overrun": first.get("overrun"),
        "first_cpu_per_wall": first.get("cpu_per_wall"),
        "attempts": len(attempts),
        "paces": [a["pace"] for a in attempts],
        "tracked_per_attempt": [a.get("tracked") for a in attempts],
        "final_pace": result.load.get("pace"),
        "final_late": f"{result.load.get('late_frames')}/{result.load.get('frames')}",
        "final_overrun": result.load.get("overrun"),
        "fell_behind": result.fell_behind,
        "loadavg_start": first.get("loadavg_start"),
        "loadavg_end": result.load.get("loadavg_end"),
        "wall_s": round(result.wall_time_s, 1),
        "wall_all_attempts_s": round(sum(a.get("wall_time_s", result.wall_time_s) for a in attempts), 1),
        "failure": result.failure,
        "summary": result.summary(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=4)
    parser.add_argument("--load", type=int, default=7, help="other ORB-SLAM3 runs going at the same time (oversubscribe.py N)")
    parser.add_argument("--warmup", type=float, default=20.0, help="seconds to let the other runs start (s)")
    parser.add_argument("--retries", type=int, default=2, help="load_retries of the measured runs")
    parser.add_argument("--json", type=Path, help="append one JSON line per run here")
    args = parser.parse_args()
    helper = None
    if args.load > 0:
        helper = subprocess.Popen([sys.executable, str(OVERSUBSCRIBE), str(args.load)])
        time.sleep(args.warmup)
    try:
        print(
            "| run | tracked | 1st attempt fell behind (late frames, max lateness, overrun) | attempts | paces | fell_behind | load avg start/end | wall s (all attempts) |"
        )
        print("|---|---:|---|---:|---|---|---|---:|")
        for number in range(1, args.runs + 1):
            with tempfile.TemporaryDirectory() as work:
                row = one_run(Path(work), load_retries=args.retries)
            row.update(run=number, load=args.load)
            if args.json:
                with args.json.open("a") as out:
                    out.write(json.dumps(row) + "\n")
            print(
                f"| {number} | {row['tracked']}/{row['frames']} | {'yes' if row['first_fell_behind'] else 'no'} "
                f"({row['first_late']}, {row['first_lateness_max_ms']:.0f} ms, {100 * row['first_overrun']:+.0f} %) | {row['attempts']} | "
                f"{', '.join(f'{p:g}' for p in row['paces'])} | {row['fell_behind']} | "
                f"{row['loadavg_start'][0]:.1f}/{row['loadavg_end'][0]:.1f} | {row['wall_s']} ({row['wall_all_attempts_s']}) |",
                flush=True,
            )
    finally:
        if helper is not None:
            try:
                os.killpg(helper.pid, signal.SIGKILL)  # oversubscribe.py calls setpgrp: its own group
            except ProcessLookupError:
                pass
            helper.wait()


if __name__ == "__main__":
    main()
