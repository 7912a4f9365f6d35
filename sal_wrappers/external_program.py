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
when the system is created. See ``PLACEHOLDERS`` for the list.

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
import re
import shlex
import shutil
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from sal_adapters import Sequence, Trajectory, write_sequence
from sal_adapters.datasets import DATASETS
from sal_adapters.errors import DatasetError
from sal_adapters.textfiles import (
    atomic_write_text,
    format_float,
)
from sal_adapters.trajectory import seconds_to_ns
from sal_wrappers.base import WRITTEN_BEFORE_FAILURE, RunResult, SlamSystem, SlamSystemError, TrackState, file_sha256
from sal_wrappers.child_process import describe_exit, log_tail
from sal_wrappers.process_group import run_process_group
from sal_wrappers.program_output import (
    OUTPUT_FORMATS,
    TIME_UNITS,
    find_output,
    frame_states,
    no_match_message,
    read_output,
    snapshot,
    written_since,
)

__all__ = ["PLACEHOLDERS", "CommandSystem"]


#: Every placeholder and what it becomes (paths are absolute).
PLACEHOLDERS: dict[str, str] = {
    "sequence": "the staged sequence: the path open_dataset(layout, path) reads (KITTI: .../sequences/00, EuRoC: the folder holding mav0/)",
    "workdir": "the run's work folder",
    "output": "the file the program must write its trajectory to (the output option, resolved against cwd)",
    "output_times": "workdir/output_times.txt: where a program writing 12-value KITTI poses may write one time per pose",
    "settings": "the settings template rendered into workdir/settings/ (option settings)",
    "timestamps": "workdir/timestamps.txt: one frame time per line (s), no header",
    "timestamps_ns": "workdir/timestamps_ns.txt: one frame time per line (integer ns, the EuRoC image names), no header",
    "associations": "workdir/associations.txt: TUM 't rgb/... t depth/...' pairs without comment lines (RGB-D in the tum layout)",
    "fps": "nominal frame rate (Hz); an integer when it is one (ORB-SLAM3 insists on an int Camera.fps)",
    "frames": "number of frames staged",
    "sensor": "mono, stereo or rgbd: the mode the program runs in",
    "camera_fx": "focal length x (px); every camera_* value but width and height is written as a real (525.0)",
    "camera_fy": "focal length y (px)",
    "camera_cx": "principal point x (px)",
    "camera_cy": "principal point y (px)",
    "camera_width": "image width (px)",
    "camera_height": "image height (px)",
    "camera_k1": "radial distortion k1 (0 when none)",
    "camera_k2": "radial distortion k2 (0 when none)",
    "camera_p1": "tangential distortion p1 (0 when none)",
    "camera_p2": "tangential distortion p2 (0 when none)",
    "camera_k3": "radial distortion k3 (0 when none)",
    "camera_baseline": "stereo baseline (m; 0 for a single camera)",
    "camera_bf": "camera_fx * camera_baseline (ORB-SLAM's Camera.bf)",
}

#: What each built-in layout can hold (a plug-in layout is not checked).
LAYOUT_SENSORS = {
    "kitti": ("mono", "stereo"),
    "euroc": ("mono", "stereo"),
    "tum": ("mono", "rgbd"),
    "folder": ("mono",),
    "synthetic": ("mono", "stereo", "rgbd"),
}
STAGE_DIR = "sequence"
LOG_NAME = "run.log"

_TOKEN = re.compile(r"\{\{|\}\}|\{([A-Za-z_][A-Za-z0-9_]*)\}")
_OPTIONS = (
    "argv",
    "prefix",
    "output",
    "output_format",
    "time_unit",
    "keyframes",
    "layout",
    "sensor",
    "mode",
    "grayscale",
    "stage_dir",
    "settings",
    "env",
    "cwd",
    "name",
    "version",
    "depends",
    "deterministic",
)
_NAME = re.compile(r"[A-Za-z0-9._-]{1,64}")
#: Most a ``depends`` folder may hold (its files are hashed for the cache key).
DEPENDS_MAX_BYTES = 1 << 30
DEPENDS_MAX_FILES = 20_000
#: Skipped in a ``depends`` folder: caches that running the program rewrites, version control.
_SKIPPED_DIRS = {"__pycache__", ".git", ".hg", ".svn", ".mypy_cache", ".pytest_cache", ".ruff_cache"}
#: Names in the work folder that the system writes itself.
_RESERVED = {"settings", LOG_NAME, "timestamps.txt", "timestamps_ns.txt", "associations.txt", "output_times.txt"}


