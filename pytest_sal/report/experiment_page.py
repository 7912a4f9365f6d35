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
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pytest_sal.engine.requirements import METRICS
from pytest_sal.report.html_page import REPORT_CSS, asset_src, esc, html_page, page_folder
from sal_adapters import SalError, Sequence, open_dataset
from sal_adapters.atomic import copy_file
from sal_adapters.datasets import WRITTEN_MARKER
from sal_adapters.images import scaled_to_width, write_image
from sal_adapters.textfiles import atomic_write_text

__all__ = ["THUMBNAIL_WIDTH", "write_experiment_report"]

#: width (px) of the example frames on the page; they are shown at this, their natural, size
THUMBNAIL_WIDTH = 360
#: metrics of the SLAM table: summary.json key, heading, format (units from ``requirements.METRICS``)
SLAM_COLUMNS = (
    ("ate_rmse", "ATE RMSE", ".4f"),
    ("rpe_trans", "RPE trans", ".4f"),
    ("rpe_rot", "RPE rot", ".3f"),
    ("t_rel", "KITTI t_rel", ".3f"),
    ("r_rel", "KITTI r_rel", ".3f"),
    ("tracking_rate", "tracked", ".1%"),
)
CLEAN = "baseline"


class _Page:
    """Collects the page's sections, its copied pictures and the problems met on the way."""

    def __init__(self, folder: Path, out_dir: Path, warn: Callable[[str], None]):
        self.folder, self.out_dir, self.warn = folder, out_dir, warn
        self.problems: list[str] = []

    def json(self, path: Path) -> dict[str, Any] | None:
        """The JSON object at ``path``, or ``None`` with the problem noted (never raises)."""
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            return self.problem(f"{self.rel(path)}: cannot be read ({exc}); its part of the report is left out")
        if not isinstance(data, dict):
            return self.problem(f"{self.rel(path)}: holds a JSON {type(data).__name__}, not an object; its part of the report is left out")
        return data

    def summaries(self, part: str, pattern: str) -> list[tuple[Path, dict[str, Any]]] | None:
        """The readable JSON files matching ``pattern`` under ``folder/part``, sorted by path;
        ``None`` when there is none at all (that command was not run)."""
        root = self.folder / part
        found = root.glob(pattern) if root.is_dir() else []  # not in hidden folders: outputs being replaced
        paths = sorted(p for p in found if not any(part.startswith(".") for part in p.relative_to(root).parts))
        if not paths:
            return None
        return [(path, data) for path in paths if (data := self.json(path)) is not None]

    def problem(self, message: str) -> None:
        """Note ``message`` on the page and warn; returns ``None`` for ``return page.problem(...)``."""
        self.problems.append(message)
        self.warn(f"warning: {message}")

    def picture(self, source: Path, name: str, alt: str, css: str = "plot") -> str:
        """Copy the PNG ``source`` to ``assets/<name>`` and return its <img>, or a note when absent."""
        if not source.is_file():
            return f"<p class='dim'>missing: {esc(self.rel(source))}</p>"
        target = self.out_dir / "assets" / name
        copy_file(source, target)
        return f"<img class='{css}' src='{asset_src(target, self.out_dir)}' alt='{esc(alt)}' loading='lazy'>"

    def rel(self, path: Path) -> str:
        try:
            return path.relative_to(self.folder).as_posix()
        except ValueError:
            return str(path)


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
    page = _Page(folder, out_dir, warn)
    pipeline = page.json(folder / "pipeline_results.json") if (folder / "pipeline_results.json").is_file() else None
    sections = [
        _frames_section(page, pipeline),
        _slam_section(page),
        _boundary_section(page),
        _features_section(page),
    ]
    name = (pipeline or {}).get("experiment") or folder.name
    dataset = (pipeline or {}).get("dataset") or {}
    where = f"{dataset.get('type', '')} {dataset.get('name', '')}, {dataset.get('frames', '?')} frames" if dataset else ""
    problems = "".join(f"<li>{esc(p)}</li>" for p in page.problems)
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
    from pytest_sal.experiment.config import load_config

    config = load_config(config_path)
    if not config.output.create_timestamp_dir:
        return config.output_dir()
    runs = sorted(config.output.base_dir.glob(f"{config.experiment.name}_????????_??????"))
    if not runs:
        raise SalError(
            f"{config_path}: no results folder {config.output.base_dir / config.experiment.name}_<YYYYmmdd_HHMMSS> yet; run sal perturb or sal evaluate on it first"
        )
    return runs[-1]  # the timestamps sort in time order


