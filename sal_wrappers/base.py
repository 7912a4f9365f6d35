"""The SLAM-system contract: what a system under test is given and what one run gives back.

A system receives a ``Sequence`` (possibly perturbed, possibly with dropped frames), a work
folder and a timeout, and returns a ``RunResult``. A run never raises for a failure of the
system itself (crash, ``exit(-1)``, hang, lost track): the failure is recorded in the result
with its reason and the tail of the log, so that the caller goes on with the next trial.
``SalError`` is raised only for bad use (a sensor the system does not support, bad options).
"""

from __future__ import annotations

import enum
import hashlib
import json
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from sal_adapters import Sequence, Trajectory
from sal_adapters.common.errors import SalError

__all__ = ["NO_FRAMES", "WRITTEN_BEFORE_FAILURE", "RunResult", "SlamSystem", "SlamSystemError", "StopCheck", "TrackState", "file_sha256"]

#: ``RunResult.info`` key: the system wrote its whole result before it failed (a crash at
#: shutdown); the run is scored all the same and keeps its ``failure``.
WRITTEN_BEFORE_FAILURE = "written_before_failure"

#: ``RunResult.failure`` of a run on a sequence with no frames (``SlamSystem.no_frames_result``)
NO_FRAMES = "the sequence has no frames (every frame dropped?): nothing to run on"

#: ``SlamSystem.run``'s ``stop``: called with the ``TrackState`` values (int8) of the first
#: frames, those whose state is final so far, and the number of frames given; a reason (text)
#: stops the run there, ``None`` lets it go on (``pytest_sal.engine.execution.early_stop.StopRule``).
StopCheck = Callable[[np.ndarray, int], "str | None"]


class SlamSystemError(SalError):
    """Bad use of a SLAM system: unknown option, unsupported sensor, missing executable."""


class TrackState(enum.IntEnum):
    """Tracking state of one frame given to a system."""

    NOT_INITIALISED = 0  #: before the first tracked frame: the system has no map yet
    OK = 1  #: tracked: the frame has a valid pose
    LOST = 2  #: not tracked after a tracked frame (lost track, or reset and not yet re-initialised)

    @classmethod
    def parse(cls, name: str | int) -> TrackState:
        """``"ok"``, ``"lost"``, ``"not_initialised"`` (or the integer value)."""
        if isinstance(name, (int, np.integer)):
            return cls(int(name))
        return cls[str(name).upper()]


