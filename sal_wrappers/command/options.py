"""The options of the ``command`` system, checked once when the system is created.

``parse_command_options(options)`` turns the keyword arguments of ``create("command", ...)``
into a ``CommandOptions`` or raises one ``SlamSystemError`` that names the option, what was
given and what is allowed (``CommandSystem`` documents each option).
"""

from __future__ import annotations

import dataclasses
import os
import re
import shlex
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sal_adapters.datasets import DATASETS
from sal_wrappers.base import SlamSystemError
from sal_wrappers.command.output import OUTPUT_FORMATS, TIME_UNITS
from sal_wrappers.command.placeholders import PLACEHOLDERS, placeholders_in

__all__ = ["LAYOUT_SENSORS", "LOG_NAME", "SENSORS", "CommandOptions", "parse_command_options"]

#: The modes a command system runs in.
SENSORS = ("mono", "stereo", "rgbd")
#: What each built-in layout can hold (a plug-in layout is not checked).
LAYOUT_SENSORS = {
    "kitti": ("mono", "stereo"),
    "euroc": ("mono", "stereo"),
    "tum": ("mono", "rgbd"),
    "folder": ("mono",),
    "synthetic": ("mono", "stereo", "rgbd"),
}
#: The program's log in the work folder.
LOG_NAME = "run.log"

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
    "num_cpus",
    "num_gpus",
    "memory",
)
#: The most CPUs and GPUs one run may ask for.
_MOST_CPUS, _MOST_GPUS = 1024.0, 64.0
_NAME = re.compile(r"[A-Za-z0-9._-]{1,64}")
#: Names in the work folder that the system writes itself.
_RESERVED = {"settings", LOG_NAME, "timestamps.txt", "timestamps_ns.txt", "associations.txt", "output_times.txt"}


@dataclass(frozen=True)
class CommandOptions:
    """Checked options of a command system (the meaning of each is in ``CommandSystem``).

    Attributes:
        settings_text: the settings template as read at creation (the text rendered each run).
        used: the placeholders used anywhere, the settings template included.
    """

    name: str
    argv: list[str]
    prefix: list[str]
    output_format: str
    time_unit: str
    keyframes: bool
    deterministic: bool
    layout: str | None
    sensor: str | None
    grayscale: bool | None
    stage_dir: str
    env: dict[str, str]
    cwd: str | None
    output: str
    settings: Path | None
    settings_text: str
    version: str | None
    depends: list[Path]
    num_cpus: float
    num_gpus: float
    memory: int | None
    used: frozenset[str] = frozenset()

    @property
    def output_is_pattern(self) -> bool:
        """``output`` is a glob pattern (``logs/*.txt``), not one path."""
        return any(c in self.output for c in "*?[")


def parse_command_options(options: Mapping[str, Any]) -> CommandOptions:
    """``options`` checked, in this order: name, unknown names, the program, how results are
    read, staging, environment, identity; then the placeholders everywhere."""
    name = options.get("name", "command")
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise SlamSystemError(
            f"command: option name={name!r} is not allowed: give 1 to 64 letters, digits, '.', '_' or '-' (the name shown in results and history)"
        )
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
    config = CommandOptions(
        name=name,
        argv=_string_list("argv", options["argv"], allow_empty=False),
        prefix=_string_list("prefix", options.get("prefix") or [], allow_empty=True),
        **_results(options),
        **_staging(options),
        **_environment(options),
        **_identity(options),
        **_resources(options),
    )
    return dataclasses.replace(config, used=frozenset(_used_placeholders(config)))


def _results(options: Mapping[str, Any]) -> dict[str, Any]:
    """How the output is read (format, time unit, keyframes) and whether runs vary."""
    output_format = options.get("output_format", "tum")
    if not isinstance(output_format, str) or output_format not in OUTPUT_FORMATS:
        raise SlamSystemError(f"command: output_format {output_format!r} is not known; allowed: {', '.join(OUTPUT_FORMATS)}")
    time_unit = options.get("time_unit")
    if time_unit is not None and (not isinstance(time_unit, str) or time_unit not in TIME_UNITS):
        raise SlamSystemError(f"command: time_unit {time_unit!r} is not known; allowed: {', '.join(TIME_UNITS)}")
    if output_format == "euroc" and time_unit not in (None, "ns"):
        raise SlamSystemError(f"command: the euroc format stores times in ns; time_unit {time_unit!r} does not apply")
    keyframes = options.get("keyframes", False)
    if not isinstance(keyframes, bool):
        raise SlamSystemError(f"command: keyframes must be True or False, got {keyframes!r}")
    deterministic = options.get("deterministic", False)
    if not isinstance(deterministic, bool):
        raise SlamSystemError(f"command: deterministic must be True or False, got {deterministic!r}")
    unit = time_unit or ("ns" if output_format == "euroc" else "s")
    return {"output_format": output_format, "time_unit": unit, "keyframes": keyframes, "deterministic": deterministic}


