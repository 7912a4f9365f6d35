"""``sal perturb CONFIG``: validate an experiment config, print the plan, then write each enabled
perturbation's sequence in the dataset's own layout under ``<base_dir>/<name>/images/<perturbation>/``
(``pytest_sal.experiment.perturb``), through the cache, with progress bars and a timing table."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pytest_sal.cli.arg_types import add_cache_arguments
from pytest_sal.experiment.boundary import boundary_parameter
from pytest_sal.experiment.config import load_config
from pytest_sal.experiment.perturb import PerturbPlan, plan_perturbations, write_perturbations

if TYPE_CHECKING:  # numpy and the modules load when a command runs, not for `sal --help`
    from sal_modules.base import Perturbation

__all__ = ["add_experiment_commands"]


def _describe(module: Perturbation | None) -> str:
    from sal_modules.base import Composite

    if module is None:
        return "clean sequence"
    steps = module.steps if isinstance(module, Composite) else (module,)
    parts = []
    for step in steps:
        specs = step.parameters()
        values = ", ".join(f"{k}={_fmt(v)}{' ' + specs[k].unit if specs[k].unit and v is not None else ''}" for k, v in step.params.items())
        parts.append(f"{step.name}({values})")
    return " >> ".join(parts)


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if value is None:
        return "null"
    if isinstance(value, tuple):
        return "(" + ", ".join(_fmt(v) for v in value) + ")"
    return repr(value) if isinstance(value, str) else str(value)


def _print_plan(plan: PerturbPlan) -> None:
    """The experiment, the dataset, each perturbation with its module and folder, and the
    boundary block."""
    config, clean, root = plan.config, plan.clean, plan.root
    print(f"experiment  {config.experiment.name} (seed {config.experiment.seed})")
    print(f"dataset     {config.dataset.type} {clean.name}: {len(clean)} frames, {clean.sensor}, {clean.fps:.3g} Hz")
    print(f"output      {root}")
    width = _name_width(plan)
    for name, module in plan.modules.items():
        print(f"  {name:{width}s} {_describe(module)}\n  {'':{width}s} -> {root / 'images' / name}")
    disabled = [p.name for p in config.perturbations if not p.enabled]
    if disabled:
        print(f"  disabled: {', '.join(disabled)}")
    rb = config.robustness_boundary
    if rb is not None:
        state = "enabled" if rb.enabled else "disabled"
        scale = boundary_parameter(config, rb).param.search_space()
        unit = f" {scale.unit}" if scale.unit else ""
        print(
            f"boundary    {rb.name} ({state}): {rb.target_perturbation}.{rb.parameter} in {rb.lower_bound:g} .. {rb.upper_bound:g}{unit}, "
            f"tolerance {rb.tolerance_text(scale.unit)}, max_trials {rb.max_trials}, ate_rmse_fail {rb.ate_rmse_fail:g} m"
        )


def _print_timings(plan: PerturbPlan, results: dict[str, Any]) -> None:
    """One row per perturbation written: module, frames kept, ms per frame, seconds."""
    from sal_modules.base import Composite

    labels = {
        name: "none" if module is None else (module.label() if isinstance(module, Composite) else module.name)
        for name, module in plan.modules.items()
    }
    width, lw = _name_width(plan), max([len(v) for v in labels.values()] + [6])
    print(f"\n  {'perturbation':{width}s} {'module':{lw}s} {'kept':>9s} {'ms/frame':>9s} {'total s':>8s}")
    for name, r in results["perturbations"].items():
        per_frame = 1000 * r["seconds"] / max(1, r["frames_in"])
        note = " (cached)" if r["cached"] else ""
        print(
            f"  {name:{width}s} {labels[name]:{lw}s} {r['frames_kept']:>4d}/{r['frames_in']:<4d} {per_frame:9.1f} {r['seconds']:8.2f}{note}"
        )


def _name_width(plan: PerturbPlan) -> int:
    return max([len(n) for n in plan.modules] + [12])


EPILOG = """\
examples:
  sal perturb example_suites/configs/fog_rain_urban.yaml --dry-run
  sal perturb example_suites/configs/indoor_camera.yaml --cache-dir /tmp/sal-cache

Writes <base_dir>/<experiment.name>/images/<perturbation>/ in the dataset's own layout, plus
pipeline_results.json and a copy of the config. Perturbed sequences are kept in the content
cache (default .sal/cache), so a second run copies them.
"""


def add_experiment_commands(commands: argparse._SubParsersAction) -> None:
    """Add ``perturb`` to the ``sal`` subcommands."""
    cmd = commands.add_parser(
        "perturb",
        help="validate an experiment config and write each perturbed sequence",
        description="Validate the experiment config (every error names the key), then write each\n"
        "enabled perturbation's sequence under <base_dir>/<name>/images/<perturbation>/.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    cmd.add_argument("config", type=Path, metavar="CONFIG", help="experiment YAML")
    cmd.add_argument("--dry-run", action="store_true", help="validate and print the plan; write nothing")
    add_cache_arguments(cmd, "content cache of perturbed sequences")
    cmd.set_defaults(run=_run_perturb)


def _run_perturb(args: argparse.Namespace) -> int:
    """Validate everything, print the plan, then (unless ``--dry-run``) write it and print the timings."""
    plan = plan_perturbations(load_config(args.config), dry_run=args.dry_run)
    _print_plan(plan)
    if args.dry_run:
        print("dry run: nothing written")
        return 0
    results = write_perturbations(plan, cache_dir=args.cache_dir)
    _print_timings(plan, results)
    print(f"wrote {plan.root}")
    return 0
