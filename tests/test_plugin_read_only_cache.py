"""A read-only cache (a shared one mounted read-only) serves what it holds to a
pytest session: no SLAM run for a cached trial, one warning, nothing written (issue 12)."""

from __future__ import annotations

from pathlib import Path

import pytest
from faults import stamps
from plugin_suites import calls, project, run

TESTS = """
@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25)
def test_fog(sal_outcome):
    pass
"""

#: the inner session's cache is a read-only mount (simulated: root ignores file modes)
READ_ONLY = f"""
import sys
sys.path.insert(0, {str(Path(__file__).parent)!r})
from faults import refuse_writes_under
refuse_writes_under(HERE / "cache")
"""


def test_a_read_only_cache_serves_a_session(pytester: pytest.Pytester) -> None:
    project(pytester, TESTS)
    run(pytester, []).assert_outcomes(passed=1)
    runs, before = calls(pytester), stamps(pytester.path / "cache")
    assert runs > 0
    conftest = pytester.path / "conftest.py"
    conftest.write_text(conftest.read_text() + READ_ONLY)
    result = run(pytester, ["-p", "no:xdist"], "-W", "always")  # a subprocess: the patch dies with it
    result.assert_outcomes(passed=1)
    assert calls(pytester) == runs  # every trial served from the cache, no warning
    assert "cannot be written" not in result.stdout.str()
    suite = pytester.path / "test_suite.py"
    suite.write_text(suite.read_text() + TESTS.replace("test_fog", "test_fog_30").replace(">= 25", ">= 30"))
    result = run(pytester, ["-p", "no:xdist"], "-W", "always")
    result.assert_outcomes(passed=2)
    assert calls(pytester) > runs  # test_fog_30's new trials ran, and were not stored
    assert stamps(pytester.path / "cache") == before
    text = result.stdout.str()
    assert (
        text.count("cannot be written (Read-only file system): the entries it holds are used, new results are computed and not stored") == 1
    ), text
