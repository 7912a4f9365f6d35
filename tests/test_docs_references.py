"""The documents name only modules and files that exist: every ``package/module.py`` path and
every dotted ``pytest_sal.x`` / ``sal_*.x`` name in README.md, ARCHITECTURE.md and
CONTRIBUTING.md resolves, so a file moved or split without its documents fails a test."""

from __future__ import annotations

import importlib
import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ("README.md", "ARCHITECTURE.md", "CONTRIBUTING.md")
PACKAGES = ("pytest_sal", "sal_adapters", "sal_modules", "sal_wrappers")
#: Names a how-to creates as its example (CONTRIBUTING.md: adding a ``haze`` module).
EXAMPLES = {"sal_modules.weather.haze"}
#: Subpackages a document may name a path from (``engine/outcomes/outcome.py``).
SUBPACKAGES = {p.name: p for package in PACKAGES for p in (ROOT / package).iterdir() if (p / "__init__.py").is_file()}


def paths(text: str) -> set[str]:
    """Backticked ``a/b.py`` paths whose first folder is a package or subpackage of ours."""
    found = set(re.findall(r"`([\w/]+/[\w]+\.py)(?::\w+)?`", text)) | set(re.findall(r"\(`([\w/]+/\w+\.py)`", text))
    return {p for p in found if p.split("/")[0] in (*PACKAGES, *SUBPACKAGES, "tests", "tools", "benchmarks")}


def dotted(text: str) -> set[str]:
    return set(re.findall(r"\b((?:pytest_sal|sal_adapters|sal_modules|sal_wrappers)(?:\.\w+)+)", text))


def resolves(name: str) -> bool:
    """``name`` is a module, or an attribute of the longest module prefix of it."""
    parts = name.split(".")
    for cut in range(len(parts), 0, -1):
        module = ".".join(parts[:cut])
        try:
            if importlib.util.find_spec(module) is None:
                continue
        except ModuleNotFoundError:  # a prefix that is a module, not a package
            continue
        obj = importlib.import_module(module)
        for attribute in parts[cut:]:
            if not hasattr(obj, attribute):
                return False
            obj = getattr(obj, attribute)
        return True
    return False


@pytest.mark.parametrize("doc", DOCS)
def test_every_named_path_exists(doc: str) -> None:
    text = (ROOT / doc).read_text()
    missing = []
    for path in sorted(paths(text)):
        first = path.split("/")[0]
        base = ROOT if first in (*PACKAGES, "tests", "tools", "benchmarks") else SUBPACKAGES[first].parent
        if not (base / path).is_file():
            missing.append(path)
    assert not missing, f"{doc} names files that do not exist: {missing}"


@pytest.mark.parametrize("doc", DOCS)
def test_every_dotted_name_resolves(doc: str) -> None:
    missing = [name for name in sorted(dotted((ROOT / doc).read_text())) if name not in EXAMPLES and not resolves(name)]
    assert not missing, f"{doc} names modules or attributes that do not exist: {missing}"


def test_the_checks_see_a_stale_name() -> None:
    assert paths("see `engine/outcomes/outcome.py` and `report/html.py`") == {"engine/outcomes/outcome.py", "report/html.py"}
    assert not (ROOT / "pytest_sal/report/html.py").exists()
    assert resolves("pytest_sal.engine.outcomes.outcome.Outcome") and not resolves("pytest_sal.report.html")
