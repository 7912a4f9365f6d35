"""A full disk at the end of a pytest session (issue 12, point 3): the inner session's conftest
makes every write under the history folder and the HTML report folder fail with ENOSPC. The
session still prints its results and its robustness table, exits with the tests' status, says in
one line per output which path could not be written and why, and writes the outputs it can
(the Markdown report); the next session, with room again, saves its history.

A full disk under the cache (issue 23, item 5) costs the cache alone: every test gets
its verdict, one warning names the cache folder and why, and nothing is left in it."""

from __future__ import annotations

from pathlib import Path

import pytest
from plugin_suites import CONFTEST, HEADER, SMALL_DATASET, output, project, run, write_tracked

#: every atomic write below a folder named in FULL fails like write(2) on a full disk
FULL_DISK = """
import errno
import os
from pathlib import Path

import sal_adapters.common.textfiles as textfiles

FULL = [Path(p) for p in os.environ.get("SAL_TEST_FULL", "").split(os.pathsep) if p]
_atomic_write = textfiles.atomic_write


def _full_disk(path, write, binary=False):
    if any(folder in Path(path).parents for folder in FULL):
        def write(handle, write=write):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    return _atomic_write(path, write, binary)


textfiles.atomic_write = _full_disk
"""

TESTS = """

@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 30, tolerance=5, max_trials=6)
def test_fog(sal_outcome):
    pass
"""


def test_a_full_disk_at_session_end_costs_only_the_outputs_it_hits(pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch) -> None:
    pytester.makeconftest(CONFTEST + SMALL_DATASET + FULL_DISK)
    write_tracked(pytester, {})
    pytester.makepyfile(test_suite=HEADER + TESTS)
    history, html, markdown = pytester.path / "history", pytester.path / "html", pytester.path / "md" / "report.md"
    monkeypatch.setenv("SAL_TEST_FULL", f"{history}:{html}")
    options = [
        "-p",
        "no:cacheprovider",
        "-p",
        "no:hypothesispytest",
        f"--sal-cache-dir={pytester.path / 'cache'}",
        f"--sal-history-dir={history}",
        f"--sal-report-html={html}",
        f"--sal-report-md={markdown}",
    ]

    full = pytester.runpytest_subprocess(*options, timeout=300)

    assert full.ret == 0, output(full)
    full.assert_outcomes(passed=1)
    text = output(full)
    assert "Traceback" not in text and "OSError" not in text
    assert "pytest-sal robustness boundaries" in text  # the table is still printed
    lines = [line for line in text.splitlines() if "not written" in line]
    assert len(lines) == 2, text
    assert lines[0].startswith(f"pytest-sal: history not written: cannot write {history}") and lines[0].endswith(
        ": No space left on device"
    )
    assert lines[1].startswith(f"pytest-sal: --sal-report-html not written: cannot write {html}") and lines[1].endswith(
        ": No space left on device"
    )
    assert ".sal-tmp" not in lines[1]  # the report's file, not its staging copy
    assert markdown.is_file() and "test_fog" in markdown.read_text()  # what could be written was
    assert [line for line in text.splitlines() if "pytest-sal: wrote" in line] == ["pytest-sal: wrote md/report.md"]
    assert not list(history.glob("*.json")) and not (html / "index.html").exists()
    assert not [p for p in [*history.rglob("*"), *html.rglob("*")] if ".sal-tmp" in p.name or p.suffix == ".tmp"]

    monkeypatch.delenv("SAL_TEST_FULL")
    room = pytester.runpytest_subprocess(*options, timeout=300)
    room.assert_outcomes(passed=1)
    assert "not written" not in output(room)
    assert sorted(line for line in output(room).splitlines() if "pytest-sal: wrote" in line) == [
        f"pytest-sal: wrote history/{next(history.glob('*.json')).name}",
        "pytest-sal: wrote html/index.html",
        "pytest-sal: wrote md/report.md",
    ]
    assert len(list(history.glob("*.json"))) == 1 and (html / "index.html").is_file()


#: the inner session's cache lies on a full disk (files are created, their bytes refused)
FULL_CACHE = f"""
import sys
sys.path.insert(0, {str(Path(__file__).parent)!r})
from faults import fill_disk_under
fill_disk_under(HERE / "cache")
"""

CACHED_TESTS = """

@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25)
def test_fog(sal_outcome):
    pass


@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 5)
def test_thick_fog(sal_outcome):
    pass
"""


def test_a_full_disk_under_the_cache_costs_the_cache_not_the_verdicts(pytester: pytest.Pytester) -> None:
    project(pytester, CACHED_TESTS)
    conftest = pytester.path / "conftest.py"
    conftest.write_text(conftest.read_text() + FULL_CACHE)

    html = pytester.path / "html"  # its trials' report images go to the cache: refused too
    result = run(pytester, ["-p", "no:xdist"], "-W", "always", f"--sal-report-html={html}")  # a subprocess: the patch dies with it

    result.assert_outcomes(passed=1, failed=1)  # test_thick_fog's requirement fails, as without a cache
    text, cache = output(result), pytester.path / "cache"
    assert "Traceback" not in text and "CacheError" not in text and "Errno" not in text, text
    assert text.count(f"the cache at {cache} cannot be written (No space left on device): ") == 1, text
    assert not [p for p in cache.rglob("*") if p.is_file()]  # no entry, no image, no .gitignore, no temporary file
    assert (html / "index.html").is_file()  # the report, without the images