def _staging(options: Mapping[str, Any]) -> dict[str, Any]:
    """How the sequence is staged: layout, sensor (or mode), grey or colour, folder."""
    layout = options.get("layout")
    if layout is not None and (not isinstance(layout, str) or layout not in DATASETS.names()):
        raise SlamSystemError(
            f"command: layout {layout!r} is not a dataset layout; allowed: {', '.join(DATASETS.names())} (default: the sequence's own)"
        )
    sensor, mode = options.get("sensor"), options.get("mode")
    if sensor is not None and mode is not None and sensor != mode:
        raise SlamSystemError(f"command: sensor={sensor!r} and mode={mode!r} disagree (they are the same option)")
    sensor = sensor if sensor is not None else mode
    if sensor is not None and (not isinstance(sensor, str) or sensor not in SENSORS):
        raise SlamSystemError(f"command: sensor {sensor!r} is not known; allowed: {', '.join(SENSORS)} (default: the sequence's own)")
    if layout in LAYOUT_SENSORS and sensor is not None and sensor not in LAYOUT_SENSORS[layout]:
        raise SlamSystemError(f"command: the {layout} layout cannot hold {sensor} data (it holds {', '.join(LAYOUT_SENSORS[layout])})")
    grayscale = options.get("grayscale")
    if grayscale is not None and not isinstance(grayscale, bool):
        raise SlamSystemError(f"command: grayscale must be True, False or None, got {grayscale!r}")
    stage_dir = options.get("stage_dir", "sequence")
    parts = Path(stage_dir).parts if isinstance(stage_dir, (str, os.PathLike)) else ()
    if not parts or Path(stage_dir).is_absolute() or ".." in parts or parts[0] in _RESERVED:
        raise SlamSystemError(
            f"command: stage_dir must be a relative folder inside the work folder, without '..' and not one of "
            f"{', '.join(sorted(_RESERVED))}; got {stage_dir!r}"
        )
    return {"layout": layout, "sensor": sensor, "grayscale": grayscale, "stage_dir": os.fspath(stage_dir)}


def _environment(options: Mapping[str, Any]) -> dict[str, Any]:
    """Where and how the program runs: env, cwd, its output path, the settings template."""
    env = options.get("env") or {}
    if not isinstance(env, Mapping) or not all(isinstance(k, str) and isinstance(v, (str, os.PathLike)) for k, v in env.items()):
        raise SlamSystemError(f"command: env must map variable names to strings, got {env!r}")
    cwd = options.get("cwd")
    if cwd is not None and not isinstance(cwd, (str, os.PathLike)):
        raise SlamSystemError(f"command: cwd must be a folder path, got {cwd!r}")
    output = options.get("output", "{workdir}/trajectory.txt")
    if not isinstance(output, (str, os.PathLike)) or not os.fspath(output):
        raise SlamSystemError(f"command: output must be a file path or glob pattern, got {output!r}")
    settings = options.get("settings")
    path: Path | None = None
    text = ""
    if settings is not None:
        if not isinstance(settings, (str, os.PathLike)):
            raise SlamSystemError(f"command: settings must be a template file path, got {settings!r}")
        path = Path(settings).expanduser().resolve()
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise SlamSystemError(f"command: settings template not found: {path}") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise SlamSystemError(f"command: cannot read settings template {path} as text ({exc})") from None
    return {
        "env": {k: os.fspath(v) for k, v in env.items()},
        "cwd": None if cwd is None else os.fspath(cwd),
        "output": os.fspath(output),
        "settings": path,
        "settings_text": text,
    }