@dataclass(frozen=True, eq=False)
class RunResult:
    """What one run of a SLAM system on one sequence gave.

    Attributes:
        system: name of the system (``orbslam3``, ``reference_vo``, ``command``).
        sequence: name of the sequence given.
        sensor: ``mono``, ``stereo`` or ``rgbd``: the mode the system ran in.
        timestamps: times (s) of the frames the system was given, in order.
        states: ``TrackState`` value per frame given (int8 array, same length).
        trajectory: the estimate that is scored: camera-to-world poses (TUM convention) at
            the timestamps of frames with state OK; ``None`` when no frame was tracked.
        scored: which trajectory ``trajectory`` is (``"online"``: per-frame tracking poses of
            the largest map segment; ``"final"``: the system's own refined trajectory).
        final_trajectory: the system's own final (refined) trajectory, when it writes one.
        maps: number of map segments (a new one starts after a loss or reset); 0 if none.
        wall_time_s: wall time of the whole run (s), including start-up.
        track_time_s: time spent in the system's per-frame tracking calls (s), when known.
        exit_status: exit status of the child process (negative: killed by that signal),
            ``None`` for an in-process run.
        failure: why the run failed (crash, exit status, timeout, nothing tracked); ``None``
            when it ran to the end or was stopped.
        stopped: why the run was stopped before its last frame (its ``stop`` said the
            requirement could no longer hold), else ``None``. Stopping is not a failure
            (``failure`` stays ``None``); ``states`` still cover every frame, those not run
            counting as not tracked (``NOT_INITIALISED`` before the first tracked frame, ``LOST``
            after), so ``tracking_rate`` is at most the full run's.
        log_path: the run's log file (the system's own output), when there is one.
        log_tail: the last lines of that log (kept for messages when the file is gone).
        info: anything else the system reports (settings file, vocabulary, options);
            ``info["attempts"]``: every attempt of a run that was re-run because it fell behind
            the sensor clock (``pace``, ``tracked``, ``frames``, ``wall_time_s``, ``failure``,
            ``fell_behind``, ``load``), the last one being this result.
        load: whether the run kept up with the sensor clock (``sal_wrappers.pacing.load_figures``:
            hand-over lateness, tracking time against the frame period, CPU time, load average);
            empty when not measured.
        fell_behind: the run (its last attempt) still fell behind the sensor clock: the machine
            was starved, so its tracking says little about the system.
    """

    system: str
    sequence: str
    sensor: str
    timestamps: np.ndarray
    states: np.ndarray
    trajectory: Trajectory | None = None
    scored: str = "online"
    final_trajectory: Trajectory | None = None
    maps: int = 0
    wall_time_s: float = 0.0
    track_time_s: float | None = None
    exit_status: int | None = None
    failure: str | None = None
    log_path: Path | None = None
    log_tail: str = ""
    info: dict[str, Any] = field(default_factory=dict)
    load: dict[str, Any] = field(default_factory=dict)
    fell_behind: bool = False
    stopped: str | None = None

    def __post_init__(self) -> None:
        t = np.asarray(self.timestamps, dtype=np.float64).reshape(-1)
        s = np.asarray(self.states, dtype=np.int8).reshape(-1)
        if len(t) != len(s):
            raise ValueError(f"run result has {len(t)} timestamps but {len(s)} states")
        object.__setattr__(self, "timestamps", t)
        object.__setattr__(self, "states", s)

    @property
    def ok(self) -> bool:
        """The run did not fail: it ran to the end or was stopped (it may still have tracked badly)."""
        return self.failure is None

    @property
    def frames(self) -> int:
        """Frames given to the system."""
        return len(self.states)

    @property
    def tracked(self) -> int:
        """Frames with state OK."""
        return int(np.count_nonzero(self.states == TrackState.OK))

    @property
    def tracking_rate(self) -> float:
        """Frames with a valid pose / frames given (0 when no frame was given)."""
        return self.tracked / self.frames if self.frames else 0.0

    @property
    def first_tracked(self) -> int | None:
        """Position of the first frame with state OK, or ``None``."""
        hits = np.flatnonzero(self.states == TrackState.OK)
        return int(hits[0]) if len(hits) else None

    def summary(self) -> str:
        """One line: system, frames tracked, maps, time, failure, and whether the run fell
        behind the sensor clock (and was re-paced)."""
        text = f"{self.system} on {self.sequence} ({self.sensor}): {self.tracked}/{self.frames} frames tracked"
        text += f", {self.maps} map(s), {self.wall_time_s:.1f} s, scored trajectory: {self.scored}"
        attempts = self.info.get("attempts") or []
        pace = self.load.get("pace")
        if self.fell_behind:
            again = f" even re-paced at {pace:g}x ({len(attempts)} attempts)" if len(attempts) > 1 else ""
            text += f"; STARVED: fell behind the sensor clock ({self.load.get('fell_behind_reason')}){again}"
        elif len(attempts) > 1:
            text += f"; fell behind the sensor clock ({attempts[0]['load'].get('fell_behind_reason')}); re-paced at {pace:g}x"
        text += f"; STOPPED early: {self.stopped}" if self.stopped else ""
        return text + (f"; FAILED: {self.failure}" if self.failure else "")

    # -- persistence (cache entries, child-process results) ------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary; ``RunResult.from_dict`` restores it."""

        def trajectory(t: Trajectory | None) -> list[list[float]] | None:
            if t is None:
                return None
            return np.column_stack([t.timestamps, t.positions, t.quaternions]).tolist()

        return {
            "system": self.system,
            "sequence": self.sequence,
            "sensor": self.sensor,
            "timestamps": self.timestamps.tolist(),
            "states": [TrackState(int(s)).name.lower() for s in self.states],
            "trajectory": trajectory(self.trajectory),
            "scored": self.scored,
            "final_trajectory": trajectory(self.final_trajectory),
            "maps": self.maps,
            "wall_time_s": self.wall_time_s,
            "track_time_s": self.track_time_s,
            "exit_status": self.exit_status,
            "failure": self.failure,
            "log_path": None if self.log_path is None else str(self.log_path),
            "log_tail": self.log_tail,
            "info": self.info,
            "load": self.load,
            "fell_behind": self.fell_behind,
            "stopped": self.stopped,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RunResult:
        """Inverse of ``to_dict`` (a dictionary of an older version lacks the newer fields:
        ``load``, ``fell_behind``, ``stopped`` take their defaults)."""

        def trajectory(rows: list[list[float]] | None) -> Trajectory | None:
            if rows is None:
                return None
            a = np.asarray(rows, dtype=np.float64).reshape(-1, 8)
            return Trajectory(a[:, 0], a[:, 1:4], a[:, 4:8])

        data = dict(data)
        data["states"] = [TrackState.parse(s).value for s in data["states"]]
        data["trajectory"] = trajectory(data.get("trajectory"))
        data["final_trajectory"] = trajectory(data.get("final_trajectory"))
        data["log_path"] = None if data.get("log_path") is None else Path(data["log_path"])
        return cls(**data)

    def to_json(self) -> str:
        return json.dumps(self.to_dict())

    @classmethod
    def from_json(cls, text: str) -> RunResult:
        return cls.from_dict(json.loads(text))


class SlamSystem:
    """Base class of a SLAM system under test.

    Subclasses set ``name``, ``sensors`` and ``description``, take their options as keyword
    arguments in ``__init__`` (checked there: ``SlamSystemError`` names a bad one) and implement
    ``run``. ``options()`` returns the options as a JSON-ready dict; ``identity()`` adds to them
    whatever else decides the results (the files a system runs) and is the cache key's part.
    ``resources()`` says what one run takes (CPUs, GPUs, memory) for the executor's scheduler.
    """

    #: the name shown in results, tables and history (the registry name; an instance may set
    #: its own, as ``command``'s ``name=`` option does)
    name: str = ""
    #: sensors the system can run on: a subset of ``mono``, ``stereo``, ``rgbd``
    sensors: ClassVar[tuple[str, ...]] = ()
    description: ClassVar[str] = ""
    #: bumped when a change of the implementation changes results (cache keys)
    version: ClassVar[int] = 1
    #: the same input gives the same result every run (one run per trial is enough); a noisy
    #: system (threads, RANSAC) gets a vote of several runs per trial
    deterministic: ClassVar[bool] = False
    #: ``run`` takes a ``stop`` and stops the run when it says so; a system that cannot stop
    #: (``command``: it runs the whole program) leaves it ``False`` and is never given one
    stoppable: ClassVar[bool] = False
    #: what one run takes where it runs (``resources()``): CPU cores and GPUs (fractions allowed)
    #: and memory in bytes (``None``: not reserved); a Ray worker's scheduler reserves them
    num_cpus: float = 1.0
    num_gpus: float = 0.0
    memory: int | None = None

    def options(self) -> dict[str, Any]:
        """The configured options (JSON-ready)."""
        return {}

    def identity(self) -> dict[str, Any]:
        """Everything that decides this system's results, for cache keys: name, version,
        options, and the content of the files it runs (JSON-ready)."""
        return {"name": self.name, "version": self.version, "options": self.options()}

    def resources(self) -> dict[str, Any]:
        """What one run needs where it runs: ``num_cpus`` and ``num_gpus`` (floats) and ``memory``
        (bytes, or ``None``). Never part of ``identity()``: where a run happens does not change
        its result, so the cache keys stay the same."""
        return {"num_cpus": float(self.num_cpus), "num_gpus": float(self.num_gpus), "memory": self.memory}

    def version_text(self) -> str:
        """What ran, in words, for the history and reports: the name, the versions its identity
        names (a package's, the program's ``version=`` option) and ``#`` the first 8 hex digits
        of the SHA-256 of the whole identity, which changes whenever a file, option or version
        that decides results changes: ``orbslam3 (pyorbslam3 0.1.1) #3fa2c9d1``."""
        identity = self.identity()
        digest = hashlib.sha256(json.dumps(identity, sort_keys=True, default=str).encode()).hexdigest()[:8]
        program = (identity.get("options") or {}).get("version")
        named = [f"version {program}"] if isinstance(program, str) else []
        named += [f"{key} {value}" for key, value in identity.items() if key not in ("name", "system") and isinstance(value, str)]
        return f"{self.name} ({', '.join(named)}) #{digest}" if named else f"{self.name} #{digest}"

    def no_frames_result(self, sequence: Sequence) -> RunResult:
        """The failed run on a sequence with no frames (``frame_drop`` at ``drop_rate`` 1): no
        system can run on it, so none is started and the reason is ``NO_FRAMES``."""
        return RunResult(
            system=self.name,
            sequence=sequence.name,
            sensor=sequence.sensor,
            timestamps=sequence.timestamps,
            states=np.zeros(0, np.int8),
            failure=NO_FRAMES,
        )

    def mode_for(self, sequence: Sequence, mode: str | None = None) -> str:
        """The sensor mode to run ``sequence`` in: ``mode`` if given, else the sequence's own
        sensor. Raises ``SlamSystemError`` when the system or the sequence cannot do it."""
        mode = mode or sequence.sensor
        if mode not in self.sensors:
            raise SlamSystemError(f"{self.name} does not run in {mode!r} mode; it supports {', '.join(self.sensors)}")
        can = {"mono": True, "stereo": sequence.sensor == "stereo", "rgbd": sequence.sensor == "rgbd"}
        if not can.get(mode, False):
            raise SlamSystemError(f"{self.name}: sequence {sequence.name!r} is {sequence.sensor}, it cannot run in {mode!r} mode")
        return mode

    def run(self, sequence: Sequence, workdir: Path, timeout: float | None = None, stop: StopCheck | None = None) -> RunResult:
        """Run on ``sequence``; write logs and files under ``workdir``; give up after
        ``timeout`` seconds (``None``: no limit). Failures of the system come back in the
        result, never as an exception.

        ``stop`` (only given to a ``stoppable`` system): asked as frames get their final state;
        when it gives a reason the run ends there, with ``RunResult.stopped`` set to it (see
        ``StopCheck``). A system that tracks in a child process calls it there, so it must pickle."""
        raise NotImplementedError

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options().items())
        return f"{type(self).__name__}({opts})"


_DIGESTS: dict[tuple[str, int, int, int], str] = {}


def file_sha256(path: str | os.PathLike[str]) -> str:
    """SHA-256 (hex) of a file's content, computed once per path, size, mtime and ctime in this
    process: cheap to ask again for every trial's cache key. ``OSError`` when it cannot be read."""
    resolved = Path(path).expanduser().resolve()
    st = resolved.stat()
    key = (str(resolved), st.st_size, st.st_mtime_ns, st.st_ctime_ns)
    digest = _DIGESTS.get(key)
    if digest is None:
        with resolved.open("rb") as fh:
            digest = hashlib.file_digest(fh, "sha256").hexdigest()
        _DIGESTS[key] = digest
    return digest
