"""The boundary workflow (``sal boundary``): the failure boundary of a config's
``robustness_boundary`` block, found with the same boundary search the pytest plugin runs.

The block names a perturbation, one of its searchable parameters and a range
``lower_bound .. upper_bound`` (the parameter's unit). The requirement judged at each trial is

* ``ate_rmse < ate_rmse_fail``, and
* when ``fail_on_tracking_failure`` is true (the default), also ``tracking_rate >= 0.5``
  (the system lost track on more than half of the frames: a tracking failure).

The envelope's edge is the *mild* end of the range (``upper_bound`` for a parameter that gets
worse when lower, such as ``fog.visibility_m``; ``lower_bound`` otherwise), so the first trial
decides whether the system passes there at all; the search then brackets the failure point
towards the severe end and bisects it down to ``tolerance`` or ``max_trials`` trials. Trials are
kept in the content cache, so searching again costs no SLAM run.

``prepare_boundary_search`` sets a search up (nothing runs); ``run_boundary_search`` runs it
and writes ``boundary_summary.json`` (``pytest_sal.experiment.boundary_summary``) and the plot
under ``<output_dir>/robustness_boundary/<system>/<boundary name>/``, beside the previous ones,
replacing them together once both are complete.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pytest_sal.experiment.boundary_summary import boundary_summary_data
from pytest_sal.experiment.config import ConfigError, build_sequence
from pytest_sal.experiment.schema import BoundaryConfig, ExperimentConfig, build_module
from sal_adapters.common.atomic import Replacement
from sal_adapters.common.textfiles import atomic_write_text

if TYPE_CHECKING:  # numpy, OpenCV and the modules load when a search runs, not for `sal --help`
    from pytest_sal.engine.execution.executor import Executor
    from pytest_sal.engine.outcomes.outcome import Outcome, Trial
    from pytest_sal.engine.search.requirement_search import Search
    from pytest_sal.store.content_cache import ContentCache
    from sal_modules.params import ParamRef
    from sal_wrappers.base import SlamSystem

__all__ = [
    "PLOT_FILE",
    "SUMMARY_FILE",
    "TRACKING_FAIL_RATE",
    "BoundaryResult",
    "BoundarySearch",
    "boundary_parameter",
    "enabled_boundary",
    "linear_sweep_trials",
    "prepare_boundary_search",
    "run_boundary_search",
]

#: ``fail_on_tracking_failure``: a trial fails when fewer than this share of frames is tracked.
TRACKING_FAIL_RATE = 0.5
#: the files of one search, in its folder
SUMMARY_FILE = "boundary_summary.json"
PLOT_FILE = "boundary_plot.png"


def linear_sweep_trials(lower: float, upper: float, tolerance: float) -> int:
    """Trials of a linear sweep from ``lower`` to ``upper`` in steps of ``tolerance``."""
    return math.ceil((upper - lower) / tolerance - 1e-9) + 1


def enabled_boundary(config: ExperimentConfig) -> BoundaryConfig:
    """The config's ``robustness_boundary`` block; a ``ConfigError`` when it has none or it is disabled."""
    rb = config.robustness_boundary
    if rb is None:
        raise ConfigError(
            config.source, "robustness_boundary", "the config has no robustness_boundary block; sal boundary needs one (with enabled: true)"
        )
    if not rb.enabled:
        raise ConfigError(
            config.source, "robustness_boundary.enabled", "the robustness_boundary block is disabled; set enabled: true to search it"
        )
    return rb


def boundary_parameter(config: ExperimentConfig, block: BoundaryConfig) -> ParamRef:
    """The parameter ``block`` searches, on its target perturbation's module (a composite's by
    its address, ``fog.visibility_m``)."""
    module = build_module(config.perturbation(block.target_perturbation))
    assert module is not None  # the config validation refuses type none
    return module.ref(block.parameter)


@dataclass
class BoundarySearch:
    """A boundary search set up, not run.

    Attributes:
        config: the experiment config; ``block`` its ``robustness_boundary`` block.
        search: what is searched (the clean sequence, the parameter, the system, the
            requirement each trial is judged by, the seed, runs and timeout), for ``run_search``.
        folder: where the summary, the plot and the runs' files go.
        max_runs: the most runs per trial (``RunPolicy``: above 1, the system is noisy).
        cache: the trial cache, or ``None``.
    """

    config: ExperimentConfig
    block: BoundaryConfig
    search: Search
    folder: Path
    max_runs: int
    cache: ContentCache | None

    @property
    def sweep_trials(self) -> int:
        """Trials a linear sweep of the range at the tolerance step would need."""
        return linear_sweep_trials(self.block.lower_bound, self.block.upper_bound, self.block.tolerance_step)


