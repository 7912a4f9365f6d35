"""``reference_vo``: the built-in, deterministic visual odometry (OpenCV only, in process).

Algorithm (``odometry``; ``lens``, ``features``, ``geometry`` and ``bundle`` beside it). A local
map of 3-D points with ORB descriptors is tracked frame by frame. ``tracker="orb"``: the
frame's ORB keypoints are matched to the map points projected with the pose a
constant-velocity model predicts (Hamming distance, ratio test, one-to-one; all keypoints when
that finds too few); ``tracker="klt"``: the map points are followed from frame to frame by
pyramidal Lucas-Kanade with a forward-backward check (ORB keypoints only at keyframes). The
pose comes from ``solvePnPRansac`` (P3P, 100 iterations, OpenCV's fixed-seed generators) and
Levenberg-Marquardt refinement, repeated on a second, narrow projection search (ORB). A frame
with fewer than ``min_inliers`` inliers is LOST. A keyframe is made when the inliers drop
below 70 % of those of the first frame after the previous keyframe; it adds the keypoints no
map point explains: RGB-D with the depth at the keypoint (unless the depth jumps within
3x3 px), stereo with ORB matching along the rectified rows refined to sub-pixel by
Lucas-Kanade (pairs that are not rectified, EuRoC, are rectified with
``sal_modules.depth.stereo_rig.stereo_rig``), mono by triangulation against the two previous
keyframes, followed by a local bundle adjustment of the last six keyframes. Mono starts when
a frame shows enough parallax against a reference frame: essential matrix, triangulated
points scaled to a median depth of 1, then the frames in between are tracked against that
map. Mono has no metric scale: score it with a Sim(3) alignment.

States: NOT_INITIALISED before a map exists, OK for a tracked frame, LOST when tracking
failed. After ``max_lost`` consecutive LOST frames the map is dropped and the odometry starts
again on the next frames: a new map segment (``maps``), whose first frame is at the identity.
The scored trajectory (``scored="online"``) is the segment with the most tracked frames, as
camera-to-world poses of the (raw, left) camera in that segment's first camera frame.

Early stop: ``run``'s ``stop`` is asked after every frame with the states that are final
(all frames stepped, except, before a mono map exists, the reference frame and those after it,
which the first map may still track); when it gives a reason the run ends there and the
frames not run count as not tracked (``RunResult.stopped``).

Results are identical run to run and whatever the number of threads. A run never raises for
a failure of its own (an exception becomes ``failure``, so does the timeout); it raises
``SlamSystemError`` for a mode the sequence cannot give, and lets errors decoding the frames
(the caller's) through. Log: ``workdir/reference_vo.log``, one line per frame
(``position timestamp state inliers ms``).
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import cv2
import numpy as np

from sal_adapters import Sequence, Trajectory
from sal_wrappers.base import RunResult, SlamSystem, SlamSystemError, StopCheck, TrackState, file_sha256
from sal_wrappers.prefetch import prefetched
from sal_wrappers.reference_vo.lens import Lens, make_lens
from sal_wrappers.reference_vo.odometry import Odometry

__all__ = ["ReferenceVO"]

TRACKERS = ("orb", "klt")


class ReferenceVO(SlamSystem):
    """The built-in visual odometry.

    Args:
        features: ORB keypoints per frame (100..20000).
        mode: ``mono``, ``stereo`` or ``rgbd``; default the sequence's sensor.
        min_inliers: fewest PnP inliers for a tracked frame (6..10000).
        tracker: ``orb`` (descriptor matching every frame) or ``klt`` (optical flow from
            frame to frame, ORB keypoints at keyframes only).
        max_lost: consecutive LOST frames after which the map is dropped (1..1000).
    """

    name = "reference_vo"
    sensors = ("mono", "stereo", "rgbd")
    description = "Built-in deterministic visual odometry (ORB or KLT, PnP on depth, stereo or triangulated points)"
    #: bump when a change of the VO code changes results (identity() also hashes source_files())
    version = 1
    deterministic = True
    stoppable = True
    #: one core: it tracks frame by frame in the calling process
    num_cpus = 1.0

    def __init__(
        self,
        *,
        features: int = 1500,
        mode: str | None = None,
        min_inliers: int = 20,
        tracker: str = "orb",
        max_lost: int = 3,
        **unknown: Any,
    ):
        if unknown:
            raise SlamSystemError(
                f"reference_vo: unknown option{'s' if len(unknown) > 1 else ''} {', '.join(f'{k}={v!r}' for k, v in unknown.items())}; "
                "options: features, mode, min_inliers, tracker, max_lost"
            )
        self.features = _integer("features", features, 100, 20000)
        if mode is not None and mode not in self.sensors:
            raise SlamSystemError(
                f"reference_vo: option mode={mode!r} is not allowed; use one of {', '.join(self.sensors)} (or None: the sequence's sensor)"
            )
        self.mode = mode
        self.min_inliers = _integer("min_inliers", min_inliers, 6, 10000)
        if tracker not in TRACKERS:
            raise SlamSystemError(f"reference_vo: option tracker={tracker!r} is not allowed; use one of {', '.join(TRACKERS)}")
        self.tracker = tracker
        self.max_lost = _integer("max_lost", max_lost, 1, 1000)

    def options(self) -> dict[str, Any]:
        return {
            "features": self.features,
            "mode": self.mode,
            "min_inliers": self.min_inliers,
            "tracker": self.tracker,
            "max_lost": self.max_lost,
        }

    def identity(self) -> dict[str, Any]:
        """``SlamSystem.identity`` plus the OpenCV version and the SHA-256 of the VO's source
        files (``source_files()``), so that an edit of the code is never served from the cache."""
        sources = {path.name: file_sha256(path) for path in source_files()}
        return {**super().identity(), "opencv": cv2.__version__, "sources": sources}

    def run(self, sequence: Sequence, workdir: Path, timeout: float | None = None, stop: StopCheck | None = None) -> RunResult:
        mode = self.mode_for(sequence, self.mode)
        start = time.monotonic()
        workdir = Path(workdir)
        workdir.mkdir(parents=True, exist_ok=True)
        log_path = workdir / "reference_vo.log"
        n = len(sequence)
        states = np.zeros(n, np.int8)
        poses: list[np.ndarray | None] = [None] * n
        segment = np.full(n, -1, np.int64)
        failure: str | None = None
        stopped: str | None = None
        lens: Lens | None = None
        odometry: Odometry | None = None
        cv2.setRNGSeed(0)
        with open(log_path, "w", encoding="utf-8") as log:
            log.write(
                f"# reference_vo {mode} on {sequence.name}: {n} frames, options {self.options()}\n# frame timestamp state inliers ms\n"
            )
            try:
                lens = make_lens(sequence, mode)
                size = (sequence.camera.width, sequence.camera.height) if lens.maps is None else lens.maps[0][0].shape[::-1]
                odometry = Odometry(
                    lens, mode, size, features=self.features, min_inliers=self.min_inliers, tracker=self.tracker, max_lost=self.max_lost
                )
            except Exception as exc:
                failure = _failed(log, exc)
            track_time, done = 0.0, 0
            if failure is None and odometry is not None:
                loop = _Loop(states, poses, segment, start, timeout, stop)
                failure, stopped, done, track_time = _track_frames(sequence, mode, odometry, log, loop)
            if done < n and odometry is not None and odometry.segments:
                states[done:] = np.where(states[done:] == TrackState.OK, TrackState.OK, TrackState.LOST)
            trajectory, sizes = _largest_segment(sequence, lens, states, poses, segment)
            if failure is None and stopped is None and trajectory is None:
                failure = "no frame was tracked"
            log.write(
                f"# {int((states == TrackState.OK).sum())}/{n} frames tracked, {odometry.segments if odometry else 0} map(s), "
                f"{track_time:.2f} s tracking ({done / max(track_time, 1e-9):.1f} frames/s)"
                + (f"; STOPPED: {stopped}" if stopped else "")
                + (f"; FAILED: {failure}" if failure else "")
                + "\n"
            )
        info = dict(
            self.options(),
            mode=mode,
            segments=sizes,
            keyframes=odometry.keyframes if odometry else 0,
            frames_processed=done,
            fps=round(done / track_time, 2) if track_time > 0 else None,
        )
        lines = log_path.read_text(encoding="utf-8").splitlines()
        return RunResult(
            system=self.name,
            sequence=sequence.name,
            sensor=mode,
            timestamps=sequence.timestamps,
            states=states,
            trajectory=trajectory,
            scored="online",
            maps=odometry.segments if odometry else 0,
            wall_time_s=time.monotonic() - start,
            track_time_s=track_time,
            failure=failure,
            stopped=stopped,
            log_path=log_path,
            log_tail="\n".join(lines[-15:]),
            info=info,
        )


@dataclass(frozen=True)
class _Loop:
    """What the frame loop fills by position (``states``, ``poses`` as T_wc, map ``segment``)
    and what ends it: the run's ``start`` (``time.monotonic()``), its ``timeout`` (s), ``stop``."""

    states: np.ndarray
    poses: list[np.ndarray | None]
    segment: np.ndarray
    start: float
    timeout: float | None
    stop: StopCheck | None


