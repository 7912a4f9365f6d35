"""The one formatter of numbers, metrics, intervals and trial lines, for every report and the
live progress: ``num`` (4 significant digits), ``with_unit``, ``signed`` changes, ``metric_text``
(a metric with its unit), ``short_id`` (a node id without folders) and ``trial_line`` (one
trial as text)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from pytest_sal.engine.outcome import Trial
from pytest_sal.engine.requirements import METRICS

__all__ = ["ELLIPSIS", "metric_text", "num", "short_id", "signed", "trial_line", "truncate_left", "truncate_right", "with_unit"]

ELLIPSIS = "…"


def short_id(test_id: str) -> str:
    """The node id without the test file's folders: ``test_fog.py::test_visibility[orbslam3]``."""
    path, sep, rest = test_id.partition("::")
    return path.rsplit("/", 1)[-1] + sep + rest


def truncate_left(text: str, width: int) -> str:
    return text if len(text) <= width else ELLIPSIS + text[len(text) - width + 1 :] if width > 1 else text[-width:]


def truncate_right(text: str, width: int) -> str:
    return text if len(text) <= width else text[: width - 1] + ELLIPSIS if width > 1 else text[:width]


def num(value: float | None) -> str:
    return "-" if value is None else f"{value:.4g}"


def with_unit(value: float | None, unit: str) -> str:
    return "-" if value is None else f"{value:.4g}{' ' + unit if unit else ''}"


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
    unit = METRICS[name].unit if name in METRICS else ""
    return f"{value:.3g}{' ' + unit if unit else ''}"


def trial_line(trial: Trial, parameter: str, unit: str, metrics: Sequence[str]) -> str:
    """One trial as text: ``fog.visibility_m = 25 m: pass  tracking_rate 0.65, ate_rmse 0.0123 m
    0.4 s (cached)``: the value with its unit, the verdict (``FAIL`` in capitals; the runs'
    votes when more than one ran), the median ``metrics`` named (with their units), the
    seconds spent on the trial (``Trial.wall_time_s``) and ``(cached)`` when no run was made."""
    votes = f" ({trial.votes()})" if len(trial.runs) > 1 else ""
    shown = ", ".join(f"{name} {metric_text(name, trial.metrics.get(name))}" for name in metrics)
    value = f"{trial.value:g}{' ' + unit if unit else ''}"
    cached = " (cached)" if trial.cached else ""
    return f"{parameter} = {value}: {'pass' if trial.passed else 'FAIL'}{votes}  {shown}  {trial.wall_time_s:.1f} s{cached}"