# ---------------------------------------------------------------- example frames


def _frames_section(page: _Page, pipeline: dict[str, Any] | None) -> str:
    images = page.folder / "images"
    heading = "<h2>Example frames</h2>"
    if not images.is_dir():
        return f"<section>{heading}<p class='dim'>no perturbed sequences: run <code>sal perturb CONFIG</code></p></section>"
    recorded = (pipeline or {}).get("perturbations") or {}
    names = [n for n in recorded if (images / n).is_dir()] + sorted(
        p.name for p in images.iterdir() if p.is_dir() and p.name not in recorded and not p.name.startswith(".")
    )
    sequences: dict[str, Sequence] = {}
    clean = _clean_sequence(page)
    if clean is not None:
        sequences[CLEAN] = clean
    for name in names:
        seq = _written_sequence(page, images / name)
        if seq is not None:
            sequences[name] = seq
    if not sequences:
        return f"<section>{heading}<p class='dim'>no readable sequence under {esc(page.rel(images))}</p></section>"
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
            page.problem(f"{page.rel(images / name)}: frame {at} cannot be read ({exc})")
            continue
        target = page.out_dir / "assets" / "frames" / f"{_file_stem(name)}.png"
        target.parent.mkdir(parents=True, exist_ok=True)
        thumb = scaled_to_width(rgb, THUMBNAIL_WIDTH)
        write_image(target, thumb)
        module = (recorded.get(name) or {}).get("module")
        caption = "clean sequence" if name == CLEAN and module is None else _module_text(module)
        figures.append(
            f"<figure style='width: {thumb.shape[1]}px'><img src='{asset_src(target, page.out_dir)}' width='{thumb.shape[1]}' height='{thumb.shape[0]}' alt='{esc(name)} at t={seq.timestamps[at]:.2f} s'>"
            f"<figcaption><b>{esc(name)}</b><br><span class='dim'>{esc(caption)}</span></figcaption></figure>"
        )
    return f"<section>{heading}<p class='dim'>the same moment, t = {moment:.2f} s, in every sequence</p><div class='gallery frames'>{''.join(figures)}</div></section>"


def _clean_sequence(page: _Page) -> Sequence | None:
    """The clean sequence, opened from the copy of the config ``sal perturb`` left (if it still opens)."""
    config_path = page.folder / "config.yaml"
    if not config_path.is_file():
        return None
    from pytest_sal.experiment.config import build_sequence, load_config

    try:
        return build_sequence(load_config(config_path))
    except SalError as exc:
        page.problem(f"clean frames: {config_path} no longer opens its dataset ({exc})")
        return None


def _written_sequence(page: _Page, folder: Path) -> Sequence | None:
    """A sequence ``sal perturb`` wrote, reopened in its own layout."""
    marker = folder / WRITTEN_MARKER
    if not marker.is_file():
        return page.problem(f"{page.rel(folder)}: no {WRITTEN_MARKER}, so not written by sal perturb; left out")
    info = page.json(marker)
    if info is None:
        return None
    try:
        return open_dataset(str(info.get("layout")), folder / str(info.get("path", ".")))
    except SalError as exc:
        return page.problem(f"{page.rel(folder)}: cannot be opened as {info.get('layout')!r} ({exc})")


def _module_text(module: dict[str, Any] | None) -> str:
    """``rain(intensity_mm_h=25) >> lens_soiling(particles=40)`` from a module's JSON form."""
    if not module:
        return "clean sequence"
    steps = module.get("steps")
    if isinstance(steps, list):
        return " >> ".join(_module_text(s) for s in steps)
    params = ", ".join(f"{k}={_value(v)}" for k, v in (module.get("params") or {}).items() if v is not None)
    return f"{module.get('module', '?')}({params})"


# ---------------------------------------------------------------- SLAM results


