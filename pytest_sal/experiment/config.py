"""Experiment configs: the SAL YAML schema, validated up front (``sal perturb``, ``sal evaluate``,
``sal boundary`` and ``sal features`` read them).

The schema is the paper's (``experiment``, ``dataset``, ``perturbations`` with ``composite``,
``output``, ``robustness_boundary``), with what was broken there fixed:

* an unknown key, a wrong type, an unknown module or parameter, or an out-of-range value is one
  ``ConfigError`` naming the file and the key's path (``perturbations[1].parameters.visibility_m``)
  and what is allowed; YAML syntax errors and duplicate keys name the line;
* ``experiment.seed`` really seeds every perturbation;
* validation creates nothing; ``--dry-run`` only prints the plan;
* each perturbation is written to ``images/<name>/`` by its exact name.
"""

from __future__ import annotations

import math
import os
import re
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from pytest_sal.experiment.yaml_loader import (
    NAME_CHARS,
    PATH_CHARS,
    QUOTE_CHARS,
    ConfigError,
    key_text,
    one_line,
    quote,
    read_yaml,
    type_name,
)
from sal_adapters.datasets import DATASETS, DatasetKind, open_dataset
from sal_adapters.errors import SalError
from sal_adapters.plugins import EntryPointRegistry, PluginError
from sal_adapters.suggest import suggestion
from sal_modules.errors import ParameterError

if TYPE_CHECKING:  # numpy and the modules load when a config is read, not for `sal --help`
    from sal_adapters.sequence import Sequence
    from sal_modules.base import Perturbation

__all__ = [
    "BASELINE",
    "BoundaryConfig",
    "ConfigError",
    "DatasetConfig",
    "EvaluationConfig",
    "ExperimentConfig",
    "ExperimentInfo",
    "OutputConfig",
    "PerturbationConfig",
    "StepConfig",
    "build_module",
    "build_modules",
    "build_sequence",
    "load_config",
    "parse_config",
    "perturbed_sequences",
]

T = TypeVar("T")

#: name of the clean sequence in every output tree (a perturbation of another type may not take it)
BASELINE = "baseline"

SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,99}")
SAFE_NAME_TEXT = "1 to 100 letters, digits, '_', '-', '.' (not first)"


# ------------------------------------------------------------------------------ the schema


@dataclass(frozen=True)
class ExperimentInfo:
    name: str
    description: str = ""
    version: str = "1.0.0"
    seed: int = 0


@dataclass(frozen=True)
class DatasetConfig:
    type: str
    path: Path | None = None
    sequence: str | None = None
    max_frames: int | None = None
    start: int = 0
    stereo: bool = False
    options: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class StepConfig:
    """One child of a composite perturbation."""

    type: str
    parameters: Mapping[str, Any] = field(default_factory=dict)
    name: str | None = None


@dataclass(frozen=True)
class PerturbationConfig:
    name: str
    type: str  # a registered module, "none" or "composite"
    enabled: bool = True
    parameters: Mapping[str, Any] = field(default_factory=dict)
    modules: tuple[StepConfig, ...] = ()  # composite only


@dataclass(frozen=True)
class OutputConfig:
    base_dir: Path = Path("results")
    create_timestamp_dir: bool = False


@dataclass(frozen=True)
class BoundaryConfig:
    target_perturbation: str
    parameter: str
    lower_bound: float
    upper_bound: float
    enabled: bool = False
    name: str = ""
    module: str = ""
    tolerance: float = 0.05
    max_iters: int = 8
    ate_rmse_fail: float = 1.5
    fail_on_tracking_failure: bool = True


@dataclass(frozen=True)
class EvaluationConfig:
    """How ``sal evaluate`` and ``sal boundary`` score runs: ``kitti_segments_m``, the segment
    lengths (m) of KITTI's ``t_rel`` / ``r_rel`` (``None``: the devkit's 100 .. 800 m)."""

    kitti_segments_m: tuple[float, ...] | None = None


