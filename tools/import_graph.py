#!/usr/bin/env python3
"""The import graph of the four packages, checked against their layers.

Reads every ``.py`` file's ``import`` statements with ``ast`` (top level and inside functions,
``TYPE_CHECKING`` blocks marked as such) and reports:

* an **upward import**: a module importing from a higher layer (``LAYERS`` below, lowest first),
  ``TYPE_CHECKING`` imports included;
* a **pytest import below the plugin surface**: only the top-level modules of ``pytest_sal``
  (plugin, session, api, ...) may import ``pytest`` (or ``_pytest``, ``xdist``, ``pytest_html``);
* a **cycle** among modules (strongly connected components of more than one module, counting
  imports at every level). Imports under ``if TYPE_CHECKING:`` count too: they never run, but
  two modules whose types name each other are one room, and a cycle of annotations becomes a
  cycle of imports the day one of them is needed at run time. A cycle line names its
  annotation-only edges.

Exit status 1 when either exists, so ``.ci/run`` can hold the line. ``--dot FILE`` writes the
package-level graph in Graphviz form; ``--modules`` prints every module's imports.
"""

from __future__ import annotations

import argparse
import ast
import sys
from collections import defaultdict
from collections.abc import Iterable
from pathlib import Path

__all__ = ["LAYERS", "Import", "collect_imports", "find_cycles", "layer_of", "main"]

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("sal_adapters", "sal_modules", "sal_wrappers", "pytest_sal")

#: Layers, lowest first: a module may import from its own layer or any lower one. Matched by
#: the longest dotted prefix.
LAYERS: list[tuple[str, ...]] = [
    ("sal_adapters",),  # datasets, sequences, trajectories, shared errors and file helpers
    ("sal_modules", "sal_wrappers"),  # perturbations; SLAM systems
    ("pytest_sal.analysis",),  # pure algorithms: metrics, KITTI metrics, feature tracking, plots
    ("pytest_sal.store",),  # the content-addressed cache of runs and its keys
    ("pytest_sal.engine",),  # requirements, boundary search, trials, outcomes
    ("pytest_sal.history",),  # run history, regression checks, the gate
    ("pytest_sal.experiment",),  # YAML experiments as library functions
    ("pytest_sal.report",),  # terminal, Markdown, HTML, experiment page, formatting
    ("pytest_sal.cli",),  # the sal command: argparse and printing
    ("pytest_sal",),  # the plugin surface: plugin, session, api, testing, progress
]


#: Third-party modules that belong to the plugin surface only.
PYTEST_MODULES = ("pytest", "_pytest", "xdist", "pytest_html")


class Import:
    """One ``import`` statement: who imports what, at which line, and how."""

    def __init__(self, source: str, target: str, line: int, in_function: bool, type_checking: bool) -> None:
        self.source, self.target, self.line = source, target, line
        self.in_function, self.type_checking = in_function, type_checking

    def __repr__(self) -> str:
        where = " (in a function)" if self.in_function else ""
        where += " (TYPE_CHECKING)" if self.type_checking else ""
        return f"{self.source} -> {self.target} line {self.line}{where}"


