"""Experiment configs: the SAL YAML schema (``pytest_sal.experiment.schema``), read and
validated up front (``sal perturb``, ``sal evaluate``, ``sal boundary`` and ``sal features`` read
them), and the sequences and modules a config describes, built.

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

import os
from typing import TYPE_CHECKING, Any

from pytest_sal.experiment.boundary_block import read_boundary
from pytest_sal.experiment.schema import (
    BASELINE,
    COMPOSITE_KEYS,
    DATASET_KEYS,
    EVALUATION_KEYS,
    EXPERIMENT_KEYS,
    MAX_INT,
    MAX_KITTI_SEGMENTS,
    MAX_PERTURBATIONS,
    MAX_RENDERED_FRAMES,
    OUTPUT_KEYS,
    PERTURBATION_KEYS,
    STEP_KEYS,
    TOP_KEYS,
    DatasetConfig,
    EvaluationConfig,
    ExperimentConfig,
    ExperimentInfo,
    OutputConfig,
    PerturbationConfig,
    StepConfig,
    build_module,
)
from pytest_sal.experiment.value_checks import ValueChecks, is_finite, is_number, option_hints
from pytest_sal.experiment.yaml_loader import PATH_CHARS, ConfigError, key_text, read_config_text, read_yaml
from sal_adapters.common.bounded_yaml import QUOTE_CHARS, one_line, quote
from sal_adapters.common.errors import SalError
from sal_adapters.common.suggest import suggestion
from sal_adapters.datasets import DATASETS, open_dataset
from sal_modules.errors import ParameterError

if TYPE_CHECKING:  # numpy and the modules load when a config is read, not for `sal --help`
    from sal_adapters.sequence import Sequence
    from sal_modules.base import Perturbation

__all__ = ["ConfigError", "build_modules", "build_sequence", "load_config", "parse_config", "perturbed_sequences"]


# ------------------------------------------------------------------------------ loading


def load_config(path: str | os.PathLike[str]) -> ExperimentConfig:
    """Read and validate the experiment config at ``path`` (nothing is created; a file that is
    not regular or over the size limit is refused before it is read)."""
    return parse_config(read_config_text(path), str(path))


def parse_config(text: str, source: str = "<config>") -> ExperimentConfig:
    """Validate the YAML ``text`` (``source`` names it in errors) within the limits of
    ``CONFIG_YAML`` (``pytest_sal.experiment.yaml_loader``) and the schema's."""
    data = read_yaml(text, source)
    return _Parser(source).config(data, text)


