"""The documents and the code's own words name only modules, files and attributes that exist.

* Every ``package/module.py`` path and every dotted ``pytest_sal.x`` / ``sal_*.x`` name in
  README.md, ARCHITECTURE.md and CONTRIBUTING.md resolves, so a file moved or split without
  its documents fails a test.
* Every docstring (and attribute docstring) and every comment of the four packages, ``tools/``
  and ``benchmarks/`` is held to the same: a dotted name of our packages resolves (module,
  then attribute by attribute), and so does a class-qualified reference written
  ``Class.attribute`` in backticks or in a ``:class:`` / ``:func:`` / ``:meth:`` role, where
  ``Class`` is defined or imported in that file or is a class or function of our packages (a
  name found nowhere is someone else's and is left alone; a role's name must be found). A
  bare ``:meth:`name``` inside a class is looked up on that class.
* In both, a backticked path relative to a subpackage, ``engine.search.bisection`` or
  ``search.bisection.SearchSpace`` (a subpackage's name, then one of our module names),
  resolves under a subpackage of that name.

Docstrings are read with ``ast`` and comments with ``tokenize``, so code and string data
(an error message naming a user's module) are not mistaken for prose."""

from __future__ import annotations

import ast
import dataclasses
import importlib
import importlib.util
import inspect
import io
import re
import textwrap
import tokenize
from collections.abc import Iterator
from functools import cache
from pathlib import Path
from typing import NamedTuple

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ("README.md", "ARCHITECTURE.md", "CONTRIBUTING.md")
PACKAGES = ("pytest_sal", "sal_adapters", "sal_modules", "sal_wrappers")
#: Folders whose docstrings and comments are checked: the packages and the scripts beside them.
SOURCE_FOLDERS = (*PACKAGES, "tools", "benchmarks")
#: Names a how-to creates as its example (CONTRIBUTING.md: adding a ``haze`` module).
EXAMPLES = {"sal_modules.weather.haze"}
#: Backticked names that are not Python, by file: keys of ORB-SLAM3's settings file.
NOT_PYTHON = {"sal_wrappers/orbslam3/settings.py": {"Camera.fps"}}
#: Subpackages a document may name a path from (``engine/outcomes/outcome.py``).
SUBPACKAGES = {p.name: p for package in PACKAGES for p in (ROOT / package).iterdir() if (p / "__init__.py").is_file()}

_DOTTED = re.compile(r"\b((?:pytest_sal|sal_adapters|sal_modules|sal_wrappers)(?:\.\w+)+)")
#: ``Class.attribute`` (optionally called) in double or single backticks.
_BACKTICKED = re.compile(r"(?<!`)``?([A-Z]\w*(?:\.\w+)+)(?:\([^`]*\))?``?(?!`)")
#: A Sphinx role: ``:class:`ContentCache```, ``:meth:`evict```, ``:func:`a.b.c```.
_ROLE = re.compile(r":(class|func|meth|attr|exc|mod|data):`~?([\w.]+)(?:\(\))?`")
#: A lower-case dotted name in backticks (``engine.search``, ``run_job.failed_output()``).
_RELATIVE = re.compile(r"`([a-z_]\w*(?:\.\w+)+)(?:\([^`]*\))?`")


def paths(text: str) -> set[str]:
    """Backticked ``a/b.py`` paths whose first folder is a package or subpackage of ours."""
    found = set(re.findall(r"`([\w/]+/[\w]+\.py)(?::\w+)?`", text)) | set(re.findall(r"\(`([\w/]+/\w+\.py)`", text))
    return {p for p in found if p.split("/")[0] in (*PACKAGES, *SUBPACKAGES, "tests", "tools", "benchmarks")}


def dotted(text: str) -> set[str]:
    """Dotted names of our packages, and backticked ones relative to a subpackage."""
    return set(_DOTTED.findall(text)) | {name for name in _RELATIVE.findall(text) if relative_targets(name)}


@cache
def _modules() -> tuple[dict[str, set[str]], set[str]]:
    """Our subpackages by their last name (``search`` -> ``pytest_sal.engine.search``), and the
    last names of all our modules and subpackages."""
    modules = [m for m in map(module_of, source_files()) if m]
    subpackages: dict[str, set[str]] = {}
    for module in modules:
        if any(other.startswith(module + ".") for other in modules) and "." in module:
            subpackages.setdefault(module.rpartition(".")[2], set()).add(module)
    return subpackages, {m.rpartition(".")[2] for m in modules}


