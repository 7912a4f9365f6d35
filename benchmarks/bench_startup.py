"""Start-up cost of pytest-sal: what every pytest session pays for the plugin, and ``sal --help``.

pytest imports the plugin (entry point ``pytest11: sal``) in every session of an environment
where pytest-sal is installed, robustness tests or not. Timed, each in a fresh process, in a
folder holding one plain test file:

* ``pytest`` on that file, with the plugin and with ``-p no:sal``; the plugin's cost is the
  median of the paired differences (the two runs of a repeat run back to back, so machine load
  hits both alike). Target: under 50 ms;
* ``sal --help`` (``python -m pytest_sal.cli.main --help``);
* ``python -c "import pytest_sal.plugin"``.

Each run is timed twice: wall clock, and the CPU time (user + system) of the process, which a
machine busy with other jobs inflates far less.

``--before DIR`` times a second copy of the packages too (an older checkout, e.g.
``git archive dfe0b65 | tar -x -C /tmp/sal-before``), interleaved with this checkout repeat by
repeat, so a busy machine slows both alike. Each code tree is put first on ``PYTHONPATH``.
Reports the median and the interquartile range in ms; ``--write`` replaces the start-up
section of benchmarks/RESULTS.md. Run from the repository root:

    .venv/bin/python benchmarks/bench_startup.py --repeats 31 --before /tmp/sal-before --write
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from results_file import write_section  # benchmarks/ is on sys.path when run as a script

ROOT = Path(__file__).resolve().parents[1]

#: What is timed: label -> arguments after the Python executable.
COMMANDS = {
    "pytest, 1 plain test": ["-m", "pytest", "test_plain.py"],
    "pytest -p no:sal": ["-m", "pytest", "-p", "no:sal", "test_plain.py"],
    "sal --help": ["-m", "pytest_sal.cli.main", "--help"],
    "import pytest_sal.plugin": ["-c", "import pytest_sal.plugin"],
}
#: The paired difference reported as the plugin's cost: (with, without).
PLUGIN_COST = ("pytest, 1 plain test", "pytest -p no:sal")


def run_once(args: list[str], tree: Path, folder: Path) -> tuple[float, float]:
    """Wall and CPU time (s, user + system) of ``python ARGS`` in ``folder`` with ``tree``
    first on ``PYTHONPATH``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    env["PYTHONPATH"] = str(tree)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run([sys.executable, *args], cwd=folder, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)


def measure(trees: dict[str, Path], repeats: int) -> dict[tuple[str, str], list[tuple[float, float]]]:
    """(wall, CPU) seconds per (tree, command), ``repeats`` each; every repeat runs every command of every
    tree once, trees and commands in reverse order every other repeat, after one untimed
    warm-up run of each (bytecode caches)."""
    pairs = [(name, label) for name in trees for label in COMMANDS]
    times: dict[tuple[str, str], list[tuple[float, float]]] = {pair: [] for pair in pairs}
    with tempfile.TemporaryDirectory(prefix="sal-startup-") as tmp:
        folder = Path(tmp)
        (folder / "test_plain.py").write_text("def test_plain():\n    assert True\n")
        for name, label in pairs:
            run_once(COMMANDS[label], trees[name], folder)
        for r in range(repeats):
            for name, label in pairs if r % 2 == 0 else pairs[::-1]:
                times[(name, label)].append(run_once(COMMANDS[label], trees[name], folder))
    return times


def summary(values: list[float]) -> str:
    """``median (p25-p75)`` in ms."""
    q1, med, q3 = statistics.quantiles([v * 1e3 for v in values], n=4, method="inclusive")
    return f"{med:.0f} ({q1:.0f}-{q3:.0f})"


def table(trees: dict[str, Path], times: dict[tuple[str, str], list[tuple[float, float]]]) -> str:
    """Markdown: one row per command plus the plugin's paired cost; wall, then CPU, per tree."""
    columns = [(clock, k, name) for k, clock in enumerate(("wall", "CPU")) for name in trees]
    lines = [
        "| ms, median (p25-p75) | " + " | ".join(f"{name} {clock}" for clock, _, name in columns) + " |",
        "|---|" + "---:|" * len(columns),
    ]
    for label in COMMANDS:
        lines.append(f"| `{label}` | " + " | ".join(summary([t[k] for t in times[(name, label)]]) for _, k, name in columns) + " |")
    with_plugin, without = PLUGIN_COST
    cost = [summary([a[k] - b[k] for a, b in zip(times[(name, with_plugin)], times[(name, without)])]) for _, k, name in columns]
    lines.append("| **plugin cost** (paired: with - without) | " + " | ".join(f"**{c}**" for c in cost) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=21, help="timed runs per command and code tree (default 21)")
    parser.add_argument("--before", type=Path, metavar="DIR", help="another checkout to time beside this one (its packages)")
    parser.add_argument("--write", action="store_true", help="replace the start-up section of benchmarks/RESULTS.md")
    args = parser.parse_args()
    if args.repeats < 2:
        parser.error(f"--repeats must be >= 2 (quartiles), got {args.repeats}")
    if args.before is not None and not (args.before / "pytest_sal" / "plugin.py").is_file():
        parser.error(f"--before {args.before}: no pytest_sal/plugin.py there; give a checkout of pytest-sal")
    trees = ({"before": args.before.resolve()} if args.before else {}) | {"after" if args.before else "this checkout": ROOT}
    load_start = os.getloadavg()[0]
    times = measure(trees, args.repeats)
    header = (
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; load average "
        f"{load_start:.1f} at the start, {os.getloadavg()[0]:.1f} at the end (other jobs were running). {args.repeats} fresh "
        f"processes per command and tree, interleaved. Command: `python benchmarks/bench_startup.py --repeats {args.repeats}"
        + (" --before DIR` (DIR: the code before the change)" if args.before else "`")
    )
    result = table(trees, times)
    print(header + "\n\n" + result)
    if args.write:
        write_section("startup", "Start-up cost of the plugin (issue 13)", header + "\n\n" + result)


if __name__ == "__main__":
    main()
