"""The child process of an ORB-SLAM3 run, and the frame messages the parent sends it.

``track`` runs in the child (``sal_wrappers.child_process``): it builds ``pyorbslam3.Slam``,
tracks every frame (paced to the sensor clock when asked), shuts down and saves the final
trajectory. It writes its per-frame record (ORB-SLAM3 states, ``pose_wc`` of tracked frames,
tracking times, when each frame was given, CPU usage) about once a second and before each
step that may crash, so a crash or a timeout still leaves what was tracked.

Early stop: the header's ``stop`` (a ``StopCheck``, unpickled here) is asked after each frame
with the ``TrackState`` of every frame so far (ORB-SLAM3 reports a frame's state once, so each
is final) and the header's ``frames``. When it gives a reason the child tracks no more frames,
records it as ``stopped``, shuts down and saves no final trajectory (that of a partial run);
the parent's further frames then meet a closed pipe.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from sal_adapters import Sequence
from sal_wrappers.base import StopCheck, TrackState
from sal_wrappers.child_process import write_result
from sal_wrappers.orbslam3.states import TRACKED, track_state
from sal_wrappers.pacing import process_usage

__all__ = ["ENTRY", "frame_messages", "track"]

#: ``run_child``'s name of ``track``.
ENTRY = "sal_wrappers.orbslam3.child:track"
_SENSORS = {"mono": "MONOCULAR", "stereo": "STEREO", "rgbd": "RGBD"}
#: Seconds between two writes of the child's per-frame records while tracking.
_FLUSH_INTERVAL_S = 1.0


def frame_messages(sequence: Sequence, mode: str) -> Iterator[dict[str, Any]]:
    """The messages for the child: time (s), grey left image, grey right image (stereo) and
    float32 depth in metres with 0 where unknown (RGB-D)."""
    for frame in sequence:
        message: dict[str, Any] = {"timestamp": float(frame.timestamp), "image": _grey(frame.image)}
        if mode == "stereo":
            message["right"] = _grey(frame.require("right"))
        elif mode == "rgbd":
            depth = np.asarray(frame.depth, dtype=np.float32)
            message["depth"] = np.where(np.isfinite(depth) & (depth > 0), depth, np.float32(0.0))
        yield message


def track(header: dict[str, Any], frames: Iterator[dict[str, Any]], result_path: Path) -> None:
    """Child-process entry point: build ``pyorbslam3.Slam``, track every frame (paced), then
    shut down and save the final trajectory; writes the per-frame records to ``result_path``
    before each step that may crash."""
    import pyorbslam3

    record: dict[str, Any] = {
        "phase": "loading",
        "raw_states": [],
        "poses": [],
        "track_times": [],
        "given": [],
        "points": [],
        "final_saved": False,
    }
    write_result(result_path, record)
    start = time.perf_counter()
    sensor = getattr(pyorbslam3.Sensor, _SENSORS[header["sensor"]])
    slam = pyorbslam3.Slam(header["vocabulary"], header["settings"], sensor, use_viewer=False)
    record["load_time_s"] = time.perf_counter() - start
    record["phase"] = "tracking"
    write_result(result_path, record)
    usage = _LoopUsage()
    _track_frames(slam, header, frames, record, result_path, usage)
    record["loop_time_s"] = time.perf_counter() - usage.loop_start  # tracking and waiting for the sensor clock
    record["usage"] = usage.figures()
    record["phase"] = "shutdown"
    write_result(result_path, record)
    slam.shutdown()
    final_path = header.get("final_path")
    if final_path and not record.get("stopped") and any(s in TRACKED for s in record["raw_states"]):
        record["phase"] = "saving"
        write_result(result_path, record)
        slam.save_trajectory_euroc(str(final_path))
        record["final_saved"] = Path(final_path).is_file()
    record["phase"] = "done"
    write_result(result_path, record)


def _track_frames(
    slam: Any, header: dict[str, Any], frames: Iterator[dict[str, Any]], record: dict[str, Any], result_path: Path, usage: _LoopUsage
) -> None:
    """Give every frame to ``slam`` (no earlier than the sensor clock at ``header["pace"]``
    allows) and append its results to ``record``, written about once a second; stop early
    when the header's ``stop`` says so (``record["stopped"]``: why)."""
    stop = _StopWatch(header["stop"], int(header["frames"])) if header.get("stop") is not None else None
    pace = header.get("pace")
    mode = header["sensor"]
    stall = float(header.get("stall_s") or 0.0)
    previous: tuple[float, float] | None = None  # (frame time, wall time it was given)
    last_flush = usage.loop_start
    for frame in frames:
        t = float(frame["timestamp"])
        if pace and previous is not None:
            delay = previous[1] + (t - previous[0]) / pace - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        given = time.perf_counter()
        if mode == "stereo":
            result = slam.track_stereo(frame["image"], frame["right"], t)
        elif mode == "rgbd":
            result = slam.track_rgbd(frame["image"], frame["depth"], t)
        else:
            result = slam.track_monocular(frame["image"], t)
        record["track_times"].append(time.perf_counter() - given)
        record["given"].append(given - usage.loop_start)
        previous = (t, given)
        if stall:
            time.sleep(stall)
        state = int(result.state)
        record["raw_states"].append(state)
        record["poses"].append(np.asarray(result.pose_wc, dtype=np.float64).ravel().tolist() if state in TRACKED else None)
        record["points"].append(int(result.num_tracked_points))
        if stop is not None and (stopped := stop.after(state)) is not None:
            record["stopped"] = stopped
            break
        if time.perf_counter() - last_flush > _FLUSH_INTERVAL_S:
            record["usage"] = usage.figures()
            write_result(result_path, record)
            last_flush = time.perf_counter()


class _StopWatch:
    """The run's ``stop`` asked frame by frame, with the ``TrackState`` of every frame so far."""

    def __init__(self, stop: StopCheck, frames: int) -> None:
        self.stop, self.frames = stop, frames
        self.states = np.zeros(frames, dtype=np.int8)
        self.done, self.tracked = 0, False

    def after(self, state: int) -> str | None:
        """Record the next frame's ORB-SLAM3 ``state``; why to stop, or ``None`` (never after
        the last frame: nothing is left to save)."""
        mapped = track_state(state, self.tracked)
        self.tracked = self.tracked or mapped == TrackState.OK
        if self.done < self.frames:
            self.states[self.done] = mapped
        self.done += 1
        return self.stop(self.states[: self.done], self.frames) if self.done < self.frames else None


class _LoopUsage:
    """The tracking loop's use of the machine, measured from when it is created (the loop start)."""

    def __init__(self) -> None:
        self.before, self.loadavg_start = process_usage(), [round(v, 2) for v in os.getloadavg()]
        self.loop_start = time.perf_counter()

    def figures(self) -> dict[str, Any]:
        """CPU time (s) and involuntary switches of the loop so far, load averages, cores."""
        now = process_usage()
        return {
            "cpu_s": round(now["cpu_s"] - self.before["cpu_s"], 3),
            "child_cpu_s": round(now["cpu_s"], 3),
            "loop_wall_s": round(time.perf_counter() - self.loop_start, 3),
            "involuntary_switches": int(now["involuntary_switches"] - self.before["involuntary_switches"]),
            "loadavg_start": self.loadavg_start,
            "loadavg_end": [round(v, 2) for v in os.getloadavg()],
            "cpus": os.cpu_count(),
        }


def _grey(image: np.ndarray) -> np.ndarray:
    import cv2

    if image.ndim == 2:
        return np.ascontiguousarray(image, dtype=np.uint8)
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
