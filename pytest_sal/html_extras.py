"""pytest-html integration: the row of each robustness test in ``pytest --html=report.html``
carries its boundary in words, the metric-against-parameter plot and the example frames at the
boundary's ends, embedded as base64 PNG (so they show in the plain and the self-contained
report alike).

Registered by the plugin's ``pytest_configure`` only when pytest-html is installed (plugin
``html``); matplotlib is imported when the first robustness test reports, never before. The
plot and the frames are the ones pytest-sal's own HTML report shows (``pytest_sal.report.outcome_page``).
"""

from __future__ import annotations

import base64
from pathlib import Path
from typing import Any

import pytest

from pytest_sal.engine.outcomes.outcome import Outcome
from pytest_sal.engine.outcomes.quantity import with_unit
from pytest_sal.report.html_page import esc
from pytest_sal.report.outcome_report import trial_verdict

__all__ = ["HtmlExtras", "outcome_html"]


class HtmlExtras:
    """The plugin object (``sal-html``): adds an HTML extra to the call report of every test
    that ran a search (its ``Outcome`` stashed under ``outcome_key`` on the item, by the
    plugin that registers this object)."""

    def __init__(self, outcome_key: pytest.StashKey[Outcome]) -> None:
        self.outcome_key = outcome_key

    @pytest.hookimpl(wrapper=True, optionalhook=True)
    def pytest_runtest_makereport(self, item: pytest.Item, call: pytest.CallInfo[None]) -> Any:
        report = yield
        outcome = item.stash.get(self.outcome_key, None)
        if outcome is not None and report.when == "call":
            from pytest_html import extras

            report.extras = [*getattr(report, "extras", []), extras.html(outcome_html(outcome))]
        return report


def outcome_html(outcome: Outcome) -> str:
    """``<div class="sal">``: the boundary and requirement, the metric plot and the frames at
    the boundary's ends (``Trial.artifacts["frame"]``, when the trial made one), as
    ``<img src="data:image/png;base64,...">``."""
    from pytest_sal.analysis.plots import png_bytes  # matplotlib, when the first row is made
    from pytest_sal.report.metric_plot import metric_figure

    parts = [
        f"<p><b>{esc(outcome.parameter)}</b> boundary {esc(outcome.boundary.text())} ({esc(outcome.termination)}); {esc(outcome.requirement)}</p>"
    ]
    if outcome.trials:
        parts.append(_img(png_bytes(metric_figure(outcome)), esc(f"{outcome.parameter} against the metrics")))
    for label, trial in zip(("last pass", "first fail"), outcome.end_trials()):
        if trial is None or not Path(trial.artifacts.get("frame") or "").is_file():
            continue
        caption = esc(f"{label}: {with_unit(trial.value, outcome.boundary.unit)} ({trial_verdict(trial)})")
        parts.append(
            f"<figure>{_img(Path(trial.artifacts['frame']).read_bytes(), f'frame at {caption}')}<figcaption>{caption}</figcaption></figure>"
        )
    return "<div class='sal'>" + "".join(parts) + "</div>"


def _img(png: bytes, alt: str) -> str:
    """``<img>`` of ``png`` inline (``alt`` already escaped)."""
    return f"<img src='data:image/png;base64,{base64.b64encode(png).decode('ascii')}' alt='{alt}' style='max-width: 100%'>"
