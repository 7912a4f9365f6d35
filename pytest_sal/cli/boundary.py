"""``sal boundary CONFIG --slam NAME``: the failure boundary of the config's
``robustness_boundary`` block, found with the same boundary search the pytest plugin runs.

The block names a perturbation, one of its searchable parameters and a range
``lower_bound .. upper_bound`` (search units). The requirement judged at each trial is

* ``ate_rmse < ate_rmse_fail``, and
* when ``fail_on_tracking_failure`` is true (the default), also ``tracking_rate >= 0.5``
  (the system lost track on more than half of the frames: a tracking failure).

The envelope's edge is the *mild* end of the range (``upper_bound`` for a parameter that gets
worse when lower, such as ``fog.visibility_m``; ``lower_bound`` otherwise), so the first trial
decides whether the system passes there at all; the search then brackets the failure point
towards the severe end and bisects it down to ``tolerance`` or ``max_iters`` trials. Trials are
kept in the content cache, so running the command again costs no SLAM run. The plot and the
summary are written beside the previous ones and replace them together when both are complete.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from pytest_sal.cli.arg_types import (
    add_cache_arguments,
    add_slam_arguments,
    parse_key_values,
)
from sal_adapters import SalError
from sal_adapters.atomic import Replacement
from sal_adapters.textfiles import atomic_write_text

if TYPE_CHECKING:
    from pytest_sal.engine.outcome import Outcome, Trial

__all__ = ["TRACKING_FAIL_RATE", "add_boundary_commands", "linear_sweep_trials", "run_boundary"]

#: ``fail_on_tracking_failure``: a trial fails when fewer than this share of frames is tracked.
TRACKING_FAIL_RATE = 0.5

EPILOG = """\
examples:
  sal boundary example_suites/configs/fog_rain_urban.yaml --slam reference_vo
  sal boundary exp.yaml --slam orbslam3 --slam-option features=2000 --runs 3 --cache-dir /tmp/sal-cache

The config needs an enabled robustness_boundary block (target_perturbation, parameter,
lower_bound, upper_bound, tolerance, max_iters, ate_rmse_fail, fail_on_tracking_failure).
A trial passes when ate_rmse < ate_rmse_fail and, with fail_on_tracking_failure (the default),
tracking_rate >= 0.5. The search starts at the mild end of the range and bisects the failure
point down to tolerance (or max_iters trials).

Writes <base_dir>/<name>/robustness_boundary/<slam>/<boundary name>/boundary_summary.json
(pass_value, fail_value, every trial with its metrics and verdict, termination, and the trials a
linear sweep at the tolerance step would have needed) and boundary_plot.png. Trials are cached
(default .sal/cache): a second run reads them back.
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
    add_slam_arguments(cmd, "the most runs per trial; runs vote until one verdict leads by 2, metrics are their median", default_runs=None)
    add_cache_arguments(cmd, "trial cache", no_cache="run every trial, read and store nothing in the cache")
    cmd.set_defaults(run=_run)


def linear_sweep_trials(lower: float, upper: float, tolerance: float) -> int:
    """Trials of a linear sweep from ``lower`` to ``upper`` in steps of ``tolerance``."""
    return math.ceil((upper - lower) / tolerance - 1e-9) + 1


def _progress_printer(unit: str, out: TextIO) -> Callable[[Trial], None]:
    """A ``TrialRunner.progress`` callback printing one line per trial as it finishes (again
    when a confirmation adds runs to it)."""
    count = 0

    def show(trial: Trial) -> None:
        nonlocal count
        count += 1
        print(f"  step {count:2d}  {_trial_line(trial, unit)}", file=out, flush=True)

    return show


def _trial_line(trial: Trial, unit: str) -> str:
    ate, rate = trial.metrics.get("ate_rmse"), trial.metrics.get("tracking_rate")
    ate_text = "-" if ate is None else f"{ate:.4g} m"
    rate_text = "-" if rate is None else f"{100 * rate:.0f}%"
    notes = [n for n, on in (("cached", trial.cached), (trial.votes(), len(trial.runs) > 1)) if on]
    note = f"  ({', '.join(notes)})" if notes else ""
    failed = f"  failed: {', '.join(trial.failed)}" if trial.failed else ""
    value = f"{trial.value:g}{' ' + unit if unit else ''}"
    return f"{value:>12s}  {'PASS' if trial.passed else 'FAIL'}  ATE {ate_text:>10s}  tracked {rate_text:>4s}{failed}{note}"


def _create_system(name: str, options: dict[str, Any]) -> Any:
    from sal_wrappers import create

    try:
        return create(name, **options)
    except TypeError as exc:  # an option the system's constructor does not take
        raise SalError(f"--slam-option: SLAM system {name!r} rejects the options {', '.join(options) or '(none)'}: {exc}") from None


