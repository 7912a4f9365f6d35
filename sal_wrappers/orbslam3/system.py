"""ORB-SLAM3 (through ``pyorbslam3``) as a system under test, run in a child process.

>>> system = create("orbslam3", features=2000)                       # doctest: +SKIP
>>> result = system.run(sequence, workdir, timeout=120)               # doctest: +SKIP

ORB-SLAM3 calls ``exit(-1)`` on a bad settings file and segfaults on a bad vocabulary or when
saving an empty map, so every run happens in a child process (``sal_wrappers.child_process``); its
C++ output goes to ``workdir/orbslam3.log``. The parent writes the settings file from the
sequence's camera (``sal_wrappers.orbslam3.settings``), streams grey frames to the child and
turns what the child recorded into a ``RunResult``.

Tracking states and map segments follow ``sal_wrappers.orbslam3.states``. ``maps`` counts
the segments; the scored ``trajectory`` (``scored="online"``) holds the per-frame ``pose_wc``
of the ``OK`` frames of the largest segment (most ``OK`` frames, the earlier one on a tie).
``final_trajectory`` is ORB-SLAM3's own ``save_trajectory_euroc()`` after ``shutdown()``
(biggest map, keyframes refined by bundle adjustment); it is saved only when at least one
frame was ``OK`` (saving a never-initialised map segfaults).

A run that ends cleanly but never initialises (no frame tracked) is a failure like for the
other systems: ``failure`` says so, ``exit_status`` is 0, ``trajectory`` is ``None`` and the
per-frame states are kept. Otherwise ``failure`` is set when the child did not finish: exit
status, signal, timeout. The child writes its per-frame
records about once a second and before shutting down and saving, so a crash in saving or a
timeout still leaves the per-frame states and poses; ``failure`` then says what was kept and
``info["partial"]`` is ``True``. A crash after the last frame (while shutting down or saving,
not a timeout) also sets ``info["written_before_failure"]``: every frame's result is there, so
the run is scored like a clean one and keeps its ``failure``.

Machine load (``sal_wrappers.pacing``): the child records when each frame was handed over, its
CPU time and the load average, and ``RunResult.load`` says whether the run kept up with the
sensor clock. A paced run that fell behind and ran to the end is run again, slower in
proportion (``repace``: the rate the machine achieved), up to ``load_retries`` times; the last
attempt is the result, ``info["attempts"]`` lists every attempt (pace, frames tracked, wall
time, load figures) and ``RunResult.fell_behind`` is ``True`` only when the last attempt still
fell behind: its tracking reflects a starved machine, not the system (``failure``, when set,
says so too). Earlier attempts' logs are kept as ``orbslam3.attempt<N>.log``.

Early stop: ``run``'s ``stop`` is asked in the child after every frame, so it must pickle. A
stopped run ends cleanly (``stopped`` says why, ``failure`` stays ``None``, no final trajectory is
saved); one that fell behind is re-paced like a full one, since its stop may be the machine's.
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
import importlib.util
import math
import os
import pickle
from pathlib import Path
from typing import Any

import numpy as np

from sal_adapters import Sequence, Trajectory
from sal_adapters.common.cache_dir import user_cache_dir
from sal_wrappers.base import WRITTEN_BEFORE_FAILURE, RunResult, SlamSystem, SlamSystemError, StopCheck, file_sha256
from sal_wrappers.child_process import ChildOutcome, run_child
from sal_wrappers.orbslam3.child import ENTRY, frame_messages
from sal_wrappers.orbslam3.settings import OrbParameters, write_settings
from sal_wrappers.orbslam3.states import map_states, read_final_trajectory, segment_ids, state_name
from sal_wrappers.pacing import load_figures, repace
from sal_wrappers.prefetch import prefetched

__all__ = ["OrbSlam3"]

_PHASES = {
    "loading": "while loading the vocabulary and settings",
    "tracking": "while tracking",
    "shutdown": "while shutting down",
    "saving": "while saving the final trajectory",
}


def _check_int(name: str, value: Any, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not low <= int(value) <= high:
        raise SlamSystemError(f"orbslam3: option {name}={value!r} is not allowed; use an integer from {low} to {high}")
    return int(value)


def _check_real(name: str, value: Any, low: float, high: float, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) or not math.isfinite(float(value)):
        raise SlamSystemError(f"orbslam3: option {name}={value!r} is not allowed; use a number {what}")
    if not low < float(value) <= high:
        raise SlamSystemError(f"orbslam3: option {name}={value!r} is not allowed; use a number {what}")
    return float(value)


def _check_file(name: str, value: Any) -> str | None:
    if value is None:
        return None
    path = Path(value).expanduser()
    if not path.is_file():
        raise SlamSystemError(f"orbslam3: option {name}={str(value)!r}: file not found")
    return str(path.resolve())


class OrbSlam3(SlamSystem):
    """ORB-SLAM3 in monocular, stereo or RGB-D mode (no IMU).

    Args:
        mode: ``mono``, ``stereo``, ``rgbd``, or ``None`` for the sequence's own sensor;
            ``mono`` runs on the left image of a stereo or RGB-D sequence.
        features: ``ORBextractor.nFeatures``, ORB features per image (50..100000).
        scale_factor: ``ORBextractor.scaleFactor``, scale between pyramid levels (1 < s <= 4).
        levels: ``ORBextractor.nLevels``, pyramid levels (1..20).
        fast_threshold: ``ORBextractor.iniThFAST`` (grey levels, 1..255).
        min_fast_threshold: ``ORBextractor.minThFAST`` (grey levels, 1..fast_threshold).
        pace: ``True``: give frames at the sensor rate, as the upstream examples do (frame ``i``
            no earlier than ``(t_i - t_{i-1})`` s after frame ``i-1`` was given; monocular loses
            track at random without it); a number: the same at that speed factor (2.0 = twice
            the rate); ``False``: as fast as ORB-SLAM3 tracks.
        vocabulary: DBoW2 text vocabulary file; default
            ``sal_wrappers.orbslam3.vocabulary.ensure_vocabulary()`` (built once, cached).
        th_depth: ``Stereo.ThDepth``: close/far point threshold in baselines (stereo, RGB-D).
        settings: a settings YAML to use as it is instead of the generated one.
        keep_final: also save ORB-SLAM3's own final trajectory (``final_trajectory``).
        load_retries: re-runs (0..5) of a paced run that fell behind the sensor clock, each
            slower in proportion; see the module text.
    """

    name = "orbslam3"
    sensors = ("mono", "stereo", "rgbd")
    description = "ORB-SLAM3 (pyorbslam3 0.1.1): monocular, stereo or RGB-D visual SLAM, run in a child process"
    version = 1
    stoppable = True
    #: a tracking thread plus local mapping and loop closing take about a core and a half
    num_cpus = 2.0
    #: test hook, not an option: seconds the child sleeps after each tracking call (simulates
    #: a machine that cannot keep up with the sensor clock)
    _stall_s: float = 0.0

    def __init__(
        self,
        *,
        mode: str | None = None,
        features: int = 2000,
        scale_factor: float = 1.2,
        levels: int = 8,
        fast_threshold: int = 20,
        min_fast_threshold: int = 7,
        pace: bool | float = True,
        vocabulary: str | Path | None = None,
        th_depth: float = 40.0,
        settings: str | Path | None = None,
        keep_final: bool = True,
        load_retries: int = 2,
    ):
        if mode is not None and mode not in self.sensors:
            raise SlamSystemError(
                f"orbslam3: option mode={mode!r} is not allowed; use one of {', '.join(self.sensors)} or None (the sequence's sensor)"
            )
        self.mode = mode
        self.features = _check_int("features", features, 50, 100_000)
        self.scale_factor = _check_real("scale_factor", scale_factor, 1.0, 4.0, "with 1 < scale_factor <= 4")
        self.levels = _check_int("levels", levels, 1, 20)
        self.fast_threshold = _check_int("fast_threshold", fast_threshold, 1, 255)
        self.min_fast_threshold = _check_int("min_fast_threshold", min_fast_threshold, 1, self.fast_threshold)
        if isinstance(pace, (bool, np.bool_)):
            self.pace: bool | float = bool(pace)
        else:
            self.pace = _check_real("pace", pace, 0.0, 1000.0, "(speed factor, 0 < pace <= 1000), True or False")
        self.vocabulary = _check_file("vocabulary", vocabulary)
        self.th_depth = _check_real("th_depth", th_depth, 0.0, 1e6, "> 0 (baselines)")
        self.settings = _check_file("settings", settings)
        if not isinstance(keep_final, (bool, np.bool_)):
            raise SlamSystemError(f"orbslam3: option keep_final={keep_final!r} is not allowed; use True or False")
        self.keep_final = bool(keep_final)
        self.load_retries = _check_int("load_retries", load_retries, 0, 5)
        if importlib.util.find_spec("pyorbslam3") is None:
            raise SlamSystemError("orbslam3 needs the pyorbslam3 package: pip install 'pytest-sal[orbslam3]'")

    def options(self) -> dict[str, Any]:
        return {
            "mode": self.mode,
            "features": self.features,
            "scale_factor": self.scale_factor,
            "levels": self.levels,
            "fast_threshold": self.fast_threshold,
            "min_fast_threshold": self.min_fast_threshold,
            "pace": self.pace,
            "vocabulary": self.vocabulary,
            "th_depth": self.th_depth,
            "settings": self.settings,
            "keep_final": self.keep_final,
            "load_retries": self.load_retries,
        }

    def identity(self) -> dict[str, Any]:
        """``SlamSystem.identity`` plus the installed pyorbslam3 version and the SHA-256 of the
        vocabulary and of a given settings file (hashed once per file version in a process:
        the 145 MB ORBvoc.txt takes about 0.1 s)."""
        from sal_wrappers.orbslam3.vocabulary import BUILDER_VERSION, ENV_VARIABLE

        try:
            package: str | None = importlib.metadata.version("pyorbslam3")
        except importlib.metadata.PackageNotFoundError:
            package = None
        # the vocabulary run() takes: the option, else ensure_vocabulary()'s order without building
        vocabulary = self.vocabulary or os.environ.get(ENV_VARIABLE) or None
        official = user_cache_dir("vocabulary") / "ORBvoc.txt"
        if vocabulary is None and official.is_file():
            vocabulary = str(official)
        files: dict[str, str] = {"vocabulary": f"built by sal_wrappers.orbslam3.vocabulary b{BUILDER_VERSION}"}
        for what, path in (("vocabulary", vocabulary), ("settings", self.settings)):
            if path is not None:
                try:
                    files[what] = file_sha256(path)
                except OSError as exc:
                    raise SlamSystemError(f"orbslam3: cannot read the {what} file {path} ({exc.strerror or exc})") from None
        return {**super().identity(), "pyorbslam3": package, "files": files}

    @property
    def pace_factor(self) -> float | None:
        """Speed factor of the pacing (1.0: the sensor rate), ``None`` when not paced."""
        if self.pace is False:
            return None
        return 1.0 if self.pace is True else float(self.pace)

    def run(self, sequence: Sequence, workdir: Path, timeout: float | None = None, stop: StopCheck | None = None) -> RunResult:
        """Run ORB-SLAM3 on ``sequence`` in a child process (see the module text); files go to
        ``workdir``: ``orbslam3_settings.yaml``, ``orbslam3.log``, ``final_trajectory_euroc.txt``.

        ``timeout`` (s) covers each child run (attempt), vocabulary loading included; ``stop``
        is asked in the child (see the module text). Raises ``SlamSystemError`` when the
        sequence cannot run in the mode or ``stop`` does not pickle, and the vocabulary
        module's error when the default vocabulary cannot be built; everything ORB-SLAM3 does
        (exit, crash, hang, lost track) comes back in the result."""
        mode = self.mode_for(sequence, self.mode)
        _check_picklable(stop)
        workdir = Path(workdir)
        workdir.mkdir(parents=True, exist_ok=True)
        if self.vocabulary is not None:
            vocabulary = self.vocabulary
        else:
            from sal_wrappers.orbslam3.vocabulary import ensure_vocabulary

            vocabulary = str(ensure_vocabulary())
        if self.settings is not None:
            settings = self.settings
        else:
            params = OrbParameters(
                self.features, self.scale_factor, self.levels, self.fast_threshold, self.min_fast_threshold, self.th_depth
            )
            settings = str(write_settings(workdir / "orbslam3_settings.yaml", sequence.camera, mode, sequence.fps, params))
        final_path = workdir / "final_trajectory_euroc.txt"
        final_path.unlink(missing_ok=True)
        header: dict[str, Any] = {
            "vocabulary": vocabulary,
            "settings": settings,
            "sensor": mode,
            "pace": self.pace_factor,
            "final_path": str(final_path) if self.keep_final else None,
            "stop": stop,
            "frames": len(sequence),
        }
        if self._stall_s:
            header["stall_s"] = float(self._stall_s)
        attempts: list[dict[str, Any]] = []
        while True:
            outcome = run_child(ENTRY, header, prefetched(frame_messages(sequence, mode)), workdir, timeout, log_name="orbslam3.log")
            result = self._result(sequence, mode, outcome, header, final_path)
            attempts.append(_attempt(result))
            load = result.load
            if not load.get("fell_behind") or outcome.failure is not None or len(attempts) > self.load_retries:
                break
            outcome.log_path.replace(workdir / f"orbslam3.attempt{len(attempts)}.log")
            header = {**header, "pace": repace(float(header["pace"]), load["sensor_s"], load["loop_s"])}
        fell_behind = bool(result.load.get("fell_behind"))
        failure = result.failure
        if fell_behind and failure is not None:
            paced = f" at {header['pace']:g}x" if len(attempts) > 1 else ""
            failure += f"; the machine could not keep up: the run fell behind the sensor clock{paced} ({result.load['fell_behind_reason']})"
        return dataclasses.replace(result, fell_behind=fell_behind, failure=failure, info={**result.info, "attempts": attempts})

    def _result(self, sequence: Sequence, mode: str, outcome: ChildOutcome, header: dict[str, Any], final_path: Path) -> RunResult:
        """The ``RunResult`` of one child run from the record it left (see the module text)."""
        data = outcome.result or {}
        timestamps = sequence.timestamps
        n = len(timestamps)
        reported: list[int] = [int(s) for s in data.get("raw_states", [])][:n]
        raw: list[int | None] = [*reported, *([None] * (n - len(reported)))]
        trajectory, sizes = _largest_segment(segment_ids(raw), data.get("poses", []), timestamps)
        final, final_error = None, None
        if self.keep_final and data.get("final_saved"):
            try:
                final = read_final_trajectory(final_path, timestamps)
            except (OSError, ValueError) as exc:
                final_error = str(exc)
        phase = data.get("phase")
        stopped = data.get("stopped")
        failure, partial, written = _failure(outcome, phase, len(reported), n, trajectory is not None or stopped is not None)
        track_times = np.asarray(data.get("track_times", []), dtype=np.float64)
        given = np.asarray(data.get("given", []), dtype=np.float64)
        load = load_figures(timestamps[: len(given)], given, track_times, header.get("pace"), data.get("usage")) if len(given) else {}
        counts: dict[str, int] = {}
        for s in reported:
            counts[state_name(s)] = counts.get(state_name(s), 0) + 1
        info: dict[str, Any] = {
            "settings": header["settings"],
            "settings_generated": self.settings is None,
            "vocabulary": header["vocabulary"],
            "features": self.features,
            "pace": header.get("pace"),
            "options": self.options(),
            "load_time_s": data.get("load_time_s"),
            "loop_time_s": data.get("loop_time_s"),
            "track_ms_mean": float(track_times.mean() * 1e3) if len(track_times) else None,
            "track_ms_median": float(np.median(track_times) * 1e3) if len(track_times) else None,
            "orbslam3_states": counts,
            "segment_sizes": sizes,
            "frames_reported": len(reported),
            "phase": phase,
            "partial": partial,
            WRITTEN_BEFORE_FAILURE: written,
            "final_path": str(final_path) if final is not None else None,
        }
        if final_error:
            info["final_error"] = final_error
        if outcome.cpu_at_timeout_s is not None:
            info["cpu_at_timeout_s"] = round(outcome.cpu_at_timeout_s, 3)
        return RunResult(
            system=self.name,
            sequence=sequence.name,
            sensor=mode,
            timestamps=timestamps,
            states=map_states(raw),
            trajectory=trajectory,
            scored="online",
            final_trajectory=final,
            maps=len(sizes),
            wall_time_s=float(outcome.wall_time_s),
            track_time_s=float(track_times.sum()) if len(track_times) else None,
            exit_status=outcome.exit_status,
            failure=failure,
            stopped=stopped,
            log_path=outcome.log_path,
            log_tail=outcome.log_tail,
            info=info,
            load=load,
            fell_behind=bool(load.get("fell_behind")),
        )


def _check_picklable(stop: StopCheck | None) -> None:
    """``SlamSystemError`` when ``stop`` cannot go to the child process (it does not pickle)."""
    try:
        pickle.dumps(stop)
    except Exception as exc:
        hint = "give a picklable one: a StopRule or a module-level function"
        raise SlamSystemError(f"orbslam3: stop={stop!r} cannot be sent to the child process that tracks ({exc}); {hint}") from None


def _largest_segment(ids: np.ndarray, poses: list[Any], timestamps: np.ndarray) -> tuple[Trajectory | None, list[int]]:
    """The ``pose_wc`` trajectory of the largest map segment (the earlier one on a tie; ``None``
    when no frame was tracked) and the number of frames of each segment."""
    maps = int(ids.max()) + 1 if len(ids) and ids.max() >= 0 else 0
    sizes = [int(np.count_nonzero(ids == k)) for k in range(maps)]
    if not maps:
        return None, sizes
    keep = np.flatnonzero(ids == int(np.argmax(sizes)))  # first of the largest
    matrices = np.array([np.asarray(poses[i], dtype=np.float64).reshape(4, 4) for i in keep])
    return Trajectory.from_matrices(timestamps[keep], matrices), sizes


def _failure(outcome: ChildOutcome, phase: str | None, reported: int, n: int, tracked: bool) -> tuple[str | None, bool, bool]:
    """``(failure, partial, written)``: how the run failed in words, with the phase it failed
    in and what was kept; whether per-frame results of an unfinished child are kept
    (``partial``); whether they cover every frame of a crash after the last one (``written``);
    ``tracked``: a frame was tracked, or the run was stopped (not a failure)."""
    failure = outcome.failure
    partial = failure is not None and reported > 0
    if failure is None and not tracked:
        failure = f"never initialised: no frame of {n} was tracked"  # the child ran to the end
    # a crash after the last frame (shutting down, saving the final map) leaves every frame's result
    written = partial and phase in ("shutdown", "saving") and reported == n and not outcome.timed_out
    if failure is not None:
        if phase in _PHASES:
            failure += f" {_PHASES[phase]}"
        if written:
            failure += f"; the per-frame results of all {n} frames are kept and scored"
        elif partial:
            failure += f"; the per-frame results of {reported} of {n} frames are kept"
    return failure, partial, written


def _attempt(result: RunResult) -> dict[str, Any]:
    """One attempt for ``info["attempts"]``: pace, frames tracked, wall time (s), failure, load figures."""
    return {
        "pace": result.info.get("pace"),
        "tracked": result.tracked,
        "frames": result.frames,
        "maps": result.maps,
        "wall_time_s": round(result.wall_time_s, 3),
        "failure": result.failure,
        "stopped": result.stopped,
        "fell_behind": bool(result.load.get("fell_behind")),
        "load": result.load,
    }
