"""``sal boundary CONFIG --system NAME``: the failure boundary of the config's
``robustness_boundary`` block (``pytest_sal.experiment.boundary``), with one line per trial as
it ends (``step N`` and ``pytest_sal.report.formatting.trial_line``) and the boundary found
against the trials a linear sweep would need."""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pytest_sal.cli.arg_types import add_cache_arguments, add_executor_arguments, add_slam_arguments, executor_from_args, parse_key_values
from pytest_sal.experiment.boundary import (
    BoundaryResult,
    BoundarySearch,
    enabled_boundary,
    prepare_boundary_search,
    run_boundary_search,
)
from pytest_sal.experiment.config import load_config
from sal_adapters import SalError

if TYPE_CHECKING:
    from pytest_sal.engine.outcomes.outcome import Trial
    from sal_wrappers.base import SlamSystem

__all__ = ["add_boundary_commands"]

EPILOG = """\
examples:
  sal boundary example_suites/configs/fog_rain_urban.yaml --system reference_vo
  sal boundary exp.yaml --system orbslam3 --system-option features=2000 --runs 3 --cache-dir /tmp/sal-cache
  sal boundary exp.yaml --system orbslam3 --executor ray --ray-address auto   # runs as Ray tasks, several at once

The config needs an enabled robustness_boundary block (target_perturbation, parameter,
lower_bound, upper_bound, tolerance, max_trials, ate_rmse_fail, fail_on_tracking_failure;
max_iters, the old name of max_trials, is read with a deprecation warning). tolerance is a
number in the parameter's unit or a percent of the bracket's larger end, such as "10%".
A trial passes when ate_rmse < ate_rmse_fail and, with fail_on_tracking_failure (the default),
tracking_rate >= 0.5. The search starts at the mild end of the range and bisects the failure
point down to tolerance (or max_trials trials).

Writes <base_dir>/<name>/robustness_boundary/<slam>/<boundary name>/boundary_summary.json
(the search's outcome: pass and fail value, every trial with its runs, metrics and verdict,
termination; and the experiment's block: range, tolerance, the trials a linear sweep at the
tolerance step would have needed) and boundary_plot.png. Trials are cached (default
.sal/cache): a second run reads them back.
"""


def add_boundary_commands(commands: argparse._SubParsersAction) -> None:
    """Add ``boundary`` to the ``sal`` subcommands."""
    cmd = commands.add_parser(
        "boundary",
        help="search the failure boundary of the config's robustness_boundary block for one SLAM system",
        description="Search the failure point of the robustness_boundary parameter between lower_bound and\n"
        "upper_bound: perturb, run the SLAM system, score it and bisect, as the pytest plugin does.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    cmd.add_argument("config", type=Path, metavar="CONFIG", help="experiment YAML with an enabled robustness_boundary block")
    add_slam_arguments(
        cmd, "the most runs per trial; above 1 the system is searched as a noisy one (its chance to hold)", default_runs=None
    )
    add_cache_arguments(cmd, "cache of runs", no_cache="run every trial, read and store nothing in the cache")
    add_executor_arguments(cmd)
    cmd.set_defaults(run=_run)


def _run(args: argparse.Namespace) -> int:
    from pytest_sal.report.metric_plot import metric_plot

    config = load_config(args.config)
    enabled_boundary(config)  # a missing or disabled block fails before the system is made
    system = _create_system(args.slam, parse_key_values(args.slam_option, "--system-option"))  # an unknown system fails before any work
    search = prepare_boundary_search(
        config, system, runs=args.runs, timeout=args.timeout, cache_dir=args.cache_dir, use_cache=not args.no_cache
    )
    _print_setup(search)
    with executor_from_args(args) as executor:
        result = run_boundary_search(search, on_trial=_step_printer(search), plot=metric_plot, executor=executor)
    _print_result(search, result)
    return 0


def _create_system(name: str, options: dict[str, Any]) -> SlamSystem:
    from sal_wrappers import create

    try:
        return create(name, **options)
    except TypeError as exc:  # an option the system's constructor does not take
        raise SalError(f"--system-option: SLAM system {name!r} rejects the options {', '.join(options) or '(none)'}: {exc}") from None


def _unit_text(search: BoundarySearch) -> str:
    return f" {search.search.ref.unit}" if search.search.ref.unit else ""


def _print_setup(search: BoundarySearch) -> None:
    """The range searched, the system, the dataset and the requirement."""
    rb, ref, system, clean = search.block, search.search.ref, search.search.system, search.search.dataset
    unit = _unit_text(search)
    print(
        f"boundary    {rb.name}: {ref.label} in {rb.lower_bound:g} .. {rb.upper_bound:g}{unit} (gets worse {ref.param.worse}), "
        f"tolerance {rb.tolerance_text(ref.unit)}, max_trials {rb.max_trials}"
    )
    print(f"system      {system.name} {json.dumps(system.options(), sort_keys=True)}, up to {search.max_runs} run(s) per trial")
    print(f"dataset     {search.config.dataset.type} {clean.name}: {len(clean)} frames, {clean.sensor}")
    print(f"requirement {search.search.requirement}")


def _step_printer(search: BoundarySearch) -> Callable[[Trial], None]:
    """A ``TrialRunner.progress`` callback printing ``step N`` and the trial's line as each
    trial ends (again when runs are added to it)."""
    from pytest_sal.report.formatting import trial_line
    from pytest_sal.report.outcome_report import trial_metric_names

    ref = search.search.ref
    metrics = trial_metric_names(search.search.requirement.criteria_rows())
    count = 0

    def show(trial: Trial) -> None:
        nonlocal count
        count += 1
        print(f"  step {count:2d}  {trial_line(trial, ref.label, ref.unit, metrics)}", flush=True)

    return show


def _print_result(search: BoundarySearch, result: BoundaryResult) -> None:
    """The boundary found, the trials and runs it took against a linear sweep, the files written."""
    outcome = result.outcome
    print(
        f"boundary    {search.search.ref.label} {outcome.boundary.text()} ({outcome.termination}); "
        f"{len(outcome.trials)} trials, {outcome.runs} runs ({outcome.cached_trials} trials cached) vs {search.sweep_trials} "
        f"for a linear sweep at {search.block.tolerance_step:g}{_unit_text(search)} steps; {outcome.confidence()}"
    )
    print(f"wrote {result.summary_path}" + (f"\nwrote {result.plot_path}" if result.plot_path is not None else ""))