def _track_frames(sequence: Sequence, mode: str, odometry: Odometry, log: TextIO, loop: _Loop) -> tuple[str | None, str | None, int, float]:
    """Step ``odometry`` through the frames (decoded ahead), filling ``loop``'s arrays and
    logging each frame; returns (failure, why it was stopped, frames done, tracking time in s).
    Decoding errors are the caller's, not the system's: they raise."""
    failure, done, track_time = None, 0, 0.0
    for pos, timestamp, image, right, depth in prefetched(_decoded(sequence, mode)):
        if loop.timeout is not None and time.monotonic() - loop.start > loop.timeout:
            failure = f"timed out after {loop.timeout:g} s"
            log.write(f"# {failure} at frame {pos}\n")
            break
        t0 = time.perf_counter()
        try:
            updates = odometry.step(pos, timestamp, image, right, depth)
        except Exception as exc:
            failure = _failed(log, exc, pos)
            break
        ms = (time.perf_counter() - t0) * 1000
        track_time += ms / 1000
        done = pos + 1
        for p, state, inliers, T_wc in updates:
            loop.states[p], loop.poses[p], loop.segment[p] = state, T_wc, odometry.segments - 1
            note = "" if p == pos else f" (frame {pos} started the map)"
            log.write(
                f"{p} {sequence.records[p].timestamp:.6f} {TrackState(state).name.lower()} {inliers} {ms if p == pos else 0:.1f}{note}\n"
            )
        stopped = _stop_reason(loop, odometry, done)
        if stopped is not None:
            log.write(f"# stopped after frame {pos}: {stopped}\n")
            return None, stopped, done, track_time
    return failure, None, done, track_time