def _identity(options: Mapping[str, Any]) -> dict[str, Any]:
    """What names the program beyond its files: its version, and the files it depends on."""
    version = options.get("version")
    if version is not None and (not isinstance(version, (str, int)) or isinstance(version, bool) or not str(version).strip()):
        raise SlamSystemError(f"command: option version={version!r} is not allowed: give the program's version as a non-empty string")
    depends = [Path(p).expanduser().resolve() for p in _string_list("depends", options.get("depends") or [], allow_empty=True)]
    for path in depends:
        if not path.exists():
            raise SlamSystemError(f"command: depends: {path} does not exist (list the files and folders whose content decides the results)")
    return {"version": None if version is None else str(version), "depends": depends}


def _resources(options: Mapping[str, Any]) -> dict[str, Any]:
    """What one run takes where it runs (not part of the cache key): CPUs, GPUs, memory."""
    num_cpus = _number("num_cpus", options.get("num_cpus", 1.0), _MOST_CPUS, "CPU cores, 0 < num_cpus <= 1024 (fractions allowed)")
    num_gpus = _number("num_gpus", options.get("num_gpus", 0.0), _MOST_GPUS, "GPUs, 0 <= num_gpus <= 64 (fractions allowed)", zero=True)
    memory = options.get("memory")
    if memory is not None and (not isinstance(memory, int) or isinstance(memory, bool) or memory <= 0):
        raise SlamSystemError(
            f"command: option memory={memory!r} is not allowed; give the memory one run takes in bytes as a whole number > 0 "
            "(8000000000 for 8 GB), or leave it out"
        )
    return {"num_cpus": num_cpus, "num_gpus": num_gpus, "memory": memory}


def _number(option: str, value: Any, high: float, what: str, zero: bool = False) -> float:
    """``value`` as a float above 0 (or 0 itself when ``zero``) up to ``high``, else one error
    naming the option, the value and the range ``what``."""
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not number or not (0 < value <= high or (zero and value == 0)):
        raise SlamSystemError(f"command: option {option}={value!r} is not allowed; give {what}")
    return float(value)


def _used_placeholders(config: CommandOptions) -> set[str]:
    """Every placeholder used; an unknown one, or one where it cannot apply, is an error."""
    known = ", ".join("{" + n + "}" for n in PLACEHOLDERS)
    fields: list[tuple[str, str]] = [(f"argv[{i}]", a) for i, a in enumerate(config.argv)]
    fields += [(f"prefix[{i}]", a) for i, a in enumerate(config.prefix)]
    fields += [(f"env[{k!r}]", v) for k, v in config.env.items()]
    if config.cwd is not None:
        fields.append(("cwd", config.cwd))
    fields.append(("output", config.output))
    used: set[str] = set()
    for where, text in fields:
        for name in placeholders_in(text):
            if name not in PLACEHOLDERS:
                raise SlamSystemError(
                    f"command: unknown placeholder {{{name}}} in {where} ({text!r}); known: {known} (write {{{{ and }}}} for literal braces)"
                )
            used.add(name)
    for number, line in enumerate(config.settings_text.splitlines(), start=1):
        for name in placeholders_in(line):
            if name not in PLACEHOLDERS:
                raise SlamSystemError(
                    f"command: {config.settings}:{number}: unknown placeholder {{{name}}} in the settings template; known: {known} (write {{{{ and }}}} for literal braces)"
                )
            used.add(name)
    for where, text in [("cwd", config.cwd or ""), ("output", config.output)]:
        bad = {"output", "output_times", "settings", "timestamps", "timestamps_ns", "associations"} & set(placeholders_in(text))
        if bad:
            raise SlamSystemError(
                f"command: {where} cannot use {', '.join('{' + b + '}' for b in sorted(bad))} (only {{workdir}}, {{sequence}} and the sequence's figures)"
            )
    if "settings" in used and config.settings is None:
        raise SlamSystemError("command: {settings} is used but no settings template was given (option settings=PATH)")
    if "output" in used and config.output_is_pattern:
        raise SlamSystemError(
            f"command: output {config.output!r} is a glob pattern, so {{output}} has no single path; give output a file path"
        )
    if "associations" in used and config.layout not in (None, "tum"):
        raise SlamSystemError(f"command: {{associations}} needs the tum layout, but layout is {config.layout!r}")
    return used


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
