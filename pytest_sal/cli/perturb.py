"""``sal perturb CONFIG``: validate an experiment config, then write each enabled perturbation's
sequence in the dataset's own layout under ``<base_dir>/<name>/images/<perturbation>/``,
through the trial cache, with progress bars and a timing table."""

from __future__ import annotations

import argparse
import json
import time
from contextlib import nullcontext
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pytest_sal.cli.arg_types import add_cache_arguments
from pytest_sal.experiment.config import (
    BoundaryConfig,
    ConfigError,
    ExperimentConfig,
    build_module,
    build_modules,
    build_sequence,
    load_config,
    perturbed_sequences,
)
from sal_adapters.atomic import Replacement, copy_tree, writing
from sal_adapters.cache_dir import no_cache_writes
from sal_adapters.datasets import WRITTEN_MARKER, write_sequence
from sal_adapters.textfiles import atomic_write_text

if TYPE_CHECKING:  # numpy and the modules load when a command runs, not for `sal --help`
    from sal_adapters.sequence import Sequence
    from sal_modules.base import Perturbation
    from sal_modules.params import Param

__all__ = ["add_experiment_commands", "run_perturb"]


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


def _boundary_param(config: ExperimentConfig, rb: BoundaryConfig) -> Param:
    from sal_modules.base import Composite

    pert = next(p for p in config.perturbations if p.name == rb.target_perturbation)
    module = build_module(pert)
    if isinstance(module, Composite):
        return module.param(rb.parameter)[1]
    return type(module).parameters()[rb.parameter]


# ------------------------------------------------------------------------------ sal perturb


def run_perturb(config: ExperimentConfig, *, dry_run: bool = False, cache_dir: Path | None = None, out: Any = None) -> dict[str, Any]:
    """Validate everything, then (unless ``dry_run``) write each enabled perturbation under
    ``<base_dir>/<name>/images/<perturbation>/``; returns the results written to
    ``pipeline_results.json`` (or the plan)."""
    import sys

    from pytest_sal.store.cache_keys import cache_key
    from pytest_sal.store.trial_cache import command_cache
    from sal_modules.base import Composite

    out = out or sys.stdout
    with no_cache_writes() if dry_run else nullcontext():  # a dry run renders in memory only
        clean = build_sequence(config)
        modules = build_modules(config)
        perturbed = {
            name: seq for name, seq in perturbed_sequences(config, clean).items() if name in modules
        }  # the baseline only if listed
    seed = config.experiment.seed
    root = config.output_dir()
    print(f"experiment  {config.experiment.name} (seed {seed})", file=out)
    print(f"dataset     {config.dataset.type} {clean.name}: {len(clean)} frames, {clean.sensor}, {clean.fps:.3g} Hz", file=out)
    print(f"output      {root}", file=out)
    width = max([len(n) for n in modules] + [12])
    for name, module in modules.items():
        print(f"  {name:{width}s} {_describe(module)}\n  {'':{width}s} -> {root / 'images' / name}", file=out)
    disabled = [p.name for p in config.perturbations if not p.enabled]
    if disabled:
        print(f"  disabled: {', '.join(disabled)}", file=out)
    rb = config.robustness_boundary
    if rb is not None:
        state = "enabled" if rb.enabled else "disabled"
        spec = _boundary_param(config, rb)
        unit = f" {spec.search_space().unit}" if spec.search_space().unit else ""
        print(
            f"boundary    {rb.name} ({state}): {rb.target_perturbation}.{rb.parameter} in {rb.lower_bound:g} .. {rb.upper_bound:g}{unit}, "
            f"tolerance {rb.tolerance:g}, max_iters {rb.max_iters}, ate_rmse_fail {rb.ate_rmse_fail:g} m",
            file=out,
        )
    if dry_run:
        print("dry run: nothing written", file=out)
        return {"dry_run": True, "output_dir": str(root), "perturbations": list(modules)}

    images = root / "images"
    for name in perturbed:
        target = images / name
        if target.exists() and (not target.is_dir() or (any(target.iterdir()) and not (target / WRITTEN_MARKER).is_file())):
            raise ConfigError(
                config.source, "output.base_dir", f"{target} exists and was not written by sal perturb; move it or choose another base_dir"
            )
    cache = command_cache(cache_dir)
    results: dict[str, Any] = {
        "experiment": config.experiment.name,
        "seed": seed,
        "dataset": {"type": config.dataset.type, "name": clean.name, "frames": len(clean)},
        "status": "running",
        "perturbations": {},
    }
    all_indices = [int(r.index) for r in clean.records]
    with Replacement() as outputs:  # the old output stays whole until every new part is complete
        for name, seq in perturbed.items():
            module = modules[name]
            started = time.perf_counter()

            def fill(target: Path, seq: Sequence = seq) -> None:
                write_sequence(seq, target, progress=True)

            folder, was_cached = cache.compute_dir(cache_key(frames=seq.fingerprint), fill)
            target = images / name
            staging = outputs.folder(target)
            with writing(target):
                copy_tree(folder, staging)
            kept = {int(r.index) for r in seq.records}
            dropped = [i for i in all_indices if i not in kept]
            if dropped:
                atomic_write_text(
                    staging / "dropped_frames.txt",
                    f"# frames of {clean.name} dropped by {name} (dataset frame indices)\n" + "".join(f"{i}\n" for i in dropped),
                )
            results["perturbations"][name] = {
                "type": next(p.type for p in config.perturbations if p.name == name),
                "module": None if module is None else module.to_dict(),
                "frames_in": len(clean),
                "frames_kept": len(seq),
                "dropped_frames": dropped,
                "seconds": round(time.perf_counter() - started, 4),
                "cached": was_cached,
                "output": str(target),
            }
        results["status"] = "completed"
        outputs.write_text(root / "pipeline_results.json", json.dumps(results, indent=2) + "\n")
        outputs.write_text(root / "config.yaml", config.text)

    labels = {
        name: "none" if module is None else (module.label() if isinstance(module, Composite) else module.name)
        for name, module in modules.items()
    }
    lw = max([len(v) for v in labels.values()] + [6])
    print(f"\n  {'perturbation':{width}s} {'module':{lw}s} {'kept':>9s} {'ms/frame':>9s} {'total s':>8s}", file=out)
    for name, r in results["perturbations"].items():
        label = labels[name]
        per_frame = 1000 * r["seconds"] / max(1, r["frames_in"])
        note = " (cached)" if r["cached"] else ""
        print(
            f"  {name:{width}s} {label:{lw}s} {r['frames_kept']:>4d}/{r['frames_in']:<4d} {per_frame:9.1f} {r['seconds']:8.2f}{note}",
            file=out,
        )
    print(f"wrote {root}", file=out)
    return results


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
    config = load_config(args.config)
    run_perturb(config, dry_run=args.dry_run, cache_dir=args.cache_dir)
    return 0