@dataclass(frozen=True)
class BoundaryResult:
    """What ``run_boundary_search`` found and wrote: the ``outcome``, the ``summary`` written
    to ``summary_path``, and ``plot_path`` (``None`` when no plot was drawn)."""

    outcome: Outcome
    summary: dict[str, Any]
    summary_path: Path
    plot_path: Path | None


def prepare_boundary_search(
    config: ExperimentConfig,
    system: SlamSystem,
    *,
    runs: int | None = None,
    timeout: float | None = 600.0,
    cache_dir: Path | None = None,
    use_cache: bool = True,
) -> BoundarySearch:
    """Set up the search of the config's enabled ``robustness_boundary`` block with ``system``
    (``runs``: the most runs per trial, ``None``: 1 for a deterministic system, else
    ``NOISY_RUNS``; ``timeout``: seconds per run; the trial cache at ``cache_dir``, default
    ``.sal/cache``, unless ``use_cache`` is false)."""
    from pytest_sal.analysis.kitti_segments import KITTI_SEGMENTS_M
    from pytest_sal.engine.execution.trial_runner import RunPolicy
    from pytest_sal.engine.requirements import Requirement, ate_rmse, tracking_rate
    from pytest_sal.engine.search.requirement_search import Search
    from pytest_sal.store.content_cache import command_cache

    rb = enabled_boundary(config)
    ref = boundary_parameter(config, rb)
    mild = rb.upper_bound if ref.param.worse == "lower" else rb.lower_bound
    envelope = ref >= mild if ref.param.worse == "lower" else ref <= mild
    criteria = [ate_rmse < rb.ate_rmse_fail]
    if rb.fail_on_tracking_failure:
        criteria.append(tracking_rate >= TRACKING_FAIL_RATE)
    requirement = Requirement.build(
        [*criteria, envelope],
        tolerance=rb.tolerance,
        max_trials=rb.max_trials,
        search_range=(rb.lower_bound, rb.upper_bound),
        reliability=rb.reliability,
        confidence=rb.confidence,
        max_runs=rb.max_runs,
    )
    folder = config.output_dir() / "robustness_boundary" / system.name / rb.name
    search = Search(
        build_sequence(config),
        ref,
        system,
        requirement,
        f"sal boundary {config.experiment.name}/{rb.name}",
        runs=runs,
        seed=config.experiment.seed,
        timeout=timeout,
        workdir=folder / "runs",
        kitti_segments=config.evaluation.kitti_segments_m or KITTI_SEGMENTS_M,
    )
    cache = command_cache(cache_dir) if use_cache else None
    return BoundarySearch(config, rb, search, folder, RunPolicy.for_system(system, runs).max_runs, cache)


def run_boundary_search(
    search: BoundarySearch,
    *,
    on_trial: Callable[[Trial], None] | None = None,
    plot: Callable[[Outcome, Path], object] | None = None,
    executor: Executor | None = None,
) -> BoundaryResult:
    """Run ``search`` (``on_trial``: called with each trial as it ends, again when runs are
    added to it) and write its summary and, with ``plot`` (a function drawing
    an outcome as a PNG at a path), ``boundary_plot.png``; both replace the previous ones together.
    ``executor``: where the runs happen (``None``: here, one at a time)."""
    from pytest_sal.engine.search.requirement_search import run_search

    outcome = run_search(search.search, search.cache, executor, on_trial)
    summary_path = search.folder / SUMMARY_FILE
    plot_path = search.folder / PLOT_FILE if plot is not None else None
    with Replacement() as outputs:  # the plot and the summary replace the previous search's together
        staging = outputs.entries(search.folder)
        if plot is not None:
            plot(outcome, staging / PLOT_FILE)
        summary = _summary(search, outcome, plot_path)
        atomic_write_text(staging / SUMMARY_FILE, json.dumps(summary, indent=2) + "\n")
    return BoundaryResult(outcome, summary, summary_path, plot_path)


def _summary(search: BoundarySearch, outcome: Outcome, plot_path: Path | None) -> dict[str, Any]:
    """``boundary_summary.json``: the outcome, and apart from it what only the experiment knows."""
    config, rb = search.config, search.block
    experiment = {
        "config": config.source,
        "name": config.experiment.name,
        "boundary": rb.name,
        "target_perturbation": rb.target_perturbation,
        "module": config.perturbation(rb.target_perturbation).type,
        "lower_bound": rb.lower_bound,
        "upper_bound": rb.upper_bound,
        "tolerance": rb.tolerance,
        "max_trials": rb.max_trials,
        "reliability": rb.reliability,
        "confidence": rb.confidence,
        "max_runs": rb.max_runs,
        "linear_sweep_trials": search.sweep_trials,
        "plot": None if plot_path is None else str(plot_path),
    }
    return boundary_summary_data(outcome, experiment)