def _slam_section(page: _Page) -> str:
    root = page.folder / "slam_results"
    heading = "<h2>SLAM results</h2>"
    systems = sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")) if root.is_dir() else []
    if not systems:
        return f"<section>{heading}<p class='dim'>no SLAM runs: run <code>sal evaluate CONFIG --slam NAME</code></p></section>"
    parts = [heading]
    for system in systems:
        parts.append(f"<h3>{esc(system.name)}</h3>")
        path = system / "metrics" / "summary.json"
        summary = page.json(path) if path.is_file() else None
        if summary is None:
            parts.append(f"<p class='dim'>{'unreadable' if path.is_file() else 'missing'}: {esc(page.rel(path))}</p>")
            continue
        parts.append(_slam_table(summary))
        parts.append(
            page.picture(
                system / "metrics" / "aggregated_metrics.png",
                f"slam/{system.name}/aggregated_metrics.png",
                f"{system.name}: metrics over runs",
            )
        )
        for k in range(1, int(summary.get("run_count", 1)) + 1):
            ate = page.picture(
                system / "metrics" / "comparison" / f"run_{k}" / "ate_comparison.png",
                f"slam/{system.name}/run_{k}/ate.png",
                f"ATE per sequence, run {k}",
                "half",
            )
            plots = system / "trajectory_plots" / "comparison" / f"run_{k}"
            traj = page.picture(
                plots / "trajectory_comparison_xz.png", f"slam/{system.name}/run_{k}/trajectories.png", f"trajectories, run {k}", "half"
            )
            error = page.picture(
                plots / "trajectory_comparison_error.png",
                f"slam/{system.name}/run_{k}/error.png",
                f"translation error over time, run {k}",
                "half",
            )
            parts.append(f"<h4>run {k}</h4><div class='pair'>{ate}{traj}{error}</div>")
    return "<section>" + "\n".join(parts) + "</section>"


def _slam_table(summary: dict[str, Any]) -> str:
    order = summary.get("order") or [CLEAN, *(summary.get("perturbations") or {})]
    units = {key: METRICS[key].unit if key != "tracking_rate" else "" for key, _, _ in SLAM_COLUMNS}
    head = (
        "<th>sequence</th><th class='num'>runs ok</th>"
        + "".join(f"<th class='num'>{esc(h)}{f' [{units[key]}]' if units[key] else ''} median</th>" for key, h, _ in SLAM_COLUMNS)
        + "<th class='num'>ATE min .. max [m]</th>"
    )
    rows, failures = [], []
    for name in order:
        entry = summary.get(name) if name == CLEAN else (summary.get("perturbations") or {}).get(name)
        if not isinstance(entry, dict):
            continue
        runs, failed = int(entry.get("runs", 0)), int(entry.get("failures", 0))
        cells = [f"<td>{esc(name)}</td>", f"<td class='num'>{runs - failed}/{runs}</td>"]
        for key, _, spec in SLAM_COLUMNS:
            cells.append(f"<td class='num'>{esc(_stat(entry.get(key), 'median', spec))}</td>")
        ate = entry.get("ate_rmse")
        cells.append(f"<td class='num'>{esc(_stat(ate, 'min', '.4f'))} .. {esc(_stat(ate, 'max', '.4f'))}</td>")
        failures += [
            f"{name}, run {r.get('run')}: {r.get('reason')}" if isinstance(r, dict) else f"{name}: {r}"
            for r in entry.get("failure_reasons") or []
        ]
        rows.append(f"<tr class='{'failed' if entry.get('failures') else 'passed'}'>{''.join(cells)}</tr>")
    runs = summary.get("run_count", "?")
    listed = f"<ul class='failures'>{''.join(f'<li>{esc(f)}</li>' for f in failures)}</ul>" if failures else ""
    return (
        f"<p class='dim'>{esc(summary.get('sequence', ''))}, {esc(summary.get('frames', '?'))} frames, {esc(runs)} run(s) per sequence</p>"
        f"<table class='slam'><thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>{listed}"
    )


# ---------------------------------------------------------------- boundary searches


def _boundary_section(page: _Page) -> str:
    heading = "<h2>Robustness boundary</h2>"
    summaries = page.summaries("robustness_boundary", "*/*/boundary_summary.json")
    if summaries is None:
        return f"<section>{heading}<p class='dim'>no boundary search: run <code>sal boundary CONFIG --slam NAME</code></p></section>"
    parts = [heading]
    for path, s in summaries:
        unit = s.get("unit") or ""
        system, name = path.parent.parent.name, path.parent.name
        verdict = "passed" if s.get("edge_verdict") == "passed" else "failed"
        facts = [
            ("requirement", f"<code>{esc(s.get('requirement', '?'))}</code>"),
            (
                "boundary",
                f"{esc(s.get('parameter', '?'))} {esc(s.get('boundary_text', '?'))} <span class='dim'>({esc(s.get('termination', '?'))})</span>",
            ),
            ("pass / fail value", f"{esc(_value(s.get('pass_value')))} / {esc(_value(s.get('fail_value')))} {esc(unit)}"),
            (
                "trials",
                f"{esc(s.get('trials_used', len(s.get('trials') or [])))} (a linear sweep at the tolerance step: {esc(s.get('linear_sweep_trials', '?'))})",
            ),
            ("dataset", esc(s.get("dataset", "?"))),
        ]
        parts.append(f"<h3><span class='badge {verdict}'>{verdict}</span> {esc(name)} <span class='dim'>({esc(system)})</span></h3>")
        parts.append("<dl>" + "".join(f"<dt>{esc(k)}</dt><dd>{v}</dd>" for k, v in facts) + "</dl>")
        parts.append(
            page.picture(path.parent / "boundary_plot.png", f"boundary/{system}/{name}.png", f"{s.get('parameter')} against the metrics")
        )
        parts.append(_trials_table(s.get("trials") or [], unit))
    return "<section>" + "\n".join(parts) + "</section>"