def placeholders_in(text: str) -> list[str]:
    """The ``{name}`` placeholders in ``text`` (``{{`` / ``}}`` are escapes)."""
    return [m.group(1) for m in _TOKEN.finditer(text) if m.group(1)]


def render(text: str, values: Mapping[str, str]) -> str:
    """``text`` with each ``{name}`` replaced by ``values[name]`` and ``{{``/``}}`` by braces."""

    def one(match: re.Match[str]) -> str:
        token = match.group(0)
        if token == "{{":
            return "{"
        if token == "}}":
            return "}"
        return values[match.group(1)]

    return _TOKEN.sub(one, text)


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

    The cache key (``identity()``) holds the options and the SHA-256 of the files the system
    runs: the executable (``argv[0]``, looked up on ``PATH``), every other ``argv`` item that is
    an existing file, the settings template and the ``depends`` files.
    """

    name = "command"
    sensors = ("mono", "stereo", "rgbd")
    description = "any external SLAM program: the sequence staged in a dataset layout, the trajectory file read back"
    version = 1

    def __init__(self, **options: Any):
        name = options.get("name", "command")
        if not isinstance(name, str) or not _NAME.fullmatch(name):
            raise SlamSystemError(
                f"command: option name={name!r} is not allowed: give 1 to 64 letters, digits, '.', '_' or '-' (the name shown in results and history)"
            )
        self.name = name
        unknown = sorted(set(options) - set(_OPTIONS))
        if unknown:
            raise SlamSystemError(
                f"command: unknown option{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))}; "
                f"allowed: {', '.join(o for o in _OPTIONS if o != 'mode')} (mode is a synonym of sensor)"
            )
        if "argv" not in options or options["argv"] is None:
            raise SlamSystemError(
                'command: option argv is required: the program and its arguments as a list, e.g. argv=["./slam", "{sequence}", "{output}"]'
            )
        self.argv = _string_list("argv", options["argv"], allow_empty=False)
        self.prefix = _string_list("prefix", options.get("prefix") or [], allow_empty=True)

        self.output_format = options.get("output_format", "tum")
        if not isinstance(self.output_format, str) or self.output_format not in OUTPUT_FORMATS:
            raise SlamSystemError(f"command: output_format {self.output_format!r} is not known; allowed: {', '.join(OUTPUT_FORMATS)}")
        time_unit = options.get("time_unit")
        if time_unit is not None and (not isinstance(time_unit, str) or time_unit not in TIME_UNITS):
            raise SlamSystemError(f"command: time_unit {time_unit!r} is not known; allowed: {', '.join(TIME_UNITS)}")
        if self.output_format == "euroc" and time_unit not in (None, "ns"):
            raise SlamSystemError(f"command: the euroc format stores times in ns; time_unit {time_unit!r} does not apply")
        self.time_unit = time_unit or ("ns" if self.output_format == "euroc" else "s")
        self.keyframes = options.get("keyframes", False)
        if not isinstance(self.keyframes, bool):
            raise SlamSystemError(f"command: keyframes must be True or False, got {self.keyframes!r}")
        deterministic = options.get("deterministic", False)
        if not isinstance(deterministic, bool):
            raise SlamSystemError(f"command: deterministic must be True or False, got {deterministic!r}")
        self.deterministic = deterministic  # type: ignore[misc]  # True: one run per trial, no votes

        self.layout = options.get("layout")
        if self.layout is not None and (not isinstance(self.layout, str) or self.layout not in DATASETS.names()):
            raise SlamSystemError(
                f"command: layout {self.layout!r} is not a dataset layout; allowed: {', '.join(DATASETS.names())} (default: the sequence's own)"
            )
        sensor, mode = options.get("sensor"), options.get("mode")
        if sensor is not None and mode is not None and sensor != mode:
            raise SlamSystemError(f"command: sensor={sensor!r} and mode={mode!r} disagree (they are the same option)")
        self.sensor = sensor if sensor is not None else mode
        if self.sensor is not None and (not isinstance(self.sensor, str) or self.sensor not in self.sensors):
            raise SlamSystemError(
                f"command: sensor {self.sensor!r} is not known; allowed: {', '.join(self.sensors)} (default: the sequence's own)"
            )
        if self.layout in LAYOUT_SENSORS and self.sensor is not None and self.sensor not in LAYOUT_SENSORS[self.layout]:
            raise SlamSystemError(
                f"command: the {self.layout} layout cannot hold {self.sensor} data (it holds {', '.join(LAYOUT_SENSORS[self.layout])})"
            )
        self.grayscale = options.get("grayscale")
        if self.grayscale is not None and not isinstance(self.grayscale, bool):
            raise SlamSystemError(f"command: grayscale must be True, False or None, got {self.grayscale!r}")
        stage_dir = options.get("stage_dir", STAGE_DIR)
        parts = Path(stage_dir).parts if isinstance(stage_dir, (str, os.PathLike)) else ()
        if not parts or Path(stage_dir).is_absolute() or ".." in parts or parts[0] in _RESERVED:
            raise SlamSystemError(
                f"command: stage_dir must be a relative folder inside the work folder, without '..' and not one of "
                f"{', '.join(sorted(_RESERVED))}; got {stage_dir!r}"
            )
        self.stage_dir = os.fspath(stage_dir)

        env = options.get("env") or {}
        if not isinstance(env, Mapping) or not all(isinstance(k, str) and isinstance(v, (str, os.PathLike)) for k, v in env.items()):
            raise SlamSystemError(f"command: env must map variable names to strings, got {env!r}")
        self.env = {k: os.fspath(v) for k, v in env.items()}
        cwd = options.get("cwd")
        if cwd is not None and not isinstance(cwd, (str, os.PathLike)):
            raise SlamSystemError(f"command: cwd must be a folder path, got {cwd!r}")
        self.cwd = None if cwd is None else os.fspath(cwd)
        output = options.get("output", "{workdir}/trajectory.txt")
        if not isinstance(output, (str, os.PathLike)) or not os.fspath(output):
            raise SlamSystemError(f"command: output must be a file path or glob pattern, got {output!r}")
        self.output = os.fspath(output)
        self.output_is_pattern = any(c in self.output for c in "*?[")

        settings = options.get("settings")
        self.settings: Path | None = None
        self._settings_text = ""
        if settings is not None:
            if not isinstance(settings, (str, os.PathLike)):
                raise SlamSystemError(f"command: settings must be a template file path, got {settings!r}")
            self.settings = Path(settings).expanduser().resolve()
            try:
                self._settings_text = self.settings.read_text(encoding="utf-8")
            except FileNotFoundError:
                raise SlamSystemError(f"command: settings template not found: {self.settings}") from None
            except (OSError, UnicodeDecodeError) as exc:
                raise SlamSystemError(f"command: cannot read settings template {self.settings} as text ({exc})") from None

        version = options.get("version")
        if version is not None and (not isinstance(version, (str, int)) or isinstance(version, bool) or not str(version).strip()):
            raise SlamSystemError(f"command: option version={version!r} is not allowed: give the program's version as a non-empty string")
        self.program_version = None if version is None else str(version)
        depends = options.get("depends") or []
        self.depends = [Path(p).expanduser().resolve() for p in _string_list("depends", depends, allow_empty=True)]
        for path in self.depends:
            if not path.exists():
                raise SlamSystemError(
                    f"command: depends: {path} does not exist (list the files and folders whose content decides the results)"
                )

        self._check_placeholders()

    # -- construction checks -------------------------------------------------------------------
    def _check_placeholders(self) -> None:
        known = ", ".join("{" + n + "}" for n in PLACEHOLDERS)
        fields: list[tuple[str, str]] = [(f"argv[{i}]", a) for i, a in enumerate(self.argv)]
        fields += [(f"prefix[{i}]", a) for i, a in enumerate(self.prefix)]
        fields += [(f"env[{k!r}]", v) for k, v in self.env.items()]
        if self.cwd is not None:
            fields.append(("cwd", self.cwd))
        fields.append(("output", self.output))
        used: set[str] = set()
        for where, text in fields:
            for name in placeholders_in(text):
                if name not in PLACEHOLDERS:
                    raise SlamSystemError(
                        f"command: unknown placeholder {{{name}}} in {where} ({text!r}); known: {known} (write {{{{ and }}}} for literal braces)"
                    )
                used.add(name)
        for number, line in enumerate(self._settings_text.splitlines(), start=1):
            for name in placeholders_in(line):
                if name not in PLACEHOLDERS:
                    raise SlamSystemError(
                        f"command: {self.settings}:{number}: unknown placeholder {{{name}}} in the settings template; known: {known} (write {{{{ and }}}} for literal braces)"
                    )
                used.add(name)
        for where, text in [("cwd", self.cwd or ""), ("output", self.output)]:
            bad = {"output", "output_times", "settings", "timestamps", "timestamps_ns", "associations"} & set(placeholders_in(text))
            if bad:
                raise SlamSystemError(
                    f"command: {where} cannot use {', '.join('{' + b + '}' for b in sorted(bad))} (only {{workdir}}, {{sequence}} and the sequence's figures)"
                )
        if "settings" in used and self.settings is None:
            raise SlamSystemError("command: {settings} is used but no settings template was given (option settings=PATH)")
        if "output" in used and self.output_is_pattern:
            raise SlamSystemError(
                f"command: output {self.output!r} is a glob pattern, so {{output}} has no single path; give output a file path"
            )
        if "associations" in used and self.layout not in (None, "tum"):
            raise SlamSystemError(f"command: {{associations}} needs the tum layout, but layout is {self.layout!r}")
        self._used = used

    def options(self) -> dict[str, Any]:
        return {
            "argv": list(self.argv),
            "prefix": list(self.prefix),
            "output": self.output,
            "output_format": self.output_format,
            "time_unit": self.time_unit,
            "keyframes": self.keyframes,
            "layout": self.layout,
            "sensor": self.sensor,
            "grayscale": self.grayscale,
            "stage_dir": self.stage_dir,
            "settings": None if self.settings is None else str(self.settings),
            "settings_sha256": hashlib.sha256(self._settings_text.encode()).hexdigest() if self.settings else None,
            "env": dict(self.env),
            "cwd": self.cwd,
            "name": self.name,
            "version": self.program_version,
            "depends": [str(p) for p in self.depends],
            "deterministic": self.deterministic,
        }

    def identity(self) -> dict[str, Any]:
        """``SlamSystem.identity`` plus the system kind and the SHA-256 of every file it runs:
        the executable, ``argv`` items that are files and ``depends`` (the settings template's
        is in ``options()``)."""
        files: dict[str, str | None] = {}
        for arg, path in self._program_files():
            files[arg] = None if path is None else _digest(path, "the argv file")
        for path in self.depends:
            files[str(path)] = _tree_digest(path) if path.is_dir() else _digest(path, "the depends file")
        return {**super().identity(), "system": "command", "files": files}

    def _program_files(self) -> list[tuple[str, Path | None]]:
        """``(argv item, file)`` for the executable (``None``: not found) and each other argv
        item that names an existing file; items with placeholders are left out."""
        cwd = Path(self.cwd).expanduser() if self.cwd is not None and not placeholders_in(self.cwd) else None
        base = cwd if cwd is not None and cwd.is_absolute() else Path.cwd()
        path_var = self.env.get("PATH")
        search = path_var if path_var is not None and not placeholders_in(path_var) else os.environ.get("PATH")
        out: list[tuple[str, Path | None]] = []
        for i, arg in enumerate(self.argv):
            if placeholders_in(arg) or not arg:
                continue
            text = render(arg, {})
            if i == 0 and os.sep not in text:
                found = shutil.which(text, path=search)
                out.append((arg, None if found is None else Path(found)))
                continue
            path = Path(text).expanduser()
            path = path if path.is_absolute() else base / path
            if path.is_file():
                out.append((arg, path))
            elif i == 0:
                out.append((arg, None))
        return out  # the settings template is in options() as settings_sha256: the text read at creation, the one rendered

    # -- running -------------------------------------------------------------------------------
    def run(self, sequence: Sequence, workdir: Path, timeout: float | None = None) -> RunResult:
        """Stage ``sequence`` under ``workdir/<stage_dir>``, run the program (log: ``workdir/run.log``),
        read its trajectory. Failures of the program come back in the result."""
        mode = self.mode_for(sequence, self.sensor)
        workdir = Path(workdir).expanduser().resolve()
        workdir.mkdir(parents=True, exist_ok=True)
        layout = self.layout or sequence.kind
        if layout in LAYOUT_SENSORS and mode not in LAYOUT_SENSORS[layout]:
            raise SlamSystemError(
                f"command: the {layout} layout cannot hold {mode} data (it holds {', '.join(LAYOUT_SENSORS[layout])}); "
                f"choose another layout= or sensor='mono'"
            )

        stage_start = time.monotonic()
        staged_seq = _staged_copy(sequence, mode, self.grayscale)
        staged = write_sequence(staged_seq, workdir / self.stage_dir, layout=layout)
        stamps = sequence.timestamps
        values = self._values(sequence, mode, workdir, staged)
        atomic_write_text(workdir / "timestamps.txt", "".join(format_float(t) + "\n" for t in stamps))
        ns = [r.timestamp_ns if r.timestamp_ns is not None else seconds_to_ns(r.timestamp) for r in sequence.records]
        atomic_write_text(workdir / "timestamps_ns.txt", "".join(f"{n}\n" for n in ns))
        if "associations" in self._used:
            source = staged / "associations.txt"
            if not source.is_file():
                raise SlamSystemError(
                    f"command: {{associations}} needs an RGB-D sequence staged in the tum layout (sensor rgbd, layout tum); {source} was not written"
                )
            rows = [line for line in source.read_text().splitlines() if line.strip() and not line.lstrip().startswith("#")]
            atomic_write_text(workdir / "associations.txt", "\n".join(rows) + "\n")

        cwd = Path(render(self.cwd, values)).expanduser() if self.cwd is not None else workdir
        if not cwd.is_absolute():
            cwd = workdir / cwd
        if not cwd.is_dir():
            raise SlamSystemError(f"command: cwd {cwd} is not a folder")
        output = Path(render(self.output, values)).expanduser()
        if not output.is_absolute():
            output = cwd / output
        values["output"] = str(output)
        if self.settings is not None:
            rendered = workdir / "settings" / self.settings.name
            atomic_write_text(rendered, render(self._settings_text, values))
        command = [render(a, values) for a in [*self.prefix, *self.argv]]
        env = dict(os.environ)
        env.update({k: render(v, values) for k, v in self.env.items()})

        times_path = workdir / "output_times.txt"
        times_path.unlink(missing_ok=True)
        before = snapshot(output, self.output_is_pattern, workdir)
        stage_time = time.monotonic() - stage_start

        log_path = workdir / LOG_NAME
        status, timed_out, wall, start_error = run_process_group(command, cwd, env, log_path, timeout)

        info: dict[str, Any] = {
            "argv": command,
            "cwd": str(cwd),
            "staged": str(staged),
            "layout": layout,
            "output": str(output),
            "output_format": self.output_format,
            "time_unit": self.time_unit,
            "stage_time_s": round(stage_time, 3),
        }
        if self.settings is not None:
            info["settings"] = str(workdir / "settings" / self.settings.name)

        trajectory: Trajectory | None = None
        output_error: str | None = None
        if start_error is None:
            found, output_error = find_output(output, self.output_is_pattern, before)
            if found is not None:
                info["output"] = str(found)
                try:
                    trajectory = read_output(
                        found, self.output_format, self.time_unit, stamps, times_path if written_since(times_path, before) else None
                    )
                except DatasetError as exc:
                    output_error = f"unparsable output: {exc}"
                except ValueError as exc:
                    output_error = f"unparsable output: {found}: {exc}"

        states = np.full(len(stamps), TrackState.NOT_INITIALISED, dtype=np.int8)
        scored: Trajectory | None = None
        if trajectory is not None:
            info["poses"] = len(trajectory)
            states, scored = frame_states(stamps, sequence.fps, trajectory, self.keyframes)
            if scored is None and output_error is None:
                output_error = no_match_message(found, stamps, sequence.fps, trajectory, self.time_unit)

        if start_error is not None:
            failure: str | None = start_error
        elif timed_out:
            failure = f"timed out after {timeout:g} s and was killed"
        elif status != 0:
            failure = describe_exit(status) + (" (command not found by the shell or prefix)" if status == 127 else "")
            if scored is not None and output_error is None:  # it crashed after writing its trajectory (at shutdown)
                failure += f" after writing its trajectory ({info['poses']} poses: kept and scored)"
                info[WRITTEN_BEFORE_FAILURE] = True
        else:
            failure = output_error
        if output_error is not None and failure != output_error:
            info["output_error"] = output_error

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

    def _values(self, sequence: Sequence, mode: str, workdir: Path, staged: Path) -> dict[str, str]:
        cam = sequence.camera
        dist = [*cam.distortion, 0.0, 0.0, 0.0, 0.0, 0.0][:5]
        baseline = cam.baseline_m or 0.0
        values = {
            "sequence": str(staged),
            "workdir": str(workdir),
            "output_times": str(workdir / "output_times.txt"),
            "timestamps": str(workdir / "timestamps.txt"),
            "timestamps_ns": str(workdir / "timestamps_ns.txt"),
            "associations": str(workdir / "associations.txt"),
            "fps": str(int(sequence.fps)) if float(sequence.fps).is_integer() else format_float(sequence.fps),
            "frames": str(len(sequence)),
            "sensor": mode,
            "camera_fx": format_float(cam.fx),
            "camera_fy": format_float(cam.fy),
            "camera_cx": format_float(cam.cx),
            "camera_cy": format_float(cam.cy),
            "camera_width": str(int(cam.width)),
            "camera_height": str(int(cam.height)),
            "camera_k1": format_float(dist[0]),
            "camera_k2": format_float(dist[1]),
            "camera_p1": format_float(dist[2]),
            "camera_p2": format_float(dist[3]),
            "camera_k3": format_float(dist[4]),
            "camera_baseline": format_float(baseline),
            "camera_bf": format_float(cam.fx * baseline),
        }
        if self.settings is not None:
            values["settings"] = str(workdir / "settings" / self.settings.name)
        return values


# -- helpers ---------------------------------------------------------------------------------------
def _digest(path: Path, what: str) -> str:
    try:
        return file_sha256(path)
    except OSError as exc:
        raise SlamSystemError(f"command: cannot read {what} {path} to hash it for the cache key ({exc.strerror or exc})") from None


def _tree_digest(folder: Path) -> str:
    """SHA-256 over the sorted relative paths and contents of the files under ``folder``
    (caches and version-control folders left out); at most ``DEPENDS_MAX_FILES`` files and
    ``DEPENDS_MAX_BYTES`` bytes."""
    files: list[tuple[str, Path]] = []
    total = 0
    for root, dirs, names in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if d not in _SKIPPED_DIRS)
        for name in names:
            path = Path(root) / name
            if name.endswith((".pyc", ".pyo")) or not path.is_file():
                continue
            files.append((path.relative_to(folder).as_posix(), path))
            total += path.stat().st_size
            if len(files) > DEPENDS_MAX_FILES or total > DEPENDS_MAX_BYTES:
                raise SlamSystemError(
                    f"command: depends folder {folder} holds more than {DEPENDS_MAX_FILES} files or {DEPENDS_MAX_BYTES >> 20} MiB; "
                    "list the files and smaller folders that decide the results instead"
                )
    digest = hashlib.sha256()
    for relative, path in sorted(files):
        digest.update(f"{relative}\0{_digest(path, 'the depends file')}\n".encode())
    return digest.hexdigest()


def _string_list(option: str, value: Any, allow_empty: bool) -> list[str]:
    if isinstance(value, (str, bytes)):
        raise SlamSystemError(
            f"command: {option} must be a list of strings, not a shell string: pass {shlex.split(value) if isinstance(value, str) else value!r} "
            "(each argument one item; no shell is involved)"
        )
    if not isinstance(value, (list, tuple)):
        raise SlamSystemError(f"command: {option} must be a list of strings, got {type(value).__name__}")
    out = []
    for i, item in enumerate(value):
        if not isinstance(item, (str, os.PathLike)):
            raise SlamSystemError(f"command: {option}[{i}] must be a string, got {item!r} ({type(item).__name__})")
        out.append(os.fspath(item))
    if not out and not allow_empty:
        raise SlamSystemError(f"command: {option} is empty; give the program and its arguments")
    return out


def _staged_copy(sequence: Sequence, mode: str, grayscale: bool | None) -> Sequence:
    staged = sequence
    if mode == "mono" and sequence.sensor != "mono":
        records = [dataclasses.replace(r, right=None, depth=None) for r in sequence.records]
        staged = staged.replace(sensor="mono", records=records)
    if grayscale is not None and grayscale != sequence.grayscale:
        staged = staged.replace(grayscale=grayscale)
    return staged