def module_name(path: Path) -> str:
    """``pytest_sal/engine/search.py`` -> ``pytest_sal.engine.search``."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def all_modules() -> dict[str, Path]:
    """Every module of the four packages by dotted name."""
    return {module_name(p): p for package in PACKAGES for p in sorted((ROOT / package).rglob("*.py"))}


def resolve(target: str, modules: dict[str, Path]) -> str | None:
    """The longest known module that ``target`` names (``a.b.name`` -> ``a.b``)."""
    while target:
        if target in modules:
            return target
        target = target.rpartition(".")[0]
    return None


def collect_imports(modules: dict[str, Path]) -> list[Import]:
    """Every import between known modules, with its line and context."""
    found: list[Import] = []
    for name, path in modules.items():
        tree = ast.parse(path.read_text(), str(path))
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        _visit(tree.body, name, package, modules, found, in_function=False, type_checking=False)
    return found


def _visit(
    nodes: Iterable[ast.AST],
    source: str,
    package: str,
    modules: dict[str, Path],
    found: list[Import],
    in_function: bool,
    type_checking: bool,
) -> None:
    """Record the imports among ``nodes`` and their descendants."""
    for child in nodes:
        if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
            _visit(ast.iter_child_nodes(child), source, package, modules, found, True, type_checking)
            continue
        if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
            _visit(child.body, source, package, modules, found, in_function, True)
            _visit(child.orelse, source, package, modules, found, in_function, type_checking)
            continue
        if isinstance(child, (ast.Import, ast.ImportFrom)):
            for target in _targets(child, package):
                resolved = resolve(target, modules)
                if resolved and resolved != source:
                    found.append(Import(source, resolved, child.lineno, in_function, type_checking))
        _visit(ast.iter_child_nodes(child), source, package, modules, found, in_function, type_checking)


def _targets(statement: ast.Import | ast.ImportFrom, package: str) -> list[str]:
    """The dotted names an import statement asks for (relative ones resolved against ``package``)."""
    if isinstance(statement, ast.Import):
        return [alias.name for alias in statement.names]
    base = statement.module or ""
    if statement.level:
        anchor = package.split(".")
        anchor = anchor[: len(anchor) - (statement.level - 1)]
        base = ".".join(anchor + ([base] if base else []))
    return [f"{base}.{alias.name}" for alias in statement.names] or [base]


def pytest_imports(modules: dict[str, Path]) -> list[str]:
    """``module line N imports pytest`` for each module below the plugin surface that imports one
    of ``PYTEST_MODULES`` (at any level, ``TYPE_CHECKING`` blocks included)."""
    top = len(LAYERS) - 1
    found = []
    for name, path in modules.items():
        if layer_of(name) == top and name.count(".") == 1:
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                for target in _targets(node, name) if isinstance(node, ast.Import) or not node.level else []:
                    if target.split(".")[0] in PYTEST_MODULES:
                        found.append(f"{name} line {node.lineno} imports {target}")
    return found


def layer_of(module: str) -> int:
    """Index in ``LAYERS`` of the longest prefix naming ``module``."""
    best, best_len = -1, -1
    for index, prefixes in enumerate(LAYERS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > best_len:
                best, best_len = index, len(prefix)
    return best


def find_cycles(imports: list[Import]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), ``TYPE_CHECKING`` imports
    included. A package's ``__init__`` re-exporting its own submodules is not a cycle edge."""
    graph: dict[str, set[str]] = defaultdict(set)
    for imp in imports:
        if imp.target.startswith(imp.source + "."):
            continue
        graph[imp.source].add(imp.target)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def strongconnect(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in graph.get(node, ()):
            if nxt not in index:
                strongconnect(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    sys.setrecursionlimit(10000)
    for node in list(graph):
        if node not in index:
            strongconnect(node)
    return components


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--dot", type=Path, help="write the package-level graph to this Graphviz file")
    parser.add_argument("--modules", action="store_true", help="print every module's imports")
    args = parser.parse_args(argv)
    modules = all_modules()
    imports = collect_imports(modules)
    upward = [imp for imp in imports if layer_of(imp.target) > layer_of(imp.source)]
    cycles = find_cycles(imports)
    pytest_below = pytest_imports(modules)
    if args.modules:
        for imp in sorted(imports, key=lambda i: (i.source, i.line)):
            print(imp)
    if args.dot:
        edges = {(_package(i.source), _package(i.target)) for i in imports if _package(i.source) != _package(i.target)}
        lines = ["digraph imports {", "  rankdir=BT;"] + [f'  "{a}" -> "{b}";' for a, b in sorted(edges)] + ["}"]
        args.dot.write_text("\n".join(lines) + "\n")
    function_level = sum(imp.in_function for imp in imports)
    annotation_only = sum(imp.type_checking for imp in imports)
    print(
        f"{len(modules)} modules, {len(imports)} imports between them "
        f"({function_level} inside functions, {annotation_only} under TYPE_CHECKING; all count)"
    )
    for imp in upward:
        print(f"upward import: {imp}  (layer {layer_of(imp.source)} imports layer {layer_of(imp.target)})")
    for cycle in cycles:
        print(f"cycle: {' <-> '.join(cycle)}{annotation_edges(cycle, imports)}")
    for line in pytest_below:
        print(f"pytest below the plugin surface: {line}")
    if not upward and not cycles and not pytest_below:
        print("no upward import, no cycle, pytest only in the plugin surface")
    return 1 if upward or cycles or pytest_below else 0


def annotation_edges(cycle: list[str], imports: list[Import]) -> str:
    """`` (annotation-only: a -> b, ...)`` for the edges of ``cycle`` that exist only under
    ``TYPE_CHECKING``, else ``""``."""
    members = set(cycle)
    edges: dict[tuple[str, str], bool] = {}
    for imp in imports:
        if imp.source in members and imp.target in members:
            edge = (imp.source, imp.target)
            edges[edge] = edges.get(edge, True) and imp.type_checking
    only = sorted(f"{a} -> {b}" for (a, b), annotation in edges.items() if annotation)
    return f" (annotation-only: {', '.join(only)})" if only else ""


def _package(module: str) -> str:
    """The subpackage a module belongs to, for the package-level graph."""
    parts = module.split(".")
    return ".".join(parts[:2]) if parts[0] == "pytest_sal" and len(parts) > 2 else parts[0] if parts[0] != "pytest_sal" else module


if __name__ == "__main__":
    sys.exit(main())