def relative_targets(name: str) -> list[str]:
    """The full names ``name`` may stand for when it starts with a subpackage's name followed by
    a module's (``engine.quantity`` -> ``pytest_sal.engine.quantity``); ``[]`` when it does not."""
    subpackages, names = _modules()
    first, _, rest = name.partition(".")
    if _DOTTED.fullmatch(name) or first not in subpackages or rest.partition(".")[0] not in names:
        return []
    return [f"{package}.{rest}" for package in sorted(subpackages[first])]


def resolves_any(name: str) -> bool:
    """``name`` resolves, as written or (relative to a subpackage) under a subpackage."""
    targets = relative_targets(name)
    return any(map(resolves, targets)) if targets else resolves(name)


def resolves(name: str) -> bool:
    """``name`` is a module, or an attribute chain on the longest module prefix of it. An
    attribute of a class may be one its instances get (a dataclass field, an annotation, a
    ``self.x = ...`` in a method); the chain is not followed past one."""
    parts = name.split(".")
    for cut in range(len(parts), 0, -1):
        module = ".".join(parts[:cut])
        try:
            if importlib.util.find_spec(module) is None:
                continue
        except (ModuleNotFoundError, ValueError):  # a prefix that is a module, not a package
            continue
        obj = importlib.import_module(module)
        for attribute in parts[cut:]:
            if hasattr(obj, attribute):
                obj = getattr(obj, attribute)
            else:
                return isinstance(obj, type) and attribute in instance_attributes(obj)
        return True
    return False


def instance_attributes(cls: type) -> set[str]:
    """Names instances of ``cls`` carry that the class itself may not: dataclass fields,
    annotations, ``__slots__`` and ``self.name = ...`` assignments in its methods (MRO included)."""
    names: set[str] = set()
    for klass in cls.__mro__:
        names |= set(vars(klass).get("__annotations__", {})) | set(vars(klass).get("__slots__", ()))
        if dataclasses.is_dataclass(klass):
            names |= {f.name for f in dataclasses.fields(klass)}
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError, SyntaxError):
            continue
        for node in ast.walk(tree):
            target = node.value if isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store) else None
            if isinstance(target, ast.Name) and target.id == "self":
                names.add(node.attr)
    return names


# -- docstrings and comments --------------------------------------------------------------------


class Prose(NamedTuple):
    """One docstring or comment: where it is, the class it sits in (if any), its text."""

    where: str
    owner: str | None
    text: str


def source_files() -> list[Path]:
    return [p for folder in SOURCE_FOLDERS for p in sorted((ROOT / folder).rglob("*.py"))]


