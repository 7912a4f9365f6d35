"""pytest-html integration (``pytest_sal.html_extras``): with ``--html``, a robustness test's row
carries its boundary, the metric plot and the example frames at the boundary's ends as inline
base64 PNG; other rows carry none. pytest-html 4 keeps the rows as JSON in the ``data-jsonblob``
attribute of ``#data-container`` (its script draws them), so the test reads that."""

from __future__ import annotations

import base64
import html
import json
import re
from pathlib import Path
from typing import Any

import pytest
from plugin_suites import project, run

pytest.importorskip("pytest_html", reason="pytest-html is an optional integration (the test extra installs it)")

SUITE = """

@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25, tolerance=4)
def test_search(sal_outcome):
    pass


@sal.sweep(fog.visibility_m, H=10)
@sal.require(tracking_rate >= 0.5)
def test_level(sal_trial):
    pass


def test_plain():
    pass
"""

PNG = re.compile(r"<img src='data:image/png;base64,([A-Za-z0-9+/=]+)' alt='([^']*)'")


def rows(report: Path) -> dict[str, str]:
    """Test id -> the HTML extras of its call row."""
    blob = re.search(r'id="data-container"\s+data-jsonblob="([^"]*)"', report.read_text())
    assert blob, "no data-jsonblob in the pytest-html report"
    tests: dict[str, list[dict[str, Any]]] = json.loads(html.unescape(blob.group(1)))["tests"]
    return {
        nodeid.split("::")[-1]: "".join(e["content"] for r in found for e in r.get("extras", []) if e["format_type"] == "html")
        for nodeid, found in tests.items()
    }


@pytest.mark.parametrize("mode", [pytest.param([], id="serial"), pytest.param(["-n", "2"], id="xdist")])
def test_robustness_rows_carry_boundary_plot_and_frames(pytester: pytest.Pytester, mode: list[str]) -> None:
    project(pytester, SUITE)
    result = run(pytester, mode, "--html=report.html")
    result.assert_outcomes(passed=2, failed=1)
    found = rows(pytester.path / "report.html")
    assert set(found) == {"test_search", "test_level[H-fog.visibility_m=10]", "test_plain"}

    search = found["test_search"]
    assert "<b>fog.visibility_m</b> boundary 17.5-20 m (tolerance); tracking_rate &gt;= 0.5 wherever fog.visibility_m &gt;= 25 m" in search
    images = PNG.findall(search)
    assert [alt for _, alt in images] == [
        "fog.visibility_m against the metrics",
        "frame at last pass: 20 m (pass)",
        "frame at first fail: 17.5 m (fail)",
    ]
    for data, _ in images:
        png = base64.b64decode(data, validate=True)
        assert png.startswith(b"\x89PNG\r\n\x1a\n") and len(png) > 1000

    level = found["test_level[H-fog.visibility_m=10]"]
    assert "boundary beyond 10 m (failed everywhere searched) (single)" in level
    assert [alt for _, alt in PNG.findall(level)] == ["fog.visibility_m against the metrics", "frame at first fail: 10 m (fail)"]
    assert found["test_plain"] == ""


def test_registered_only_for_an_html_report(pytester: pytest.Pytester) -> None:
    assert pytester.parseconfigure("--html=r.html").pluginmanager.get_plugin("sal-html") is not None
    assert pytester.parseconfigure().pluginmanager.get_plugin("sal-html") is None  # no rows to render
    assert pytester.parseconfigure("-p", "no:html").pluginmanager.get_plugin("sal-html") is None
