"""The result sections of the experiment page, from the summaries the commands wrote: per SLAM
system the ATE / RPE / tracking table over runs (``sal evaluate``) with its plots; per boundary
search its requirement, interval, trials and plot (``sal boundary``); per feature type the
detections, matches and track lengths with the survival curves (``sal features``)."""

from __future__ import annotations

from typing import Any

from pytest_sal.engine.outcomes.outcome import Trial
from pytest_sal.engine.requirements import METRICS
from pytest_sal.experiment.boundary_summary import read_boundary_summary
from pytest_sal.report.experiment_folder import CLEAN, ExperimentFolder
from pytest_sal.report.formatting import number_text, plain_text
from pytest_sal.report.html_page import esc

__all__ = ["boundary_section", "features_section", "slam_section"]

#: metrics of the SLAM table: summary.json key, heading, format (units from ``requirements.METRICS``)
SLAM_COLUMNS = (
    ("ate_rmse", "ATE RMSE", ".4f"),
    ("rpe_trans", "RPE trans", ".4f"),
    ("rpe_rot", "RPE rot", ".3f"),
    ("t_rel", "KITTI t_rel", ".3f"),
    ("r_rel", "KITTI r_rel", ".3f"),
    ("tracking_rate", "tracked", ".1%"),
)


# ---------------------------------------------------------------- SLAM results


def slam_section(experiment: ExperimentFolder) -> str:
    root = experiment.root / "slam_results"
    heading = "<h2>SLAM results</h2>"
    systems = sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")) if root.is_dir() else []
    if not systems:
        return f"<section>{heading}<p class='dim'>no SLAM runs: run <code>sal evaluate CONFIG --system NAME</code></p></section>"
    parts = [heading]
    for system in systems:
        parts.append(f"<h3>{esc(system.name)}</h3>")
        path = system / "metrics" / "summary.json"
        summary = experiment.json(path) if path.is_file() else None
        if summary is None:
            parts.append(f"<p class='dim'>{'unreadable' if path.is_file() else 'missing'}: {esc(experiment.rel(path))}</p>")
            continue
        parts.append(_slam_table(summary))
        parts.append(
            experiment.picture(
                system / "metrics" / "aggregated_metrics.png",
                f"slam/{system.name}/aggregated_metrics.png",
                f"{system.name}: metrics over runs",
            )
        )
        for k in range(1, int(summary.get("run_count", 1)) + 1):
            ate = experiment.picture(
                system / "metrics" / "comparison" / f"run_{k}" / "ate_comparison.png",
                f"slam/{system.name}/run_{k}/ate.png",
                f"ATE per sequence, run {k}",
                "half",
            )
            plots = system / "trajectory_plots" / "comparison" / f"run_{k}"
            traj = experiment.picture(
                plots / "trajectory_comparison_xz.png", f"slam/{system.name}/run_{k}/trajectories.png", f"trajectories, run {k}", "half"
            )
            error = experiment.picture(
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


def boundary_section(experiment: ExperimentFolder) -> str:
    heading = "<h2>Robustness boundary</h2>"
    summaries = experiment.summaries("robustness_boundary", "*/*/boundary_summary.json")
    if summaries is None:
        return f"<section>{heading}<p class='dim'>no boundary search: run <code>sal boundary CONFIG --system NAME</code></p></section>"
    parts = [heading]
    for path, data in summaries:
        try:
            summary = read_boundary_summary(data)
        except ValueError as exc:
            experiment.problem(f"{experiment.rel(path)}: {exc}; its part of the report is left out")
            continue
        outcome, block = summary.outcome, summary.experiment
        unit = outcome.boundary.unit
        system, name = path.parent.parent.name, path.parent.name
        verdict = "passed" if outcome.verdict == "passed" else "failed"
        facts = [
            ("requirement", f"<code>{esc(outcome.requirement)}</code>"),
            (
                "boundary",
                f"{esc(outcome.parameter)} {esc(outcome.boundary.text())} <span class='dim'>({esc(outcome.termination)})</span>",
            ),
            (
                "pass / fail value",
                f"{esc(plain_text(outcome.boundary.pass_value))} / {esc(plain_text(outcome.boundary.fail_value))} {esc(unit)}",
            ),
            ("trials", f"{esc(len(outcome.trials))} (a linear sweep at the tolerance step: {esc(block['linear_sweep_trials'] or '?')})"),
            ("dataset", esc(outcome.dataset)),
        ]
        parts.append(f"<h3><span class='badge {verdict}'>{verdict}</span> {esc(name)} <span class='dim'>({esc(system)})</span></h3>")
        parts.append("<dl>" + "".join(f"<dt>{esc(k)}</dt><dd>{v}</dd>" for k, v in facts) + "</dl>")
        parts.append(
            experiment.picture(
                path.parent / "boundary_plot.png", f"boundary/{system}/{name}.png", f"{outcome.parameter} against the metrics"
            )
        )
        parts.append(_trials_table(outcome.trials, unit))
    return "<section>" + "\n".join(parts) + "</section>"


def _trials_table(trials: list[Trial], unit: str) -> str:
    rows = []
    for i, t in enumerate(trials):
        m = t.metrics
        notes = (["cached"] if t.cached else []) + [t.votes()]
        failed = "; ".join(t.failed) + "".join(f" ({why})" for why in m.get("failures") or [])  # why a metric is missing
        cells = [
            str(i + 1),
            plain_text(t.value),
            "pass" if t.passed else "fail",
            number_text(m.get("ate_rmse"), ".4f"),
            number_text(m.get("tracking_rate"), ".0%"),
            ", ".join(notes),
            failed,
        ]
        numeric = {0, 1, 3, 4}
        rows.append(
            f"<tr class='{'passed' if t.passed else 'failed'}'>"
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


def features_section(experiment: ExperimentFolder) -> str:
    heading = "<h2>Feature tracking</h2>"
    summaries = experiment.summaries("features", "*/summary.json")
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
                number_text(st.get("mean_track_length"), ".2f"),
                plain_text(st.get("max_track_length")),
            ]
            rows.append("<tr>" + "".join(f"<td{' class=num' if i else ''}>{esc(c)}</td>" for i, c in enumerate(cells)) + "</tr>")
        parts.append(f"<table class='features'><thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>")
        survival = experiment.picture(
            path.parent / "track_survival.png", f"features/{feature}/track_survival.png", f"{feature}: track survival", "half"
        )
        detections = experiment.picture(
            path.parent / "detections.png", f"features/{feature}/detections.png", f"{feature}: detections and matches per frame", "half"
        )
        parts.append(f"<div class='pair'>{survival}{detections}</div>")
    return "<section>" + "\n".join(parts) + "</section>"


def _stat(entry: Any, key: str, spec: str) -> str:
    return number_text(entry.get(key) if isinstance(entry, dict) else None, spec)