@dataclass(frozen=True)
class ExperimentConfig:
    source: str
    experiment: ExperimentInfo
    dataset: DatasetConfig
    perturbations: tuple[PerturbationConfig, ...]
    output: OutputConfig
    robustness_boundary: BoundaryConfig | None = None
    text: str = ""  # the config file as read (copied into the output)
    evaluation: EvaluationConfig = field(default_factory=EvaluationConfig)

    def output_dir(self, now: datetime | None = None) -> Path:
        """``<base_dir>/<experiment.name>[_<timestamp>]``."""
        name = self.experiment.name
        if self.output.create_timestamp_dir:
            name += "_" + (now or datetime.now()).strftime("%Y%m%d_%H%M%S")
        return self.output.base_dir / name

    def enabled(self) -> list[PerturbationConfig]:
        return [p for p in self.perturbations if p.enabled]


# ------------------------------------------------------------------------------ loading

_TOP = ("experiment", "dataset", "perturbations", "output", "robustness_boundary", "evaluation")
_EVALUATION = ("kitti_segments_m",)
_EXPERIMENT = ("name", "description", "version", "seed")
_DATASET = ("type", "path", "sequence", "max_frames", "start", "stereo", "options")
_PERTURBATION = ("name", "type", "enabled", "parameters")
_STEP = ("name", "type", "parameters")
_COMPOSITE = ("mode", "modules")
_OUTPUT = ("base_dir", "create_timestamp_dir")
_BOUNDARY = (
    "enabled",
    "name",
    "target_perturbation",
    "module",
    "parameter",
    "lower_bound",
    "upper_bound",
    "tolerance",
    "max_iters",
    "ate_rmse_fail",
    "fail_on_tracking_failure",
)


#: Limits of the schema, checked before anything is built: the perturbation modules (each
#: composite step counts; a dry run sets each up on the first frame) and the frames of a dataset.
MAX_PERTURBATIONS = 256
MAX_FRAMES = 1_000_000
#: Frames the synthetic world renders (``dataset.options.frames``): opening it computes every pose.
MAX_RENDERED_FRAMES = 10_000
#: Bytes of a path a config names, and of one file or folder name in it (Linux PATH_MAX, NAME_MAX).
MAX_PATH_BYTES = 4096
MAX_NAME_BYTES = 255
#: Trials of a boundary search (bisection: 64 halvings reach a double's precision).
MAX_SEARCH_TRIALS = 100
#: Segment lengths of the KITTI metrics (the devkit has 8).
MAX_KITTI_SEGMENTS = 100


