"""The perturb workflow (``sal perturb``): each enabled perturbation's sequence written in the
dataset's own layout under ``<base_dir>/<name>/images/<perturbation>/``, through the content
cache, with ``pipeline_results.json`` and a copy of the config beside them.

``plan_perturbations`` builds everything (a dry run renders in memory only);
``write_perturbations`` writes the plan. Its outputs (``images/<perturbation>/``,
``pipeline_results.json``, ``config.yaml``) switch as one generation: they are written into a
staged copy of the experiment folder (``.<name>.sal-tmp-PID-HEX`` beside it) that is swapped in
whole once complete (``sal_adapters.common.atomic.Replacement(within=...)``), so a killed run leaves
the previous generation or the new one, never a mix.
"""

from __future__ import annotations

import json
import time
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pytest_sal.experiment.config import ConfigError, build_modules, build_sequence, perturbed_sequences
from pytest_sal.experiment.schema import ExperimentConfig
from sal_adapters.common.atomic import Replacement, copy_tree, writing
from sal_adapters.common.cache_dir import no_cache_writes
from sal_adapters.common.textfiles import atomic_write_text
from sal_adapters.datasets import WRITTEN_MARKER, write_sequence

if TYPE_CHECKING:  # numpy and the modules load when a command runs, not for `sal --help`
    from pytest_sal.store.content_cache import ContentCache
    from sal_adapters.sequence import Sequence
    from sal_modules.base import Perturbation

__all__ = ["PIPELINE_RESULTS", "PerturbPlan", "plan_perturbations", "write_perturbations"]

#: the results file written beside ``images/``
PIPELINE_RESULTS = "pipeline_results.json"


@dataclass(frozen=True)
class PerturbPlan:
    """What ``write_perturbations`` writes.

    Attributes:
        config: the validated experiment config.
        clean: the clean sequence the config names.
        modules: each enabled perturbation's module by name (``None``: the clean sequence).
        sequences: each enabled perturbation's (lazily) perturbed sequence by name.
        root: the output folder, ``<base_dir>/<experiment.name>[_<timestamp>]``.
    """

    config: ExperimentConfig
    clean: Sequence
    modules: dict[str, Perturbation | None]
    sequences: dict[str, Sequence]
    root: Path


def plan_perturbations(config: ExperimentConfig, *, dry_run: bool = False) -> PerturbPlan:
    """Build the clean sequence, every enabled module and its perturbed sequence (a module that
    cannot apply to the sequence is a ``ConfigError``); with ``dry_run`` nothing is written,
    not even to the cache."""
    with no_cache_writes() if dry_run else nullcontext():  # a dry run renders in memory only
        clean = build_sequence(config)
        modules = build_modules(config)
        sequences = {
            name: seq for name, seq in perturbed_sequences(config, clean).items() if name in modules
        }  # the baseline only if listed
    return PerturbPlan(config, clean, modules, sequences, config.output_dir())


def write_perturbations(plan: PerturbPlan, *, cache_dir: Path | None = None, progress: bool = True) -> dict[str, Any]:
    """Write each perturbed sequence of ``plan`` under ``<root>/images/<name>/`` (through the
    content cache at ``cache_dir``, default ``.sal/cache``; ``progress``: a bar per sequence
    written), with ``dropped_frames.txt`` where frames were dropped, ``pipeline_results.json``
    and ``config.yaml``. A target folder that ``sal perturb`` did not write is a
    ``ConfigError``, before anything is written. Returns the content of ``pipeline_results.json``
    (per perturbation: frames in and kept, dropped frame indices, seconds, cached, output)."""
    from pytest_sal.store.content_cache import command_cache

    config, clean, images = plan.config, plan.clean, plan.root / "images"
    for name in plan.sequences:
        target = images / name
        if target.exists() and (not target.is_dir() or (any(target.iterdir()) and not (target / WRITTEN_MARKER).is_file())):
            raise ConfigError(
                config.source, "output.base_dir", f"{target} exists and was not written by sal perturb; move it or choose another base_dir"
            )
    cache = command_cache(cache_dir)
    results: dict[str, Any] = {
        "experiment": config.experiment.name,
        "seed": config.experiment.seed,
        "dataset": {"type": config.dataset.type, "name": clean.name, "frames": len(clean)},
        "status": "running",
        "perturbations": {},
    }
    with Replacement(within=plan.root) as outputs:  # the old output stays whole; the new one switches in as one
        for name, seq in plan.sequences.items():
            results["perturbations"][name] = _write_one(plan, name, seq, cache, outputs, progress)
        results["status"] = "completed"
        outputs.write_text(plan.root / PIPELINE_RESULTS, json.dumps(results, indent=2) + "\n")
        outputs.write_text(plan.root / "config.yaml", config.text)
    return results


def _write_one(plan: PerturbPlan, name: str, seq: Sequence, cache: ContentCache, outputs: Replacement, progress: bool) -> dict[str, Any]:
    """Write the perturbation ``name`` (its sequence ``seq``) into the staging of ``outputs``;
    its entry of ``pipeline_results.json``."""
    from pytest_sal.store.cache_keys import cache_key

    clean, module = plan.clean, plan.modules[name]
    started = time.perf_counter()

    def fill(target: Path) -> None:
        write_sequence(seq, target, progress=progress)

    folder, was_cached = cache.compute_dir(cache_key(frames=seq.fingerprint), fill)
    target = plan.root / "images" / name
    staging = outputs.folder(target)
    with writing(target):
        copy_tree(folder, staging)
    kept = {int(r.index) for r in seq.records}
    dropped = [i for i in (int(r.index) for r in clean.records) if i not in kept]
    if dropped:
        atomic_write_text(
            staging / "dropped_frames.txt",
            f"# frames of {clean.name} dropped by {name} (dataset frame indices)\n" + "".join(f"{i}\n" for i in dropped),
        )
    return {
        "type": plan.config.perturbation(name).type,
        "module": None if module is None else module.to_dict(),
        "frames_in": len(clean),
        "frames_kept": len(seq),
        "dropped_frames": dropped,
        "seconds": round(time.perf_counter() - started, 4),
        "cached": was_cached,
        "output": str(target),
    }