def module_of(path: Path) -> str | None:
    """The dotted module name of a package file; ``None`` for a script in tools/ or benchmarks/."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[0] not in PACKAGES:
        return None
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def prose(source: str, where: str) -> Iterator[Prose]:
    """Every string statement (docstrings, attribute docstrings) and every comment of ``source``."""
    tree = ast.parse(source)
    owners: dict[int, str] = {}
    for node in ast.walk(tree):  # outer classes first, so an inner class has the last word
        if isinstance(node, ast.ClassDef):
            for child in ast.walk(node):
                if isinstance(child, ast.Expr):
                    owners[id(child)] = node.name
    for node in ast.walk(tree):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            yield Prose(f"{where}:{node.lineno}", owners.get(id(node)), node.value.value)
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            yield Prose(f"{where}:{token.start[0]}", None, token.string)


def namespace(tree: ast.Module, module: str | None) -> dict[str, str | None]:
    """Top-level names of a file -> the dotted name they stand for (``None``: defined in a script)."""
    names: dict[str, str | None] = {}
    for node in tree.body:
        if isinstance(node, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            names[node.name] = f"{module}.{node.name}" if module else None
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            for alias in node.names:
                names[alias.asname or alias.name] = f"{node.module}.{alias.name}"
        elif isinstance(node, ast.If):  # if TYPE_CHECKING: imports
            for child in node.body:
                if isinstance(child, ast.ImportFrom) and child.module and not child.level:
                    for alias in child.names:
                        names.setdefault(alias.asname or alias.name, f"{child.module}.{alias.name}")
    return names


@cache
def our_names() -> dict[str, list[str]]:
    """Every top-level class and function of the four packages by its bare name."""
    index: dict[str, list[str]] = {}
    for path in source_files():
        module = module_of(path)
        if module is None:
            continue
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
                index.setdefault(node.name, []).append(f"{module}.{node.name}")
    return index


def references(text: str) -> Iterator[tuple[str, bool]]:
    """``(name, must_exist)`` for each reference in ``text``: dotted names of our packages,
    backticked ``Class.attribute`` ones and the names of roles (which must be found)."""
    for name in _DOTTED.findall(text):
        yield name, True
    for name in _BACKTICKED.findall(text):
        if not _DOTTED.fullmatch(name):
            yield name, False
    for _role, name in _ROLE.findall(text):
        if not _DOTTED.fullmatch(name):
            yield name, True
    for name in _RELATIVE.findall(text):
        if relative_targets(name):
            yield name, True


def class_members(tree: ast.Module) -> dict[str, set[str]]:
    """Each class of a file -> the names its body defines and its methods set on ``self``."""
    members: dict[str, set[str]] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef):
            found = members.setdefault(node.name, set())
            for child in ast.walk(node):
                if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and child is not node:
                    found.add(child.name)
                elif isinstance(child, ast.Name) and isinstance(child.ctx, ast.Store):
                    found.add(child.id)
                elif isinstance(child, ast.Attribute) and isinstance(child.ctx, ast.Store):
                    found.add(child.attr)
    return members


def stale_names(source: str, where: str, module: str | None) -> list[str]:
    """``file:line name`` for each reference in the docstrings and comments of ``source`` that
    does not resolve."""
    tree = ast.parse(source)
    names, members = namespace(tree, module), class_members(tree)
    stale = []
    for piece in prose(source, where):
        for name, must_exist in references(piece.text):
            if name in EXAMPLES | NOT_PYTHON.get(where, set()) or _reference_resolves(
                name, must_exist, names, members, piece.owner, module
            ):
                continue
            stale.append(f"{piece.where} {name}")
    return stale


def _reference_resolves(
    name: str, must_exist: bool, names: dict[str, str | None], members: dict[str, set[str]], owner: str | None, module: str | None
) -> bool:
    if _DOTTED.fullmatch(name) or relative_targets(name):
        return resolves_any(name)
    first, _, rest = name.partition(".")
    if owner and not rest and first not in names and first not in our_names():  # :meth:`evict` in a class
        return first in members.get(owner, set()) or (module is not None and resolves(f"{module}.{owner}.{first}"))
    if first in names:
        target = names[first]
        if target is None:  # a class of a script: not imported here
            return True
        if target.split(".")[0] not in PACKAGES:  # someone else's (pathlib.Path.exists)
            return resolves(f"{target}.{rest}" if rest else target)
        candidates = [target]
    elif first in our_names():
        candidates = our_names()[first]
    else:
        return not must_exist
    return any(resolves(f"{c}.{rest}" if rest else c) for c in candidates)


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
    missing = [name for name in sorted(dotted((ROOT / doc).read_text())) if name not in EXAMPLES and not resolves_any(name)]
    assert not missing, f"{doc} names modules or attributes that do not exist: {missing}"


@pytest.mark.parametrize("folder", SOURCE_FOLDERS)
def test_docstrings_and_comments_name_what_exists(folder: str) -> None:
    stale = []
    for path in source_files():
        if path.relative_to(ROOT).parts[0] == folder:
            stale += stale_names(path.read_text(), str(path.relative_to(ROOT)), module_of(path))
    assert not stale, "docstrings or comments name what does not exist:\n" + "\n".join(stale)


def test_the_checks_see_a_stale_name() -> None:
    assert paths("see `engine/outcomes/outcome.py` and `report/html.py`") == {"engine/outcomes/outcome.py", "report/html.py"}
    assert not (ROOT / "pytest_sal/report/html.py").exists()
    assert resolves("pytest_sal.engine.outcomes.outcome.Outcome") and not resolves("pytest_sal.report.html")
    assert resolves("pytest_sal.engine.outcomes.outcome.Outcome.verdict")  # a dataclass field
    assert dotted("on `engine.quantity`, `outcomes.quantity`, `boundary.noisy`") == {"engine.quantity", "outcomes.quantity"}
    assert not resolves_any("engine.quantity") and resolves_any("outcomes.quantity.with_unit")
    source = '''"""Votes live in ``pytest_sal.votes``; see :class:`ContentCache` and ``Path.cwd``."""
from pathlib import Path

from pytest_sal.engine.execution.trial_runner import TrialRunner


class Gone:
    """Unlike ``TrialRunner._run``, ``TrialRunner.add_runs`` exists; :meth:`missing` does not."""

    def present(self) -> None:
        """:meth:`present` is here, :class:`NoSuchClass` is nowhere, ``Unknown.x`` is not ours."""
        x = "pytest_sal.in_a_string_not_prose"  # but pytest_sal.engine.nothing is in a comment
        # ``search.bisection.boundary_search`` is here, ``engine.bisection`` is not, ``fog.visibility_m`` is no path
'''
    assert stale_names(source, "example.py", "pytest_sal.example") == [
        "example.py:1 pytest_sal.votes",
        "example.py:8 TrialRunner._run",
        "example.py:8 missing",
        "example.py:11 NoSuchClass",
        "example.py:12 pytest_sal.engine.nothing",
        "example.py:13 engine.bisection",
    ]