def _stop_reason(loop: _Loop, odometry: Odometry, done: int) -> str | None:
    """What ``loop.stop`` says after ``done`` frames (never after the last one: nothing is left
    to save), given the states that are final: all frames done, except before a mono map exists
    the start's reference frame and those after it, which the first map may still track."""
    if loop.stop is None or done >= len(loop.states):
        return None
    settled = done if odometry.started or odometry.init is None else int(odometry.init["pos"])
    return loop.stop(loop.states[:settled], len(loop.states))


def source_files() -> list[Path]:
    """The files whose code decides reference_vo's results: every module of this package."""
    return sorted(Path(__file__).resolve().parent.glob("*.py"))


def _decoded(sequence: Sequence, mode: str) -> Iterator[tuple[int, float, np.ndarray, np.ndarray | None, np.ndarray | None]]:
    """``(position, time, image, right, depth)`` per frame, with what ``mode`` needs."""
    for pos, frame in enumerate(sequence):
        yield pos, frame.timestamp, frame.image, frame.right if mode == "stereo" else None, frame.depth if mode == "rgbd" else None


def _integer(option: str, value: Any, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= value <= hi:
        raise SlamSystemError(f"reference_vo: option {option}={value!r} is not allowed; use an integer in {lo}..{hi}")
    return int(value)


def _failed(log: TextIO, exc: Exception, pos: int | None = None) -> str:
    reason = f"{type(exc).__name__}: {exc}" + ("" if pos is None else f" (frame {pos})")
    log.write("# " + "".join(traceback.format_exception(exc)).replace("\n", "\n# ") + "\n")
    return reason


def _largest_segment(
    sequence: Sequence, lens: Lens | None, states: np.ndarray, poses: list[np.ndarray | None], segment: np.ndarray
) -> tuple[Trajectory | None, list[int]]:
    """The scored trajectory (the segment with the most tracked frames, raw-left camera poses;
    ``None`` when nothing was tracked) and the tracked frames of each segment."""
    ok = states == TrackState.OK
    sizes = [int(np.count_nonzero(ok & (segment == s))) for s in range(int(segment.max()) + 1)] if len(segment) else []
    if lens is None or not sizes or max(sizes) == 0:  # no lens: no frame was tracked
        return None, sizes
    rows = np.flatnonzero(ok & (segment == int(np.argmax(sizes))))
    T = lens.to_raw(np.stack([pose for r in rows if (pose := poses[r]) is not None]))  # every tracked frame has one
    return Trajectory.from_matrices(sequence.timestamps[rows], T), sizes