def run_boundary(
    config_path: Path,
    slam: str,
    *,
    slam_options: dict[str, Any] | None = None,
    runs: int | None = None,
    timeout: float | None = 600.0,
    cache_dir: Path | None = None,
    use_cache: bool = True,
    out: TextIO | None = None,
) -> dict[str, Any]:
    """Run the boundary search of the config's ``robustness_boundary`` block with the SLAM
    system ``slam``; write and return ``boundary_summary.json``'s content."""
    from pytest_sal.analysis.kitti_metrics import KITTI_SEGMENTS_M
    from pytest_sal.engine.requirement_runner import SearchSettings, search_outcome
    from pytest_sal.engine.requirements import Requirement, ate_rmse, tracking_rate
    from pytest_sal.engine.trial_runner import TrialRunner
    from pytest_sal.experiment.config import (
        ConfigError,
        build_module,
        build_sequence,
        load_config,
    )
    from pytest_sal.report.metric_plot import metric_plot
    from pytest_sal.store.trial_cache import command_cache

    out = out or sys.stdout
    config = load_config(config_path)
    rb = config.robustness_boundary
    if rb is None:
        raise ConfigError(
            config.source, "robustness_boundary", "the config has no robustness_boundary block; sal boundary needs one (with enabled: true)"
        )
    if not rb.enabled:
        raise ConfigError(
            config.source, "robustness_boundary.enabled", "the robustness_boundary block is disabled; set enabled: true to search it"
        )
    system = _create_system(slam, slam_options or {})  # an unknown system fails before any work
    pert = next(p for p in config.perturbations if p.name == rb.target_perturbation)
    module = build_module(pert)
    assert module is not None  # the config validation refuses type none
    ref = module.ref(rb.parameter)  # a Composite takes the address (fog.visibility_m)
    worse = ref.param.worse
    mild = rb.upper_bound if worse == "lower" else rb.lower_bound
    envelope = ref >= mild if worse == "lower" else ref <= mild
    criteria = [ate_rmse < rb.ate_rmse_fail]
    if rb.fail_on_tracking_failure:
        criteria.append(tracking_rate >= TRACKING_FAIL_RATE)
    requirement = Requirement.build(
        [*criteria, envelope], tolerance=rb.tolerance, max_trials=rb.max_iters, search_range=(rb.lower_bound, rb.upper_bound)
    )
    clean = build_sequence(config)
    folder = config.output_dir() / "robustness_boundary" / system.name / rb.name
    cache = command_cache(cache_dir) if use_cache else None
    runner = TrialRunner(
        clean,
        ref,
        system,
        requirement,
        runs=runs,
        seed=config.experiment.seed,
        cache=cache,
        workdir=folder / "runs",
        timeout=timeout,
        progress=_progress_printer(ref.unit, out),
        kitti_segments=config.evaluation.kitti_segments_m or KITTI_SEGMENTS_M,
    )
    unit = ref.unit
    unit_text = f" {unit}" if unit else ""
    sweep = linear_sweep_trials(rb.lower_bound, rb.upper_bound, rb.tolerance)
    print(
        f"boundary    {rb.name}: {ref.label} in {rb.lower_bound:g} .. {rb.upper_bound:g}{unit_text} (gets worse {worse}), "
        f"tolerance {rb.tolerance:g}{unit_text}, max_iters {rb.max_iters}",
        file=out,
    )
    print(
        f"system      {system.name} {json.dumps(system.options(), sort_keys=True)}, up to {runner.policy.max_runs} run(s) per trial",
        file=out,
    )
    print(f"dataset     {config.dataset.type} {clean.name}: {len(clean)} frames, {clean.sensor}", file=out)
    print(f"requirement {requirement}", file=out)
    test_id = f"sal boundary {config.experiment.name}/{rb.name}"
    outcome = search_outcome(runner, requirement, SearchSettings(), test_id)
    plot, path = folder / "boundary_plot.png", folder / "boundary_summary.json"
    with Replacement() as outputs:  # the plot and the summary replace the previous search's together
        staging = outputs.entries(folder)
        metric_plot(outcome, staging / plot.name)
        summary = _summary(outcome, config, rb, ref, pert.type, sweep, plot)
        atomic_write_text(staging / path.name, json.dumps(summary, indent=2) + "\n")
    cached = outcome.cached_trials
    print(
        f"boundary    {ref.label} {outcome.boundary.text()} ({outcome.termination}); "
        f"{len(outcome.trials)} trials, {outcome.runs} runs ({cached} trials cached) vs {sweep} for a linear sweep at {rb.tolerance:g}{unit_text} steps; "
        f"{outcome.confidence()}",
        file=out,
    )
    print(f"wrote {path}\nwrote {plot}", file=out)
    return summary


def _summary(outcome: Outcome, config: Any, rb: Any, ref: Any, module_type: str, sweep: int, plot: Path) -> dict[str, Any]:
    return {
        "experiment": config.experiment.name,
        "boundary": rb.name,
        "target_perturbation": rb.target_perturbation,
        "module": module_type,
        "parameter": ref.label,
        "unit": ref.unit,
        "worse": outcome.worse,
        "lower_bound": rb.lower_bound,
        "upper_bound": rb.upper_bound,
        "tolerance": rb.tolerance,
        "max_iters": rb.max_iters,
        "requirement": outcome.requirement,
        "system": outcome.system,
        "system_options": outcome.system_options,
        "dataset": outcome.dataset,
        "dataset_fingerprint": outcome.dataset_fingerprint,
        "seed": outcome.seed,
        "edge": outcome.edge,
        "edge_verdict": outcome.verdict,
        "pass_value": outcome.boundary.pass_value,
        "fail_value": outcome.boundary.fail_value,
        "boundary_text": outcome.boundary.text(),
        "termination": outcome.termination,
        "contradictions": outcome.contradictions,
        "trials_used": len(outcome.trials),
        "runs_used": outcome.runs,
        "confidence": outcome.confidence(),
        "linear_sweep_trials": sweep,
        "trials": [
            {
                "value": t.value,
                "verdict": "pass" if t.passed else "fail",
                "metrics": t.metrics,
                "failed": t.failed,
                "cached": t.cached,
                "runs": len(t.runs),
                "votes": t.votes(),
                "wall_time_s": round(t.wall_time_s, 4),
            }
            for t in outcome.trials
        ],
        "plot": str(plot),
    }


def _run(args: argparse.Namespace) -> int:
    run_boundary(
        args.config,
        args.slam,
        slam_options=parse_key_values(args.slam_option, "--slam-option"),
        runs=args.runs,
        timeout=args.timeout,
        cache_dir=args.cache_dir,
        use_cache=not args.no_cache,
    )
    return 0
