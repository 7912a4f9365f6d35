"""tools/import_graph.py, the layer and cycle check .ci/lint runs: it must see imports inside
functions and relative imports, count ``TYPE_CHECKING`` imports (annotation-only edges) in
cycles and layers, and rank modules by their longest layer prefix."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("import_graph", ROOT / "tools" / "import_graph.py")
assert spec is not None and spec.loader is not None
import_graph = importlib.util.module_from_spec(spec)
sys.modules["import_graph"] = import_graph
spec.loader.exec_module(import_graph)


def write(folder: Path, files: dict[str, str]) -> dict[str, Path]:
    modules = {}
    for name, text in files.items():
        path = folder / (name.replace(".", "/") + ".py")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        modules[name] = path
    return modules


def test_imports_inside_functions_and_relative_ones_are_seen(tmp_path: Path) -> None:
    modules = write(
        tmp_path,
        {
            "pytest_sal.engine.a": "def f():\n    from pytest_sal.report import b\n",
            "pytest_sal.report.b": "from . import c\n",
            "pytest_sal.report.c": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pytest_sal.engine import a\n",
        },
    )
    found = {(i.source, i.target, i.in_function, i.type_checking) for i in import_graph.collect_imports(modules)}
    assert found == {
        ("pytest_sal.engine.a", "pytest_sal.report.b", True, False),
        ("pytest_sal.report.b", "pytest_sal.report.c", False, False),
        ("pytest_sal.report.c", "pytest_sal.engine.a", False, True),
    }
    upward = [i for i in import_graph.collect_imports(modules) if import_graph.layer_of(i.target) > import_graph.layer_of(i.source)]
    assert [(i.source, i.target) for i in upward] == [("pytest_sal.engine.a", "pytest_sal.report.b")]


def test_cycles_count_every_level_type_checking_included(tmp_path: Path) -> None:
    Import = import_graph.Import
    edges = [Import("a", "b", 1, False, False), Import("b", "c", 1, True, False), Import("c", "a", 1, False, False)]
    assert import_graph.find_cycles(edges) == [["a", "b", "c"]]
    assert import_graph.annotation_edges(["a", "b", "c"], edges) == ""
    edges[2] = Import("c", "a", 1, False, True)
    assert import_graph.find_cycles(edges) == [["a", "b", "c"]]
    assert import_graph.annotation_edges(["a", "b", "c"], edges) == " (annotation-only: c -> a)"
    edges.append(Import("c", "a", 9, True, False))  # the same edge at run time too: not annotation-only
    assert import_graph.annotation_edges(["a", "b", "c"], edges) == ""


def test_an_annotation_only_cycle_fails_the_check(tmp_path: Path, monkeypatch, capsys) -> None:
    """The shape ``sal_modules.base`` / ``params`` / ``param_refs`` had: run-time imports one way,
    ``TYPE_CHECKING`` imports back."""
    modules = write(
        tmp_path,
        {
            "sal_modules.base": "from sal_modules.refs import Ref\n",
            "sal_modules.refs": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from sal_modules.base import Base\n",
        },
    )
    monkeypatch.setattr(import_graph, "all_modules", lambda: modules)
    assert import_graph.main([]) == 1
    out = capsys.readouterr().out
    assert "cycle: sal_modules.base <-> sal_modules.refs (annotation-only: sal_modules.refs -> sal_modules.base)" in out
    assert "1 under TYPE_CHECKING" in out


def test_an_upward_type_checking_import_is_upward(tmp_path: Path, monkeypatch, capsys) -> None:
    modules = write(
        tmp_path,
        {
            "sal_adapters.x": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pytest_sal.engine import y\n",
            "pytest_sal.engine.y": "",
        },
    )
    monkeypatch.setattr(import_graph, "all_modules", lambda: modules)
    assert import_graph.main([]) == 1
    assert "upward import: sal_adapters.x -> pytest_sal.engine.y line 3 (TYPE_CHECKING)" in capsys.readouterr().out


def test_layers_rank_by_the_longest_prefix() -> None:
    layer = import_graph.layer_of
    assert layer("sal_adapters.sequence") < layer("sal_modules.weather.fog") == layer("sal_wrappers.orbslam3.system")
    assert layer("sal_wrappers.orbslam3.system") < layer("pytest_sal.analysis.metrics") < layer("pytest_sal.engine.execution.trial_runner")
    assert layer("pytest_sal.engine.outcomes.outcome") < layer("pytest_sal.history.gate") < layer("pytest_sal.report.html")
    assert layer("pytest_sal.report.html") < layer("pytest_sal.cli.main") < layer("pytest_sal.plugin")


def test_pytest_is_imported_only_by_the_plugin_surface(tmp_path: Path) -> None:
    modules = write(tmp_path, {"pytest_sal.plugin": "import pytest\n", "pytest_sal.engine.x": "def f():\n    from _pytest import nodes\n"})
    assert import_graph.pytest_imports(modules) == ["pytest_sal.engine.x line 2 imports _pytest.nodes"]
