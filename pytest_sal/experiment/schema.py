"""The SAL experiment schema: what a validated config holds (one frozen dataclass per section:
``experiment``, ``dataset``, ``perturbations`` with ``composite`` steps, ``output``,
``robustness_boundary``, ``evaluation``), the keys each section allows, the schema's limits,
and ``build_module``, the perturbation module one ``perturbations`` entry describes.

``pytest_sal.experiment.config`` reads YAML into these (``load_config``); nothing here reads
files or checks values.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the modules load when a config is read, not for `sal --help`
    from sal_modules.base import Perturbation

__all__ = [
    "BASELINE",
    "BOUNDARY_KEYS",
    "COMPOSITE_KEYS",
    "DATASET_KEYS",
    "EVALUATION_KEYS",
    "EXPERIMENT_KEYS",
    "MAX_FRAMES",
    "MAX_INT",
    "MAX_KITTI_SEGMENTS",
    "MAX_NAME_BYTES",
    "MAX_PATH_BYTES",
    "MAX_PERTURBATIONS",
    "MAX_RENDERED_FRAMES",
    "MAX_SEARCH_RUNS",
    "MAX_SEARCH_TRIALS",
    "OUTPUT_KEYS",
    "PERTURBATION_KEYS",
    "STEP_KEYS",
    "TOP_KEYS",
    "BoundaryConfig",
    "DatasetConfig",
    "EvaluationConfig",
    "ExperimentConfig",
    "ExperimentInfo",
    "OutputConfig",
    "PerturbationConfig",
    "StepConfig",
    "build_module",
]

#: name of the clean sequence in every output tree (a perturbation of another type may not take it)
BASELINE = "baseline"


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
    """The ``robustness_boundary`` block: bounds in the parameter's unit, ``tolerance`` a number
    in that unit or a percent ``"N%"`` of the bracket's larger end (``pytest_sal.engine.tolerance``),
    the trial budget ``max_trials`` (YAML ``max_iters`` is its old name), ``ate_rmse_fail`` in m;
    ``module`` is the module owning ``parameter`` in the target; a noisy system's
    ``reliability``, ``confidence`` and run budget ``max_runs`` (as ``sal.require``'s)."""

    target_perturbation: str
    parameter: str
    lower_bound: float
    upper_bound: float
    enabled: bool = False
    name: str = ""
    module: str = ""
    tolerance: float | str = "10%"
    max_trials: int = 8
    ate_rmse_fail: float = 1.5
    fail_on_tracking_failure: bool = True
    reliability: float = 0.8
    confidence: float = 0.9
    max_runs: int = 30

    @property
    def tolerance_step(self) -> float:
        """The widest bracket ``tolerance`` allows in ``lower_bound .. upper_bound`` (the unit)."""
        from pytest_sal.engine.tolerance import parse_tolerance

        return parse_tolerance(self.tolerance).step(self.lower_bound, self.upper_bound)

    def tolerance_text(self, unit: str = "") -> str:
        """``5 m`` or ``10% of the bracket's larger end``."""
        from pytest_sal.engine.tolerance import parse_tolerance

        return parse_tolerance(self.tolerance).text(unit)


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

    def perturbation(self, name: str) -> PerturbationConfig:
        """The perturbation called ``name`` (``KeyError`` when none is)."""
        found = next((p for p in self.perturbations if p.name == name), None)
        if found is None:
            raise KeyError(name)
        return found


# ------------------------------------------------------------------------------ keys and limits

TOP_KEYS = ("experiment", "dataset", "perturbations", "output", "robustness_boundary", "evaluation")
EVALUATION_KEYS = ("kitti_segments_m",)
EXPERIMENT_KEYS = ("name", "description", "version", "seed")
DATASET_KEYS = ("type", "path", "sequence", "max_frames", "start", "stereo", "options")
PERTURBATION_KEYS = ("name", "type", "enabled", "parameters")
STEP_KEYS = ("name", "type", "parameters")
COMPOSITE_KEYS = ("mode", "modules")
OUTPUT_KEYS = ("base_dir", "create_timestamp_dir")
BOUNDARY_KEYS = (
    "enabled",
    "name",
    "target_perturbation",
    "module",
    "parameter",
    "lower_bound",
    "upper_bound",
    "tolerance",
    "max_trials",
    "max_iters",  # the old name of max_trials, read with a SalDeprecationWarning
    "ate_rmse_fail",
    "fail_on_tracking_failure",
    "reliability",
    "confidence",
    "max_runs",
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
#: The most runs a noisy system's boundary search may make (``robustness_boundary.max_runs``).
MAX_SEARCH_RUNS = 10_000
#: The largest integer a config may give either way (int64, what numpy and every JSON reader
#: keep exactly): ``experiment.seed`` is in 0 .. MAX_INT.
MAX_INT = 2**63 - 1
#: Segment lengths of the KITTI metrics (the devkit has 8).
MAX_KITTI_SEGMENTS = 100


def build_module(pert: PerturbationConfig) -> Perturbation | None:
    """The module of one perturbation (``None`` for type none)."""
    from sal_modules.base import Composite
    from sal_modules.registry import module_class

    if pert.type == "none":
        return None
    if pert.type == "composite":
        return Composite([module_class(s.type)(**s.parameters) for s in pert.modules])
    return module_class(pert.type)(**pert.parameters)
