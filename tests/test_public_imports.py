"""The import lines the README's examples and example_suites/ use keep working after the
packages were reorganised: each runs in a fresh interpreter, and the README's short paths
(``pytest_sal.metrics``, ``pytest_sal.plots``) give the very objects of their real modules."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
IMPORT_LINE = re.compile(r"^(?:from [\w.]+ import [\w, ]+|import [\w.]+(?: as \w+)?)$")


def documented_imports() -> list[str]:
    """Every import line of the README's Python blocks and of the example suites."""
    lines: set[str] = set()
    readme = ROOT / "README.md"
    for block in re.findall(r"```python\n(.*?)```", readme.read_text(), re.S):
        lines.update(line.strip() for line in block.splitlines() if IMPORT_LINE.match(line.strip()))
    for path in sorted((ROOT / "example_suites").rglob("*.py")):
        lines.update(line.strip() for line in path.read_text().splitlines() if IMPORT_LINE.match(line.strip()))
    return sorted(line for line in lines if re.match(r"(from|import) (pytest_sal|sal_\w+)", line))


def test_the_documented_import_lines_are_found() -> None:
    lines = documented_imports()
    assert "from pytest_sal.metrics import evaluate, aggregate" in lines
    assert "from pytest_sal.plots import plot_trajectories, plot_ate_over_time" in lines
    assert len(lines) >= 8


@pytest.mark.parametrize("line", documented_imports())
def test_documented_import_works(line: str) -> None:
    result = subprocess.run([sys.executable, "-c", line], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert result.returncode == 0, result.stderr


def test_short_paths_are_the_real_objects() -> None:
    import pytest_sal.analysis.metrics as metrics
    import pytest_sal.analysis.plots as plots
    import pytest_sal.analysis.trajectory_errors as trajectory_errors
    import pytest_sal.metrics
    import pytest_sal.plots

    # what pytest_sal.metrics offered before the reorganisation, and where each name lives now
    before = {"AGGREGATED", "MIN_POSES", "Association", "AteResult", "ErrorStats", "RpeResult", "RunMetrics"}
    before |= {"aggregate", "associate", "ate", "default_max_diff", "relative_errors", "evaluate", "rpe", "scale_error"}
    assert before <= set(pytest_sal.metrics.__all__)
    for name in pytest_sal.metrics.__all__:
        home = metrics if name in metrics.__all__ else trajectory_errors
        assert getattr(pytest_sal.metrics, name) is getattr(home, name), name
    assert set(pytest_sal.plots.__all__) == set(plots.__all__)
    assert all(getattr(pytest_sal.plots, name) is getattr(plots, name) for name in plots.__all__)