def load_config(path: str | os.PathLike[str]) -> ExperimentConfig:
    """Read and validate the experiment config at ``path`` (nothing is created)."""
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(source, "", "config file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(source, "", f"cannot read the config: {exc}") from None
    return parse_config(text, source)


def parse_config(text: str, source: str = "<config>") -> ExperimentConfig:
    """Validate the YAML ``text`` (``source`` names it in errors) within the limits of
    ``pytest_sal.experiment.yaml_loader`` and the schema's."""
    data = read_yaml(text, source)
    return _Parser(source).config(data, text)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_finite(value: Any) -> bool:
    """A number, not NaN nor infinite (nor an integer too large for a float)."""
    try:
        return _is_number(value) and math.isfinite(value)
    except OverflowError:  # an integer beyond any float
        return False


#: What a dataset option annotated with each type takes from YAML: (words, check).
_OPTION_TYPES: dict[Any, tuple[str, Callable[[Any], bool]]] = {
    type(None): ("null", lambda v: v is None),
    bool: ("true or false", lambda v: isinstance(v, bool)),
    int: ("an integer", lambda v: isinstance(v, int) and not isinstance(v, bool)),
    float: ("a number", _is_finite),
    str: ("a string", lambda v: isinstance(v, str)),
    Path: ("a path", lambda v: isinstance(v, str)),
}


def _alternatives(hint: Any) -> tuple[Any, ...]:
    """The types of the annotation ``hint`` (``str | None``: ``str``, ``NoneType``)."""
    return typing.get_args(hint) if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union else (hint,)


def _option_types(hint: Any) -> list[tuple[str, Callable[[Any], bool]]] | None:
    """(words, check) of each type an option annotated ``hint`` may be (``tuple[float, ...]``:
    a list of numbers), or ``None`` for an annotation not known here."""
    found = []
    alternatives = _alternatives(hint)
    for alt in alternatives:
        items = typing.get_args(alt) if typing.get_origin(alt) is tuple else ()
        if alt is str and Path in alternatives:
            continue
        if alt in _OPTION_TYPES:
            found.append(_OPTION_TYPES[alt])
        elif items and set(items) <= {int, float, Ellipsis}:
            n = None if Ellipsis in items else len(items)

            def numbers(v: Any, n: int | None = n) -> bool:
                return isinstance(v, list) and n in (None, len(v)) and all(_is_finite(x) for x in v)

            found.append((f"a list of {n or 'some'} numbers", numbers))
        else:
            return None
    return found


def _option_hints(kind: DatasetKind) -> dict[str, Any]:
    """The annotations of the options of a dataset kind (none where they cannot be read)."""
    try:
        return typing.get_type_hints(kind.open)
    except Exception:  # a plug-in's annotation naming what its module does not import
        return {}


class _Parser:
    def __init__(self, source: str):
        self.source = source

    def error(self, where: str, message: str) -> ConfigError:
        return ConfigError(self.source, where, message)

    # -- generic helpers
    def mapping(self, value: Any, where: str, known: tuple[str, ...], required: tuple[str, ...] = ()) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.error(where or "top level", f"must be a mapping with keys {', '.join(known)}; got {type_name(value)}")
        prefix = f"{where}." if where else ""
        for key in value:
            if key not in known:
                raise self.error(f"{prefix}{key_text(key)}", "unknown key" + suggestion(str(key), known, "known"))
        for key in required:
            if value.get(key) is None:
                raise self.error(f"{prefix}{key}", "is required")
        return value

    def typed(self, value: Any, where: str, kind: str, *, optional: bool = False, minimum: float | None = None) -> Any:
        if value is None and optional:
            return None
        ok = {
            "str": isinstance(value, str),
            "bool": isinstance(value, bool),
            "int": isinstance(value, int) and not isinstance(value, bool),
            "number": _is_number(value),
            "dict": isinstance(value, dict),
            "list": isinstance(value, list),
        }[kind]
        words = {
            "str": "a string",
            "bool": "true or false",
            "int": "an integer",
            "number": "a number",
            "dict": "a mapping",
            "list": "a list",
        }[kind]
        if minimum is not None:
            words += f" >= {minimum:g}"
        if optional:
            words += " or null"
        if not ok or (minimum is not None and value < minimum):
            raise self.error(where, f"{quote(value)} is not valid; must be {words}")
        return float(value) if kind == "number" else value

    def search_trials(self, value: Any, where: str) -> int:
        """A number of boundary search trials, 1 .. ``MAX_SEARCH_TRIALS``."""
        trials = self.typed(value, where, "int", minimum=1)
        if trials > MAX_SEARCH_TRIALS:
            raise self.error(where, f"{trials} is not valid; the limit is {MAX_SEARCH_TRIALS} trials")
        return trials

    def frame_count(self, value: Any, where: str) -> int | None:
        """An optional frame count, 1 .. ``MAX_FRAMES``."""
        count = self.typed(value, where, "int", optional=True, minimum=1)
        if count is not None and count > MAX_FRAMES:
            raise self.error(where, f"{count} is not valid; the limit is {MAX_FRAMES} frames")
        return count

    def path(self, value: Any, where: str, *, optional: bool = False) -> str | None:
        """A path-valued key (every one is checked by ``checked_path``): a string a file system
        can take, with no NUL character, at most ``MAX_PATH_BYTES`` long and ``MAX_NAME_BYTES``
        per name."""
        text = self.typed(value, where, "str", optional=optional)
        return None if text is None else self.checked_path(text, where)

    def checked_path(self, text: str, where: str) -> str:
        """``text``, refused if it cannot be a path (see ``path``)."""
        if "\0" in text:
            raise self.error(where, f"contains a NUL character ({quote(text)}); no path can hold one")
        try:
            encoded = os.fsencode(text)
        except UnicodeEncodeError:
            raise self.error(where, f"{quote(text)} holds a character no file name can hold here") from None
        longest = max(encoded.split(b"/"), key=len)
        if len(encoded) > MAX_PATH_BYTES or len(longest) > MAX_NAME_BYTES:
            raise self.error(
                where,
                f"{quote(text)} is too long ({len(encoded)} bytes, a name of {len(longest)}); "
                f"a path may have at most {MAX_PATH_BYTES} bytes and each name in it {MAX_NAME_BYTES}",
            )
        return text

    def folder(self, value: Any, where: str) -> Path:
        """A path-valued key with ``$VARIABLES`` and ``~`` expanded, then checked."""
        text = self.typed(value, where, "str")
        return Path(self.checked_path(os.path.expanduser(os.path.expandvars(text)), where))

    def option(self, value: Any, where: str, hint: Any) -> None:
        """A dataset option checked against its annotation in the dataset kind's ``open``
        (a value of an annotation ``_option_types`` does not know is left to the kind)."""
        allowed = _option_types(hint)
        if allowed is None:
            return
        if not any(fits(value) for _, fits in allowed):
            words = [w for w, _ in allowed]
            raise self.error(
                where, f"{quote(value)} is not valid; must be {', '.join(words[:-1]) + ' or ' if len(words) > 1 else ''}{words[-1]}"
            )
        if isinstance(value, str) and Path in _alternatives(hint):
            self.checked_path(value, where)

    def registered(
        self, registry: EntryPointRegistry[T], name: str, where: str, known: tuple[str, ...] = (), hidden: tuple[str, ...] = ()
    ) -> T:
        """The entry ``name`` of ``registry``. Only an error lists the names (``known`` first,
        not ``hidden``): listing reads the entry points of every installed package."""
        try:
            return registry.get(name)
        except PluginError as exc:
            names = [n for n in registry.names() if n not in hidden]
            if name in names:  # installed, but it cannot be loaded
                raise self.error(where, one_line(str(exc), 3 * QUOTE_CHARS)) from None
            raise self.error(
                where, f"unknown {registry.what} {quote(name, NAME_CHARS)}" + suggestion(name, [*known, *names], "known")
            ) from None

    def safe_name(self, value: Any, where: str) -> str:
        self.typed(value, where, "str")
        if not SAFE_NAME.fullmatch(value):  # fullmatch: "name\n" is refused too (match's $ allows it)
            raise self.error(where, f"{quote(value)} cannot be a folder name; use {SAFE_NAME_TEXT}")
        return value

    # -- sections
    def config(self, data: Any, text: str) -> ExperimentConfig:
        if data is None:
            raise self.error("", "the config is empty; it needs the sections experiment, dataset, perturbations, output")
        top = self.mapping(data, "", _TOP, required=("experiment", "dataset"))
        experiment = self.experiment(top["experiment"])
        dataset = self.dataset(top["dataset"])
        perturbations = self.perturbations(top.get("perturbations"))
        output = self.output(top.get("output"))
        boundary = self.boundary(top.get("robustness_boundary"), perturbations)
        evaluation = self.evaluation(top.get("evaluation"))
        return ExperimentConfig(self.source, experiment, dataset, perturbations, output, boundary, text, evaluation)

    def experiment(self, value: Any) -> ExperimentInfo:
        d = self.mapping(value, "experiment", _EXPERIMENT, required=("name",))
        version = d.get("version", "1.0.0")
        if _is_number(version):
            version = str(version)
        return ExperimentInfo(
            name=self.safe_name(d["name"], "experiment.name"),
            description=self.typed(d.get("description", ""), "experiment.description", "str"),
            version=self.typed(version, "experiment.version", "str"),
            seed=self.typed(d.get("seed", 0), "experiment.seed", "int", minimum=0),
        )

    def dataset(self, value: Any) -> DatasetConfig:
        d = self.mapping(value, "dataset", _DATASET, required=("type",))
        kind = self.typed(d["type"], "dataset.type", "str")
        dataset_kind = self.registered(DATASETS, kind, "dataset.type")
        allowed = dataset_kind.option_names()
        folder = None if d.get("path") is None else self.folder(d["path"], "dataset.path")
        if folder is not None:
            try:
                found = "" if folder.is_dir() else "is not a folder" if folder.exists() else "does not exist"
            except OSError as exc:  # stat refused (a folder above is unreadable)
                found = f"cannot be read ({exc.strerror})"
            if found:
                raise self.error("dataset.path", f"{quote(str(folder), PATH_CHARS)} {found}; give the dataset folder")
        elif kind != "synthetic":
            raise self.error("dataset.path", f"is required for dataset kind {quote(kind)}")
        sequence = d.get("sequence")
        if kind == "kitti" and (type(sequence) is int or (isinstance(sequence, float) and sequence.is_integer())):
            sequence = f"{int(sequence):02d}"
        sequence = self.path(sequence, "dataset.sequence", optional=True)  # a folder in the dataset
        stereo = self.typed(d.get("stereo", False), "dataset.stereo", "bool")
        options = dict(self.typed(d.get("options") or {}, "dataset.options", "dict"))
        for key in options:
            if key not in allowed or key in ("sequence", "stereo"):
                rest = [a for a in allowed if a not in ("sequence", "stereo")]
                raise self.error(
                    f"dataset.options.{key_text(key)}",
                    f"unknown option of dataset kind {quote(kind)}" + suggestion(str(key), rest, "known"),
                )
        hints = _option_hints(dataset_kind)
        for key, value in options.items():
            self.option(value, f"dataset.options.{key}", hints.get(key))
        frames = options.get("frames")
        if _is_number(frames) and not 1 <= frames <= MAX_RENDERED_FRAMES:
            raise self.error(
                "dataset.options.frames", f"{quote(frames)} is not valid; must be a whole number in 1 .. {MAX_RENDERED_FRAMES}"
            )
        for key, given in (("sequence", sequence), ("stereo", stereo or None)):
            if given is not None and key not in allowed:
                raise self.error(
                    f"dataset.{key}", f"dataset kind {quote(kind)} has no {key} option; its options: {', '.join(allowed) or 'none'}"
                )
        return DatasetConfig(
            type=kind,
            path=folder,
            sequence=sequence,
            max_frames=self.frame_count(d.get("max_frames"), "dataset.max_frames"),
            start=self.typed(d.get("start", 0), "dataset.start", "int", minimum=0),
            stereo=stereo,
            options=options,
        )

    def perturbations(self, value: Any) -> tuple[PerturbationConfig, ...]:
        if value is None or value == []:
            return (PerturbationConfig(name="baseline", type="none"),)
        self.typed(value, "perturbations", "list")
        if len(value) > MAX_PERTURBATIONS:
            raise self.error("perturbations", f"{len(value)} perturbations; the limit is {MAX_PERTURBATIONS} (split the experiment)")
        found: list[PerturbationConfig] = []
        seen: dict[str, int] = {}
        modules = 0
        for i, item in enumerate(value):
            where = f"perturbations[{i}]"
            d = self.mapping(item, where, _PERTURBATION, required=("name", "type"))
            name = self.safe_name(d["name"], f"{where}.name")
            if name in seen:
                raise self.error(
                    f"{where}.name",
                    f"{quote(name)} is already the name of perturbations[{seen[name]}]; names must be unique (they are folder names)",
                )
            seen[name] = i
            kind = self.typed(d["type"], f"{where}.type", "str")
            if name == BASELINE and kind != "none":
                raise self.error(
                    f"{where}.name", f"{BASELINE!r} is kept for the clean sequence (type none); rename this {quote(kind)} perturbation"
                )
            enabled = self.typed(d.get("enabled", True), f"{where}.enabled", "bool")
            params = self.typed(d.get("parameters") or {}, f"{where}.parameters", "dict")
            if kind == "none":
                if params:
                    raise self.error(f"{where}.parameters", "type none (the clean sequence) takes no parameters")
                found.append(PerturbationConfig(name, kind, enabled))
            elif kind == "composite":
                steps = self.composite(params, f"{where}.parameters")
                found.append(PerturbationConfig(name, kind, enabled, dict(params), steps))
            else:
                self.module(kind, params, where, known=("none", "composite"))
                found.append(PerturbationConfig(name, kind, enabled, dict(params)))
            modules += len(found[-1].modules) or 1
            if modules > MAX_PERTURBATIONS:
                raise self.error(
                    where,
                    f"brings the modules to {modules} (composite steps count one each); the limit is {MAX_PERTURBATIONS} (split the experiment)",
                )
        return tuple(found)

    def module(self, kind: str, params: dict[str, Any], where: str, known: tuple[str, ...] = ()) -> Perturbation:
        """The module ``kind`` with ``params`` (``known``: the other types allowed there)."""
        from sal_modules.registry import PERTURBATIONS, module_class

        self.registered(PERTURBATIONS, kind, f"{where}.type", known, hidden=("composite",))
        cls = module_class(kind)
        specs = cls.parameters()
        for key, value in params.items():
            if key not in specs:
                raise self.error(
                    f"{where}.parameters.{key_text(key)}", f"{kind} has no such parameter" + suggestion(str(key), specs, "parameters")
                )
            spec = specs[key]
            try:
                spec.validate(value, kind)
            except ParameterError:
                shown = f"{quote(value)}{' ' + spec.unit if spec.unit and _is_number(value) else ''}"
                raise self.error(f"{where}.parameters.{key}", f"{shown} is not valid; {key} must be {spec.allowed()}") from None
            if spec.domain == "text":  # a file (night's ONNX model)
                self.path(value, f"{where}.parameters.{key}", optional=spec.optional)
        try:
            return cls(**params)
        except ParameterError as exc:
            raise self.error(f"{where}.parameters", str(exc)) from None

    def composite(self, params: dict[str, Any], where: str) -> tuple[StepConfig, ...]:
        d = self.mapping(params, where, _COMPOSITE, required=("modules",))
        mode = d.get("mode", "sequential")
        if mode != "sequential":
            raise self.error(f"{where}.mode", f"{quote(mode)} is not valid; the only mode is 'sequential'")
        modules = self.typed(d["modules"], f"{where}.modules", "list")
        if not modules:
            raise self.error(f"{where}.modules", "must list at least one module")
        if len(modules) > MAX_PERTURBATIONS:
            raise self.error(f"{where}.modules", f"{len(modules)} steps; the limit is {MAX_PERTURBATIONS} modules (split the experiment)")
        steps = []
        for j, item in enumerate(modules):
            at = f"{where}.modules[{j}]"
            s = self.mapping(item, at, _STEP, required=("type",))
            kind = self.typed(s["type"], f"{at}.type", "str")
            if kind in ("none", "composite"):
                raise self.error(f"{at}.type", f"{quote(kind)} cannot be a step of a composite; use a perturbation module")
            step_params = self.typed(s.get("parameters") or {}, f"{at}.parameters", "dict")
            self.module(kind, step_params, at)
            name = self.typed(s.get("name"), f"{at}.name", "str", optional=True)
            steps.append(StepConfig(kind, dict(step_params), name))
        return tuple(steps)

    def output(self, value: Any) -> OutputConfig:
        d = self.mapping(value if value is not None else {}, "output", _OUTPUT)
        return OutputConfig(
            base_dir=self.folder(d.get("base_dir", "results"), "output.base_dir"),
            create_timestamp_dir=self.typed(d.get("create_timestamp_dir", False), "output.create_timestamp_dir", "bool"),
        )

    def evaluation(self, value: Any) -> EvaluationConfig:
        d = self.mapping(value if value is not None else {}, "evaluation", _EVALUATION)
        segments = d.get("kitti_segments_m")
        if segments is None:
            return EvaluationConfig()
        where = "evaluation.kitti_segments_m"
        if not isinstance(segments, list) or not segments or not all(_is_finite(v) and v > 0 for v in segments):
            raise self.error(where, f"{quote(segments)} is not valid; must be a list of segment lengths > 0 m, e.g. [10, 20, 30, 40]")
        if len(segments) > MAX_KITTI_SEGMENTS:
            raise self.error(where, f"{len(segments)} lengths; the limit is {MAX_KITTI_SEGMENTS}")
        return EvaluationConfig(tuple(sorted({float(v) for v in segments})))

    def boundary(self, value: Any, perturbations: tuple[PerturbationConfig, ...]) -> BoundaryConfig | None:
        if value is None:
            return None
        w = "robustness_boundary"
        d = self.mapping(value, w, _BOUNDARY, required=("target_perturbation", "parameter", "lower_bound", "upper_bound"))
        target = self.typed(d["target_perturbation"], f"{w}.target_perturbation", "str")
        by_name = {p.name: p for p in perturbations}
        if target not in by_name:
            raise self.error(
                f"{w}.target_perturbation",
                f"{quote(target)} is not a perturbation of this config" + suggestion(target, by_name, "perturbations"),
            )
        pert = by_name[target]
        if pert.type == "none":
            raise self.error(
                f"{w}.target_perturbation", f"{quote(target)} is the clean sequence (type none); it has no parameter to search"
            )
        parameter = self.typed(d["parameter"], f"{w}.parameter", "str")
        from sal_modules.base import Composite

        module = build_module(pert)
        assert module is not None
        if isinstance(module, Composite):
            try:
                position, spec = module.param(parameter)
            except ParameterError:
                addresses = [a for a, (_, p) in module.addresses().items() if p.searchable and "@" not in a and "." in a]
                raise self.error(
                    f"{w}.parameter",
                    f"composite {quote(target)} has no parameter {quote(parameter)}" + suggestion(parameter, addresses, "searchable"),
                ) from None
            owner = module.steps[position].name
        else:
            spec = type(module).parameters().get(parameter)  # type: ignore[assignment]
            owner = module.name
        searchable = (
            [a for a, (_, p) in module.addresses().items() if p.searchable and "@" not in a and "." in a]
            if isinstance(module, Composite)
            else list(type(module).searchable())
        )
        if spec is None or not spec.searchable:
            raise self.error(
                f"{w}.parameter",
                f"{quote(parameter)} is not a searchable parameter of {quote(target)} ({module.name})"
                + suggestion(parameter, searchable, "searchable"),
            )
        declared = self.typed(d.get("module", ""), f"{w}.module", "str")
        if declared and declared != owner:
            raise self.error(
                f"{w}.module", f"{quote(declared)} does not match the module of {quote(parameter)} in {quote(target)}, which is {owner!r}"
            )
        scale = spec.search_space()
        unit = f" {scale.unit}" if scale.unit else ""
        allowed = f"{'an integer' if scale.domain == 'integer' else 'a number'} in {scale.min:g} .. {scale.max:g}{unit}"
        bounds = {}
        for key in ("lower_bound", "upper_bound"):
            v = d[key]
            ok = _is_number(v) and scale.min <= v <= scale.max and (scale.domain != "integer" or float(v).is_integer())
            if not ok:
                raise self.error(
                    f"{w}.{key}", f"{quote(v)}{unit if _is_number(v) else ''} is not valid; {parameter} search values must be {allowed}"
                )
            bounds[key] = int(v) if scale.domain == "integer" else float(v)
        if not bounds["lower_bound"] < bounds["upper_bound"]:
            raise self.error(f"{w}.upper_bound", f"{bounds['upper_bound']:g} must be greater than lower_bound {bounds['lower_bound']:g}")
        tolerance = self.typed(d.get("tolerance", 0.05), f"{w}.tolerance", "number")
        if not 0 < tolerance < float("inf"):  # NaN and inf are refused here, naming this key
            raise self.error(f"{w}.tolerance", f"{tolerance:g} is not valid; must be a number > 0{unit}")
        fail = self.typed(d.get("ate_rmse_fail", 1.5), f"{w}.ate_rmse_fail", "number")
        if not 0 < fail < float("inf"):
            raise self.error(f"{w}.ate_rmse_fail", f"{fail:g} m is not valid; must be a number > 0 m")
        name = d.get("name") or f"{target}_{parameter.replace('.', '_')}"
        return BoundaryConfig(
            target_perturbation=target,
            parameter=parameter,
            lower_bound=bounds["lower_bound"],
            upper_bound=bounds["upper_bound"],
            enabled=self.typed(d.get("enabled", False), f"{w}.enabled", "bool"),
            name=self.safe_name(name, f"{w}.name"),
            module=owner,
            tolerance=tolerance,
            max_iters=self.search_trials(d.get("max_iters", 8), f"{w}.max_iters"),
            ate_rmse_fail=fail,
            fail_on_tracking_failure=self.typed(d.get("fail_on_tracking_failure", True), f"{w}.fail_on_tracking_failure", "bool"),
        )


# ------------------------------------------------------------------------------ building


def build_sequence(config: ExperimentConfig) -> Sequence:
    """The clean sequence the config names (a dataset error names the config and the key)."""
    ds = config.dataset
    options = dict(ds.options)
    if ds.sequence is not None:
        options["sequence"] = ds.sequence
    if ds.stereo:
        options["stereo"] = True
    try:
        return open_dataset(ds.type, ds.path, start=ds.start, max_frames=ds.max_frames, **options)
    except SalError as exc:  # cut: a dataset kind may quote a whole option
        raise ConfigError(config.source, "dataset", one_line(str(exc), 3 * QUOTE_CHARS)) from None


def build_module(pert: PerturbationConfig) -> Perturbation | None:
    """The module of one perturbation (``None`` for type none)."""
    from sal_modules.base import Composite
    from sal_modules.registry import module_class

    if pert.type == "none":
        return None
    if pert.type == "composite":
        return Composite([module_class(s.type)(**s.parameters) for s in pert.modules])
    return module_class(pert.type)(**pert.parameters)


def build_modules(config: ExperimentConfig) -> dict[str, Perturbation | None]:
    """The module of each enabled perturbation by name (``None``: the clean sequence)."""
    return {p.name: build_module(p) for p in config.enabled()}


def perturbed_sequences(config: ExperimentConfig, clean: Sequence) -> dict[str, Sequence]:
    """``baseline`` (the clean sequence) first, then each enabled perturbation by name: lazily
    perturbed with the experiment's seed and named ``<clean name>+<perturbation name>``, so
    two perturbations of one module (fog, fog_heavy) stay apart in every record (type none:
    the clean sequence under that name). A module that cannot apply to this sequence (no depth
    for fog) is a ``ConfigError`` naming the perturbation."""
    from sal_modules import perturb

    sequences = {BASELINE: clean}
    for index, pert in enumerate(config.perturbations):
        if not pert.enabled:
            continue
        module = build_module(pert)
        if module is None:
            sequences[pert.name] = clean
            continue
        try:
            sequences[pert.name] = perturb(clean, module, seed=config.experiment.seed).replace(name=f"{clean.name}+{pert.name}")
        except SalError as exc:
            raise ConfigError(config.source, f"perturbations[{index}]", str(exc)) from None
    return sequences
