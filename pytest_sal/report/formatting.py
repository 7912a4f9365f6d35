"""The reports' and the live progress's one formatter of metrics, changes, values read from
files and trial lines: ``signed`` changes, ``metric_text`` (a metric with its unit),
``metrics_text`` (several), ``number_text`` and ``plain_text`` (values of a summary file),
``short_id`` (a node id without folders), ``truncate_left`` / ``truncate_right`` and
``trial_line`` (one trial as text).

A number with its unit (``num``, ``with_unit``) and the boundary interval (``Boundary.text``,
``Boundary.short_text``) are written by ``pytest_sal.engine.outcomes.quantity`` and
``pytest_sal.engine.outcomes.outcome``, one layer down, since the engine's failure message needs them
too; this module builds on them."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from pytest_sal.engine.outcomes.outcome import Trial
from pytest_sal.engine.outcomes.quantity import num, with_unit
from pytest_sal.engine.requirements import METRICS

__all__ = [
    "ELLIPSIS",
    "metric_text",
    "metrics_text",
    "number_text",
    "plain_text",
    "short_id",
    "signed",
    "trial_line",
    "truncate_left",
    "truncate_right",
]

ELLIPSIS = "…"


def short_id(test_id: str) -> str:
    """The node id without the test file's folders: ``test_fog.py::test_visibility[orbslam3]``."""
    path, sep, rest = test_id.partition("::")
    return path.rsplit("/", 1)[-1] + sep + rest


def truncate_left(text: str, width: int) -> str:
    """``text`` cut to ``width`` characters from the left, marked ``…`` (``…est_fog.py::test``)."""
    return text if len(text) <= width else ELLIPSIS + text[len(text) - width + 1 :] if width > 1 else text[-width:]


def truncate_right(text: str, width: int) -> str:
    """``text`` cut to ``width`` characters from the right, marked ``…``."""
    return text if len(text) <= width else text[: width - 1] + ELLIPSIS if width > 1 else text[:width]


def signed(value: float | None, unit: str) -> str:
    """``+1.2 m``, ``-3 %``, ``±0 m``; ``-`` when unknown."""
    if value is None:
        return "-"
    text = "±0" if abs(value) < 1e-12 else f"{value:+.3g}"
    return f"{text} {unit}" if unit else text


def metric_text(name: str, value: Any) -> str:
    """A metric value with its unit (``0.412 m``); ``-`` when missing."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return str(value)
    return with_unit(value, METRICS[name].unit if name in METRICS else "", digits=3)


def metrics_text(metrics: Mapping[str, Any], names: Iterable[str]) -> str:
    """The ``names`` metrics of ``metrics`` with their units: ``ate_rmse 0.21 m, tracking_rate 0.99``."""
    return ", ".join(f"{name} {metric_text(name, metrics.get(name))}" for name in names)


def number_text(value: Any, spec: str) -> str:
    """``value`` in the format ``spec`` (``.4f``, ``.1%``), or ``-`` when it is not a finite
    number (missing or null in a summary file)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return "-"
    return format(value, spec)


def plain_text(value: Any) -> str:
    """A value read from a summary file: a float to 4 significant digits, a list of them in
    brackets (``[0.5, 2]``), ``-`` for null, anything else as it is."""
    if isinstance(value, float):
        return num(value)
    if isinstance(value, list):
        return "[" + ", ".join(plain_text(v) for v in value) + "]"
    return "-" if value is None else str(value)


def trial_line(trial: Trial, parameter: str, unit: str, metrics: Sequence[str]) -> str:
    """One trial as text: ``fog.visibility_m = 25 m: pass  tracking_rate 0.65, ate_rmse 0.0123 m
    0.4 s (cached)``: the value with its unit, the verdict (``FAIL`` in capitals; the runs'
    votes when more than one ran), the median ``metrics`` named (with their units), the
    seconds spent on the trial (``Trial.wall_time_s``), ``(cached)`` when no run was made,
    ``(speculative)`` when a parallel search evaluated it beside its path and, when runs were
    stopped early, why the first was (``stopped early (2 of 3 runs): ...``): their metrics cover
    the frames they ran."""
    votes = f" ({trial.votes()})" if len(trial.runs) > 1 else ""
    notes = (" (cached)" if trial.cached else "") + (" (speculative)" if trial.speculative else "")
    shown = metrics_text(trial.metrics, metrics)
    stopped = [run["stopped"] for run in trial.runs if run.get("stopped")]
    count = f" ({len(stopped)} of {len(trial.runs)} runs)" if len(trial.runs) > 1 else ""
    early = f"  stopped early{count}: {stopped[0]}" if stopped else ""
    return (
        f"{parameter} = {with_unit(trial.value, unit, digits=6)}: {'pass' if trial.passed else 'FAIL'}{votes}  {shown}  "
        f"{trial.wall_time_s:.1f} s{notes}{early}"
    )
