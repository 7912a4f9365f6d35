"""The ``command`` system: any external SLAM program, run on a sequence staged on disk.

The sequence (perturbed or not: lazy frames are decoded here) is written in a dataset layout
under ``workdir/sequence``, the program is started with an argument list built from
placeholders, and the trajectory it writes is read back and matched to the frames::

    create("command",
           argv=["./Examples/RGB-D/rgbd_tum", "Vocabulary/ORBvoc.txt", "{settings}",
                 "{sequence}", "{associations}"],
           settings="TUM_synthetic.yaml", layout="tum",
           output="CameraTrajectory.txt", output_format="tum")

Placeholders (``{name}``; ``{{`` and ``}}`` are literal braces) work in ``argv``, ``prefix``,
``env`` values, ``cwd``, ``output`` and in the ``settings`` template; an unknown one is an error
when the system is created. See
``sal_wrappers.command.placeholders.PLACEHOLDERS`` for the list.

Output formats (``output_format``), all camera-to-world poses of the (left) camera:

``tum``
    ``t tx ty tz qx qy qz qw`` per line, ``#`` comments.
``kitti``
    12 values per line (3x4 ``[R | t]`` row-major), or 13 with the timestamp first. A 12-value
    file takes its times from ``{output_times}`` (one time per line) when the program wrote that
    file; otherwise it must hold exactly one pose per frame given, in order.
``euroc``
    EuRoC CSV: ``t [ns], px, py, pz, qw, qx, qy, qz[, ...]``.
``json``
    a list of ``{"t": time, "pose": P}`` where ``P`` is a 4x4 (or 3x4) matrix as nested lists,
    or ``[tx, ty, tz, qx, qy, qz, qw]``.

Times in the output are in ``time_unit`` (``s`` by default, ``ns`` for ``euroc``) on the clock of
the staged sequence (the times in its ``times.txt`` / ``rgb.txt`` / ``data.csv``). A frame is
tracked (OK) when a pose lies within half a frame period of its time; frames before the first
tracked one are NOT_INITIALISED, untracked frames after it LOST. With ``keyframes=True`` (the
file holds keyframes only) every frame from the first to the last pose counts as tracked.

A program that crashes or exits non-zero after writing a trajectory that this run wrote and
that matches the frames (ORB-SLAM3 sometimes crashes at shutdown) keeps its trajectory and
tracking states: ``failure`` says how it ended, and ``info["written_before_failure"]`` tells
the scoring (``pytest_sal.analysis.metrics.evaluate``) to score it all the same. A timed-out run is not
scored (the file may have been half written when the program was killed).
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from sal_adapters import Sequence, Trajectory, write_sequence
from sal_adapters.common.errors import DatasetError
from sal_adapters.common.textfiles import atomic_write_text, format_float
from sal_wrappers.base import WRITTEN_BEFORE_FAILURE, RunResult, SlamSystem, SlamSystemError, StopCheck, TrackState
from sal_wrappers.child_process import describe_exit, log_tail
from sal_wrappers.command.files import file_digest, program_files, tree_digest
from sal_wrappers.command.options import LAYOUT_SENSORS, LOG_NAME, SENSORS, parse_command_options
from sal_wrappers.command.output import Stamp, find_output, frame_states, no_match_message, read_output, snapshot, written_since
from sal_wrappers.command.placeholders import placeholder_values, render
from sal_wrappers.process_group import run_process_group

__all__ = ["CommandSystem"]


class CommandSystem(SlamSystem):
    """Any external SLAM program, given the sequence as files and read back from its trajectory.

    Options (keyword arguments):
        argv: the program and its arguments, a list of strings (never a shell string) with
            placeholders (``PLACEHOLDERS``).
        prefix: list prepended to ``argv``: ``["conda", "run", "-n", "orbslam"]``,
            ``["xvfb-run", "-a"]``, ``["docker", "run", "--rm", "-v", "{workdir}:{workdir}", "image"]``.
        output: where the program writes its trajectory: a path (placeholders allowed; relative
            to ``cwd``) or a glob pattern (``logs/*.txt``; the newest file written by this run is
            read). Default ``{workdir}/trajectory.txt``.
        output_format: ``tum`` (default), ``kitti``, ``euroc`` or ``json`` (module text).
        time_unit: unit of the output's times: ``s`` (default; ``ns`` for ``euroc``), ``ms``,
            ``us``, ``ns`` (ORB-SLAM3's ``SaveTrajectoryEuRoC`` writes TUM columns in ns).
        keyframes: the output holds keyframe poses only: frames from the first to the last pose
            count as tracked.
        layout: dataset layout to stage the sequence in (``kitti``, ``tum``, ``euroc``,
            ``folder``, ``synthetic`` or a plug-in kind); default: the sequence's own kind.
        sensor (or mode): ``mono``, ``stereo`` or ``rgbd``; default: the sequence's own sensor.
            ``mono`` on a stereo or RGB-D sequence stages the left images only.
        grayscale: stage grey (``True``) or colour (``False``) images; default: as the dataset
            stores them. KITTI grey images go to ``image_0/1``, colour to ``image_2/3``.
        stage_dir: folder under the work folder to stage the sequence in (default ``sequence``);
            for programs that recognise a dataset by its path (MASt3R-SLAM: ``stage_dir="euroc"``).
        settings: a template file (e.g. an ORB-SLAM3 yaml) rendered with the placeholders into
            ``workdir/settings/<name>``; ``{settings}`` is its path.
        env: extra environment variables (values may hold placeholders).
        cwd: the program's working folder; default ``{workdir}``.
        name: the name shown in results, tables, reports and history (default ``command``):
            letters, digits, ``.``, ``_``, ``-``, at most 64 characters.
        version: the program's version as you name it (a string); part of the cache key.
        depends: more files or folders whose content decides the results (modules a script
            imports, a vocabulary, a config): hashed into the cache key like the program itself.
        num_cpus, num_gpus: CPU cores (default 1) and GPUs (default 0) one run takes, fractions
            allowed; a Ray worker reserves them (a DROID-SLAM recipe asks for ``num_gpus=1``).
        memory: bytes of memory one run takes (an integer; default: not reserved).

    The cache key (``identity()``) holds the options and the SHA-256 of the files the system
    runs: the executable (``argv[0]``, looked up on ``PATH``), every other ``argv`` item that is
    an existing file, the settings template and the ``depends`` files; not ``num_cpus``,
    ``num_gpus`` or ``memory`` (``resources()``), which decide where a run happens, not its result.
    """

    name = "command"
    sensors = SENSORS
    description = "any external SLAM program: the sequence staged in a dataset layout, the trajectory file read back"
    version = 1

    def __init__(self, **options: Any):
        self.config = parse_command_options(options)
        self.name = self.config.name
        self.deterministic = self.config.deterministic  # type: ignore[misc]  # True: one run per trial, no votes
        self.num_cpus, self.num_gpus, self.memory = self.config.num_cpus, self.config.num_gpus, self.config.memory

    def options(self) -> dict[str, Any]:
        config = self.config
        return {
            "argv": list(config.argv),
            "prefix": list(config.prefix),
            "output": config.output,
            "output_format": config.output_format,
            "time_unit": config.time_unit,
            "keyframes": config.keyframes,
            "layout": config.layout,
            "sensor": config.sensor,
            "grayscale": config.grayscale,
            "stage_dir": config.stage_dir,
            "settings": None if config.settings is None else str(config.settings),
            "settings_sha256": hashlib.sha256(config.settings_text.encode()).hexdigest() if config.settings else None,
            "env": dict(config.env),
            "cwd": config.cwd,
            "name": config.name,
            "version": config.version,
            "depends": [str(p) for p in config.depends],
            "deterministic": config.deterministic,
        }

    def identity(self) -> dict[str, Any]:
        """``SlamSystem.identity`` plus the system kind and the SHA-256 of every file it runs:
        the executable, ``argv`` items that are files and ``depends`` (the settings template's
        is in ``options()`` as ``settings_sha256``: the text read at creation, the one rendered)."""
        files: dict[str, str | None] = {}
        for arg, path in program_files(self.config.argv, self.config.cwd, self.config.env):
            files[arg] = None if path is None else file_digest(path, "the argv file")
        for path in self.config.depends:
            files[str(path)] = tree_digest(path) if path.is_dir() else file_digest(path, "the depends file")
        return {**super().identity(), "system": "command", "files": files}

    # -- running -------------------------------------------------------------------------------
    def _layout(self, sequence: Sequence, mode: str) -> str:
        """The dataset layout the sequence is staged in (``layout=``, else the sequence's own),
        refused when it cannot hold ``mode``'s data."""
        layout = self.config.layout or sequence.kind
        if layout in LAYOUT_SENSORS and mode not in LAYOUT_SENSORS[layout]:
            raise SlamSystemError(
                f"command: the {layout} layout cannot hold {mode} data (it holds {', '.join(LAYOUT_SENSORS[layout])}); "
                f"choose another layout= or sensor='mono'"
            )
        return layout

    def run(self, sequence: Sequence, workdir: Path, timeout: float | None = None, stop: StopCheck | None = None) -> RunResult:
        """Stage ``sequence`` under ``workdir/<stage_dir>``, run the program (log: ``workdir/run.log``),
        read its trajectory. Failures of the program come back in the result. ``stop`` is
        ignored: the program runs the whole sequence and its states are known only at its end
        (the system is not ``stoppable``, so the trial runner gives it none)."""
        config = self.config
        mode = self.mode_for(sequence, config.sensor)
        if not len(sequence):
            return self.no_frames_result(sequence)
        workdir = Path(workdir).expanduser().resolve()
        workdir.mkdir(parents=True, exist_ok=True)
        layout = self._layout(sequence, mode)
        stage_start = time.monotonic()
        staged = self._stage(sequence, mode, workdir, layout)
        values = placeholder_values(sequence, mode, workdir, staged, config.settings)
        cwd, output = self._paths(values, workdir)
        values["output"] = str(output)
        if config.settings is not None:
            atomic_write_text(workdir / "settings" / config.settings.name, render(config.settings_text, values))
        command = [render(a, values) for a in [*config.prefix, *config.argv]]
        env = dict(os.environ)
        env.update({k: render(v, values) for k, v in config.env.items()})
        times_path = workdir / "output_times.txt"
        times_path.unlink(missing_ok=True)
        before = snapshot(output, config.output_is_pattern, workdir)
        stage_time = time.monotonic() - stage_start

        log_path = workdir / LOG_NAME
        status, timed_out, wall, start_error, cpu_at_timeout = run_process_group(command, cwd, env, log_path, timeout)

        info: dict[str, Any] = {
            "argv": command,
            "cwd": str(cwd),
            "staged": str(staged),
            "layout": layout,
            "output": str(output),
            "output_format": config.output_format,
            "time_unit": config.time_unit,
            "stage_time_s": round(stage_time, 3),
        }
        if cpu_at_timeout is not None:
            info["cpu_at_timeout_s"] = round(cpu_at_timeout, 3)
        if config.settings is not None:
            info["settings"] = str(workdir / "settings" / config.settings.name)
        stamps = sequence.timestamps
        trajectory, found, output_error = (None, None, None) if start_error is not None else self._read(output, before, stamps, times_path)
        if found is not None:
            info["output"] = str(found)
        states = np.full(len(stamps), TrackState.NOT_INITIALISED, dtype=np.int8)
        scored: Trajectory | None = None
        if trajectory is not None:
            info["poses"] = len(trajectory)
            states, scored = frame_states(stamps, sequence.fps, trajectory, config.keyframes)
            if scored is None and output_error is None:
                output_error = no_match_message(found, stamps, sequence.fps, trajectory, config.time_unit)

        failure = _failure(start_error, status, timed_out, timeout, output_error, scored is not None, info)

        return RunResult(
            system=self.name,
            sequence=sequence.name,
            sensor=mode,
            timestamps=stamps,
            states=states,
            trajectory=scored,
            scored="final",
            final_trajectory=trajectory if trajectory is not None and len(trajectory) else None,
            maps=1 if scored is not None else 0,
            wall_time_s=wall,
            track_time_s=None,
            exit_status=status,
            failure=failure,
            log_path=log_path,
            log_tail=log_tail(log_path),
            info=info,
        )

    def _stage(self, sequence: Sequence, mode: str, workdir: Path, layout: str) -> Path:
        """Write the sequence in ``layout`` under ``workdir/<stage_dir>`` and the time (and
        association) files beside it; returns the staged sequence's path."""
        staged = write_sequence(_staged_copy(sequence, mode, self.config.grayscale), workdir / self.config.stage_dir, layout=layout)
        atomic_write_text(workdir / "timestamps.txt", "".join(format_float(t) + "\n" for t in sequence.timestamps))
        ns = [r.time_ns for r in sequence.records]
        atomic_write_text(workdir / "timestamps_ns.txt", "".join(f"{n}\n" for n in ns))
        if "associations" in self.config.used:
            source = staged / "associations.txt"
            if not source.is_file():
                raise SlamSystemError(
                    f"command: {{associations}} needs an RGB-D sequence staged in the tum layout (sensor rgbd, layout tum); {source} was not written"
                )
            rows = [line for line in source.read_text().splitlines() if line.strip() and not line.lstrip().startswith("#")]
            atomic_write_text(workdir / "associations.txt", "\n".join(rows) + "\n")
        return staged

    def _paths(self, values: dict[str, str], workdir: Path) -> tuple[Path, Path]:
        """The program's working folder and the path of its output (a pattern stays one)."""
        cwd = Path(render(self.config.cwd, values)).expanduser() if self.config.cwd is not None else workdir
        if not cwd.is_absolute():
            cwd = workdir / cwd
        if not cwd.is_dir():
            raise SlamSystemError(f"command: cwd {cwd} is not a folder")
        output = Path(render(self.config.output, values)).expanduser()
        return cwd, output if output.is_absolute() else cwd / output

    def _read(
        self, output: Path, before: dict[Path, Stamp], stamps: np.ndarray, times_path: Path
    ) -> tuple[Trajectory | None, Path | None, str | None]:
        """``(trajectory, file read, what went wrong)`` of the output this run wrote."""
        found, output_error = find_output(output, self.config.output_is_pattern, before)
        if found is None:
            return None, None, output_error
        times = times_path if written_since(times_path, before) else None
        try:
            return read_output(found, self.config.output_format, self.config.time_unit, stamps, times), found, output_error
        except DatasetError as exc:
            return None, found, f"unparsable output: {exc}"
        except ValueError as exc:
            return None, found, f"unparsable output: {found}: {exc}"


def _failure(
    start_error: str | None,
    status: int | None,
    timed_out: bool,
    timeout: float | None,
    output_error: str | None,
    matched: bool,
    info: dict[str, Any],
) -> str | None:
    """How the run failed, in words (``None``: it did not). A program that exits non-zero after
    writing a trajectory that ``matched`` the frames keeps it: ``info`` is marked to score it.
    ``info["output_error"]`` keeps an output problem that another failure hides."""
    if start_error is not None or status is None:  # no exit status: the program never started
        failure = start_error
    elif timed_out:
        failure = f"timed out after {timeout:g} s and was killed"
    elif status != 0:
        failure = describe_exit(status) + (" (command not found by the shell or prefix)" if status == 127 else "")
        if matched and output_error is None:  # it crashed after writing its trajectory (at shutdown)
            failure += f" after writing its trajectory ({info['poses']} poses: kept and scored)"
            info[WRITTEN_BEFORE_FAILURE] = True
    else:
        failure = output_error
    if output_error is not None and failure != output_error:
        info["output_error"] = output_error
    return failure


def _staged_copy(sequence: Sequence, mode: str, grayscale: bool | None) -> Sequence:
    staged = sequence
    if mode == "mono" and sequence.sensor != "mono":
        records = [dataclasses.replace(r, right=None, depth=None) for r in sequence.records]
        staged = staged.replace(sensor="mono", records=records)
    if grayscale is not None and grayscale != sequence.grayscale:
        staged = staged.replace(grayscale=grayscale)
    return staged
