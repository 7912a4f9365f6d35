"""One HTML page from an experiment folder: what ``sal perturb``, ``sal evaluate``,
``sal boundary`` and ``sal features`` wrote under ``<base_dir>/<name>/``.

The page (``report/index.html`` by default) is self-contained like the plugin's report: inline
CSS, no script, no network resources, and its pictures copied beside it under ``assets/`` with
relative links, so the folder can be moved or uploaded as a CI artifact. It shows:

* example frames: the same moment (the middle of the clean sequence, matched by timestamp) in
  the clean sequence and in every perturbed one, with each perturbation's parameters;
* per SLAM system: the ATE / RPE / tracking table over runs from ``metrics/summary.json``, the
  aggregated and per-run ATE plots and the trajectory comparisons;
* per boundary search: requirement, interval, termination, trials used against a linear sweep,
  the metric plot and the trials;
* per feature type: detections, matches and track length per sequence, and the survival curves.

A part that is missing is named with the command that makes it; a part that cannot be read
(broken JSON) is named with its file and the reason, and the rest of the page is still built.

This module assembles the page; ``experiment_folder`` reads the folder, ``experiment_frames``
and ``experiment_results`` write the sections.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from pytest_sal.experiment.config import load_config
from pytest_sal.report.experiment_folder import ExperimentFolder
from pytest_sal.report.experiment_frames import frames_section
from pytest_sal.report.experiment_results import boundary_section, features_section, slam_section
from pytest_sal.report.html_page import REPORT_CSS, esc, html_page, page_folder
from sal_adapters import SalError
from sal_adapters.common.textfiles import atomic_write_text

__all__ = ["write_experiment_report"]


def write_experiment_report(folder: str | Path, out_dir: str | Path | None = None, *, warn: Callable[[str], None] = print) -> Path:
    """Write ``index.html`` and ``assets/`` for the experiment ``folder`` into ``out_dir``
    (default ``folder/report``); return the page's path. ``folder`` may also be the experiment's
    YAML config: its results folder ``<output.base_dir>/<experiment.name>`` is used.

    Raises:
        SalError: ``folder`` is not a folder (or a config), holds none of images/, slam_results/,
            robustness_boundary/, features/ (nothing was run into it yet), or ``out_dir`` is a file.
    """
    folder = Path(folder).expanduser()
    if folder.is_file() and folder.suffix.lower() in (".yaml", ".yml"):
        folder = _results_folder(folder)
    if not folder.is_dir():
        raise SalError(f"experiment folder not found: {folder} (give <output.base_dir>/<experiment.name>)")
    parts = ("images", "slam_results", "robustness_boundary", "features")
    if not any((folder / p).is_dir() for p in parts):
        raise SalError(
            f"{folder} holds no experiment results (none of {', '.join(p + '/' for p in parts)}); "
            "run sal perturb, sal evaluate, sal boundary or sal features on its config first"
        )
    out_dir = Path(out_dir).expanduser() if out_dir is not None else folder / "report"
    if out_dir.exists() and not out_dir.is_dir():
        raise SalError(f"report folder {out_dir} is a file; give a folder for index.html and assets/")
    with page_folder(out_dir) as staging:
        _write_report(folder, staging, warn)
    return out_dir / "index.html"


def _write_report(folder: Path, out_dir: Path, warn: Callable[[str], None]) -> None:
    """Write ``index.html`` and ``assets/`` of the experiment ``folder`` into ``out_dir``."""
    experiment = ExperimentFolder(folder, out_dir, warn)
    pipeline = experiment.json(folder / "pipeline_results.json") if (folder / "pipeline_results.json").is_file() else None
    sections = [
        frames_section(experiment, pipeline),
        slam_section(experiment),
        boundary_section(experiment),
        features_section(experiment),
    ]
    name = (pipeline or {}).get("experiment") or folder.name
    dataset = (pipeline or {}).get("dataset") or {}
    where = f"{dataset.get('type', '')} {dataset.get('name', '')}, {dataset.get('frames', '?')} frames" if dataset else ""
    problems = "".join(f"<li>{esc(p)}</li>" for p in experiment.problems)
    title = f"Experiment {name}"
    text = html_page(
        title,
        REPORT_CSS + _EXTRA_CSS,
        _BODY.format(
            title=esc(title),
            where=esc(f"{where} - {folder}" if where else str(folder)),
            problems=f"<section class='problems'><h2>Left out</h2><ul>{problems}</ul></section>" if problems else "",
            sections="\n".join(sections),
        ),
    )
    atomic_write_text(out_dir / "index.html", text)


def _results_folder(config_path: Path) -> Path:
    """The config's results folder; with ``create_timestamp_dir`` the newest ``<name>_<time>``."""
    config = load_config(config_path)
    if not config.output.create_timestamp_dir:
        return config.output_dir()
    runs = sorted(config.output.base_dir.glob(f"{config.experiment.name}_????????_??????"))
    if not runs:
        raise SalError(
            f"{config_path}: no results folder {config.output.base_dir / config.experiment.name}_<YYYYmmdd_HHMMSS> yet; run sal perturb or sal evaluate on it first"
        )
    return runs[-1]  # the timestamps sort in time order


_BODY = """<header><h1>{title}</h1><p class="where">{where}</p></header>
{problems}
{sections}"""

_EXTRA_CSS = """
section { margin: 1.4em 0 2.2em; }
h2 { border-bottom: 1px solid #d0d7de; padding-bottom: .25em; }
h4 { margin: 1em 0 .3em; font-size: .95em; }
img.plot { max-width: 900px; }
.gallery.frames figure { border-color: #d0d7de; }
.gallery.frames img { width: auto; }
.gallery.frames figcaption { text-align: left; overflow-wrap: anywhere; }
.pair { display: flex; flex-wrap: wrap; gap: 1em; }
img.half { display: block; max-width: 49%; height: auto; border: 1px solid #e5e7eb; border-radius: 4px; }
table.slam tr.failed td:first-child { color: #b42318; font-weight: 600; }
ul.failures { color: #b42318; margin-top: 0; }
section.problems { border: 1px solid #cf222e; border-radius: 6px; padding: .5em 1.2em; background: #fff5f5; }
"""
