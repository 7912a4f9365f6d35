"""The example frames of the experiment page: the same moment (the middle of the clean sequence,
matched by timestamp) in the clean sequence and in every sequence ``sal perturb`` wrote, each
captioned with its perturbation's parameters."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pytest_sal.experiment.config import build_sequence, load_config
from pytest_sal.report.experiment_folder import CLEAN, ExperimentFolder
from pytest_sal.report.formatting import plain_text
from pytest_sal.report.html_page import asset_src, esc
from sal_adapters import SalError, Sequence, open_dataset
from sal_adapters.datasets import WRITTEN_MARKER
from sal_adapters.images import scaled_to_width, write_image

__all__ = ["THUMBNAIL_WIDTH", "frames_section"]

#: width (px) of the example frames on the page; they are shown at this, their natural, size
THUMBNAIL_WIDTH = 360


def frames_section(experiment: ExperimentFolder, pipeline: dict[str, Any] | None) -> str:
    """The ``<section>`` of example frames; ``pipeline``: ``pipeline_results.json``, whose
    ``perturbations`` give the sequences' order and their modules (``None`` when absent)."""
    images = experiment.root / "images"
    heading = "<h2>Example frames</h2>"
    if not images.is_dir():
        return f"<section>{heading}<p class='dim'>no perturbed sequences: run <code>sal perturb CONFIG</code></p></section>"
    recorded = (pipeline or {}).get("perturbations") or {}
    sequences = _sequences(experiment, images, recorded)
    if not sequences:
        return f"<section>{heading}<p class='dim'>no readable sequence under {esc(experiment.rel(images))}</p></section>"
    first = next(iter(sequences.values()))
    moment = float(first.timestamps[len(first) // 2])
    figures = []
    for name, seq in sequences.items():
        if not len(seq):
            continue
        at = int(np.argmin(np.abs(seq.timestamps - moment)))
        try:
            rgb = seq[at].image
        except (SalError, OSError, ValueError) as exc:
            experiment.problem(f"{experiment.rel(images / name)}: frame {at} cannot be read ({exc})")
            continue
        target = experiment.out_dir / "assets" / "frames" / f"{_file_stem(name)}.png"
        target.parent.mkdir(parents=True, exist_ok=True)
        thumb = scaled_to_width(rgb, THUMBNAIL_WIDTH)
        write_image(target, thumb)
        module = (recorded.get(name) or {}).get("module")
        caption = "clean sequence" if name == CLEAN and module is None else _module_text(module)
        figures.append(
            f"<figure style='width: {thumb.shape[1]}px'><img src='{asset_src(target, experiment.out_dir)}' width='{thumb.shape[1]}' height='{thumb.shape[0]}' alt='{esc(name)} at t={seq.timestamps[at]:.2f} s'>"
            f"<figcaption><b>{esc(name)}</b><br><span class='dim'>{esc(caption)}</span></figcaption></figure>"
        )
    return f"<section>{heading}<p class='dim'>the same moment, t = {moment:.2f} s, in every sequence</p><div class='gallery frames'>{''.join(figures)}</div></section>"


def _sequences(experiment: ExperimentFolder, images: Path, recorded: dict[str, Any]) -> dict[str, Sequence]:
    """The sequences that open, by name: the clean one first, then those of ``images/``, the
    ``recorded`` ones in their order before the others (sorted)."""
    names = [n for n in recorded if (images / n).is_dir()] + sorted(
        p.name for p in images.iterdir() if p.is_dir() and p.name not in recorded and not p.name.startswith(".")
    )
    sequences: dict[str, Sequence] = {}
    clean = _clean_sequence(experiment)
    if clean is not None:
        sequences[CLEAN] = clean
    for name in names:
        seq = _written_sequence(experiment, images / name)
        if seq is not None:
            sequences[name] = seq
    return sequences


def _clean_sequence(experiment: ExperimentFolder) -> Sequence | None:
    """The clean sequence, opened from the copy of the config ``sal perturb`` left (if it still opens)."""
    config_path = experiment.root / "config.yaml"
    if not config_path.is_file():
        return None
    try:
        return build_sequence(load_config(config_path))
    except SalError as exc:
        experiment.problem(f"clean frames: {config_path} no longer opens its dataset ({exc})")
        return None


def _written_sequence(experiment: ExperimentFolder, folder: Path) -> Sequence | None:
    """A sequence ``sal perturb`` wrote, reopened in its own layout."""
    marker = folder / WRITTEN_MARKER
    if not marker.is_file():
        experiment.problem(f"{experiment.rel(folder)}: no {WRITTEN_MARKER}, so not written by sal perturb; left out")
        return None
    info = experiment.json(marker)
    if info is None:
        return None
    try:
        return open_dataset(str(info.get("layout")), folder / str(info.get("path", ".")))
    except SalError as exc:
        experiment.problem(f"{experiment.rel(folder)}: cannot be opened as {info.get('layout')!r} ({exc})")
        return None


def _module_text(module: dict[str, Any] | None) -> str:
    """``rain(intensity_mm_h=25) >> lens_soiling(particles=40)`` from a module's JSON form."""
    if not module:
        return "clean sequence"
    steps = module.get("steps")
    if isinstance(steps, list):
        return " >> ".join(_module_text(s) for s in steps)
    params = ", ".join(f"{k}={plain_text(v)}" for k, v in (module.get("params") or {}).items() if v is not None)
    return f"{module.get('module', '?')}({params})"


def _file_stem(name: str) -> str:
    """``name`` safe as a file name (other characters become ``_``)."""
    return "".join(c if c.isalnum() or c in "._-" else "_" for c in name) or "sequence"