def _trials_table(trials: list[Any], unit: str) -> str:
    rows = []
    for i, t in enumerate(t for t in trials if isinstance(t, dict)):
        m = t.get("metrics") or {}
        notes = [x for x, on in (("cached", t.get("cached")), (t.get("votes"), t.get("votes"))) if on]
        failed = "; ".join(t.get("failed") or []) + "".join(f" ({why})" for why in m.get("failures") or [])  # why a metric is missing
        cells = [
            str(i + 1),
            _value(t.get("value")),
            str(t.get("verdict", "?")),
            _fmt(m.get("ate_rmse"), ".4f"),
            _fmt(m.get("tracking_rate"), ".0%"),
            ", ".join(notes),
            failed,
        ]
        numeric = {0, 1, 3, 4}
        rows.append(
            f"<tr class='{'passed' if t.get('verdict') == 'pass' else 'failed'}'>"
            + "".join(f"<td{' class=num' if j in numeric else ''}>{esc(c)}</td>" for j, c in enumerate(cells))
            + "</tr>"
        )
    head = ["#", f"value [{unit}]" if unit else "value", "verdict", "ATE [m]", "tracked", "", "failed criteria"]
    return (
        "<table class='trials'><thead><tr>"
        + "".join(f"<th>{esc(h)}</th>" for h in head)
        + f"</tr></thead><tbody>{''.join(rows)}</tbody></table>"
    )


# ---------------------------------------------------------------- feature tracking


def _features_section(page: _Page) -> str:
    heading = "<h2>Feature tracking</h2>"
    summaries = page.summaries("features", "*/summary.json")
    if summaries is None:
        return f"<section>{heading}<p class='dim'>no feature tracking: run <code>sal features CONFIG --features orb</code></p></section>"
    parts = [heading]
    for path, s in summaries:
        feature = path.parent.name
        parts.append(f"<h3>{esc(feature)} <span class='dim'>{esc(s.get('extractor', ''))}</span></h3>")
        head = "".join(
            f"<th{' class=num' if i else ''}>{h}</th>"
            for i, h in enumerate(
                ("sequence", "detections / frame", "matches / frame", "match ratio", "mean track length", "longest track")
            )
        )
        rows = []
        for name, st in (s.get("sequences") or {}).items():
            if not isinstance(st, dict):
                continue
            cells = [
                name,
                _stat(st.get("detections_per_frame"), "mean", ".0f"),
                _stat(st.get("matches_per_frame"), "mean", ".0f"),
                _stat(st.get("match_ratio"), "mean", ".1%"),
                _fmt(st.get("mean_track_length"), ".2f"),
                _value(st.get("max_track_length")),
            ]
            rows.append("<tr>" + "".join(f"<td{' class=num' if i else ''}>{esc(c)}</td>" for i, c in enumerate(cells)) + "</tr>")
        parts.append(f"<table class='features'><thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>")
        survival = page.picture(
            path.parent / "track_survival.png", f"features/{feature}/track_survival.png", f"{feature}: track survival", "half"
        )
        detections = page.picture(
            path.parent / "detections.png", f"features/{feature}/detections.png", f"{feature}: detections and matches per frame", "half"
        )
        parts.append(f"<div class='pair'>{survival}{detections}</div>")
    return "<section>" + "\n".join(parts) + "</section>"


# ---------------------------------------------------------------- formatting


def _stat(entry: Any, key: str, spec: str) -> str:
    return _fmt(entry.get(key) if isinstance(entry, dict) else None, spec)


def _fmt(value: Any, spec: str) -> str:
    return "-" if not isinstance(value, (int, float)) or isinstance(value, bool) or not np.isfinite(value) else format(value, spec)


def _value(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, list):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    return "-" if value is None else str(value)


def _file_stem(name: str) -> str:
    return "".join(c if c.isalnum() or c in "._-" else "_" for c in name) or "sequence"


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