class _Parser(ValueChecks):
    """Reads each section of a config into its dataclass (``robustness_boundary``:
    ``pytest_sal.experiment.boundary_block``)."""

    def config(self, data: Any, text: str) -> ExperimentConfig:
        if data is None:
            raise self.error("", "the config is empty; it needs the sections experiment, dataset, perturbations, output")
        top = self.mapping(data, "", TOP_KEYS, required=("experiment", "dataset"))
        experiment = self.experiment(top["experiment"])
        dataset = self.dataset(top["dataset"])
        perturbations = self.perturbations(top.get("perturbations"))
        output = self.output(top.get("output"))
        boundary = read_boundary(self, top.get("robustness_boundary"), perturbations)
        evaluation = self.evaluation(top.get("evaluation"))
        return ExperimentConfig(self.source, experiment, dataset, perturbations, output, boundary, text, evaluation)

    def experiment(self, value: Any) -> ExperimentInfo:
        d = self.mapping(value, "experiment", EXPERIMENT_KEYS, required=("name",))
        version = d.get("version", "1.0.0")
        if is_number(version):
            version = str(version)
        return ExperimentInfo(
            name=self.safe_name(d["name"], "experiment.name"),
            description=self.typed(d.get("description", ""), "experiment.description", "str"),
            version=self.typed(version, "experiment.version", "str"),
            seed=self.typed(d.get("seed", 0), "experiment.seed", "int", minimum=0, maximum=MAX_INT),
        )

    def dataset(self, value: Any) -> DatasetConfig:
        d = self.mapping(value, "dataset", DATASET_KEYS, required=("type",))
        kind = self.typed(d["type"], "dataset.type", "str")
        dataset_kind = self.registered(DATASETS, kind, "dataset.type")
        allowed = dataset_kind.option_names()
        folder = None if d.get("path") is None else self.folder(d["path"], "dataset.path")
        if folder is not None:
            try:
                usable = folder.is_dir() or (dataset_kind.opens_files and folder.is_file())
                found = "" if usable else "is not a folder" if folder.exists() else "does not exist"
            except OSError as exc:  # stat refused (a folder above is unreadable)
                found = f"cannot be read ({exc.strerror})"
            if found:
                what = "the dataset file or folder" if dataset_kind.opens_files else "the dataset folder"
                raise self.error("dataset.path", f"{quote(str(folder), PATH_CHARS)} {found}; give {what}")
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
        hints = option_hints(dataset_kind)
        for key, value in options.items():
            self.option(value, f"dataset.options.{key}", hints.get(key))
        frames = options.get("frames")
        if is_number(frames) and not 1 <= frames <= MAX_RENDERED_FRAMES:
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
            start=self.typed(d.get("start", 0), "dataset.start", "int", minimum=0, maximum=MAX_INT),
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
            d = self.mapping(item, where, PERTURBATION_KEYS, required=("name", "type"))
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
                shown = f"{quote(value)}{' ' + spec.unit if spec.unit and is_number(value) else ''}"
                raise self.error(f"{where}.parameters.{key}", f"{shown} is not valid; {key} must be {spec.allowed()}") from None
            if spec.domain == "text":  # a file (night's ONNX model)
                self.path(value, f"{where}.parameters.{key}", optional=spec.optional)
        try:
            return cls(**params)
        except ParameterError as exc:
            raise self.error(f"{where}.parameters", str(exc)) from None

    def composite(self, params: dict[str, Any], where: str) -> tuple[StepConfig, ...]:
        d = self.mapping(params, where, COMPOSITE_KEYS, required=("modules",))
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
            s = self.mapping(item, at, STEP_KEYS, required=("type",))
            kind = self.typed(s["type"], f"{at}.type", "str")
            if kind in ("none", "composite"):
                raise self.error(f"{at}.type", f"{quote(kind)} cannot be a step of a composite; use a perturbation module")
            step_params = self.typed(s.get("parameters") or {}, f"{at}.parameters", "dict")
            self.module(kind, step_params, at)
            name = self.typed(s.get("name"), f"{at}.name", "str", optional=True)
            steps.append(StepConfig(kind, dict(step_params), name))
        return tuple(steps)

    def output(self, value: Any) -> OutputConfig:
        d = self.mapping(value if value is not None else {}, "output", OUTPUT_KEYS)
        return OutputConfig(
            base_dir=self.folder(d.get("base_dir", "results"), "output.base_dir"),
            create_timestamp_dir=self.typed(d.get("create_timestamp_dir", False), "output.create_timestamp_dir", "bool"),
        )

    def evaluation(self, value: Any) -> EvaluationConfig:
        d = self.mapping(value if value is not None else {}, "evaluation", EVALUATION_KEYS)
        segments = d.get("kitti_segments_m")
        if segments is None:
            return EvaluationConfig()
        where = "evaluation.kitti_segments_m"
        if not isinstance(segments, list) or not segments or not all(is_finite(v) and v > 0 for v in segments):
            raise self.error(where, f"{quote(segments)} is not valid; must be a list of segment lengths > 0 m, e.g. [10, 20, 30, 40]")
        if len(segments) > MAX_KITTI_SEGMENTS:
            raise self.error(where, f"{len(segments)} lengths; the limit is {MAX_KITTI_SEGMENTS}")
        return EvaluationConfig(tuple(sorted({float(v) for v in segments})))


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
