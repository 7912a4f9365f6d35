"""Time limits the test suite used to assert, measured here instead of failing tests on a busy machine.

The tests keep what was computed (the one-line error, the killed process group, the items the
producer ran ahead, the crack overlay); the seconds they took are measured by this script
against the targets below:

* a hostile experiment config (a YAML alias bomb, 1000-deep nesting, 300 perturbations, a
  100 000-character name) is rejected in under 1 s of CPU time (``load_config``);
* the cracked-lens pattern of one 1241x376 lens is built in under 1 s of CPU time;
* a ``command`` system that hangs past its 1 s timeout is killed with its process group and
  its result returned within 4 s after the timeout;
* frame production in ``prefetched`` overlaps consumption: 20 frames of 20 ms production and
  20 ms tracking take under 0.75 of the 0.8 s they take one after the other.

Each figure is the worst (CPU, kill delay) or the median (overlap) of ``--repeats`` runs.
``--write`` replaces the time-limits section of benchmarks/RESULTS.md. Run from the
repository root:

    .venv/bin/python benchmarks/bench_time_limits.py --repeats 5 --write
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from functools import partial
from pathlib import Path

import yaml
from results_file import write_section  # benchmarks/ is on sys.path when run as a script

ROOT = Path(__file__).resolve().parents[1]
VALID_CONFIG = ROOT / "example_suites" / "configs" / "fog_rain_urban.yaml"
HANG = "import sys, subprocess, time\nsubprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'])\ntime.sleep(60)\n"


def alias_bomb(levels: int) -> str:
    """``levels`` levels of nine YAML aliases each: 9**levels strings once expanded."""
    text = 'l0: &l0 ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n'
    return text + "".join(f"l{i}: &l{i} [{','.join([f'*l{i - 1}'] * 9)}]\n" for i in range(1, levels))


def hostile_configs() -> dict[str, str]:
    """Config texts that ``load_config`` must reject quickly, by what makes them hostile."""
    valid = VALID_CONFIG.read_text()
    config = yaml.safe_load(valid)
    many = dict(config, perturbations=[{"name": f"p{i}", "type": "fog"} for i in range(300)])
    long_name = dict(config, experiment={**config["experiment"], "name": "x" * 100_000})
    return {
        "alias bomb (10^9 strings) before a valid config": alias_bomb(9) + valid,
        "1000-deep nesting": "experiment: " + "[" * 1000 + "]" * 1000 + "\n",
        "300 perturbations": yaml.safe_dump(many, sort_keys=False),
        "a 100 000-character experiment name": yaml.safe_dump(long_name, sort_keys=False),
    }


def rejection_cpu_s(text: str, folder: Path) -> float:
    """CPU seconds ``load_config`` takes to reject ``text`` (it must raise ``ConfigError``)."""
    from pytest_sal.experiment.config import load_config
    from pytest_sal.experiment.yaml_loader import ConfigError

    path = folder / "hostile.yaml"
    path.write_text(text)
    start = time.process_time()
    try:
        load_config(path)
    except ConfigError:
        return time.process_time() - start
    raise AssertionError(f"{path} was accepted")


def crack_build_cpu_s() -> float:
    """CPU seconds of building the crack overlay of one 1241x376 lens."""
    from sal_adapters import open_dataset
    from sal_modules import ModuleContext, create

    module = create("cracked_lens")
    module.setup(ModuleContext(sequence=open_dataset("synthetic", scene="urban", frames=3), seed=1))
    start = time.process_time()
    module.build("left", 376, 1241)
    return time.process_time() - start


def kill_delay_s(folder: Path) -> float:
    """Seconds between a hung ``command`` system's 1 s timeout and its returned result."""
    from sal_adapters import open_dataset
    from sal_wrappers import create

    script = folder / "hang.py"
    script.write_text(HANG)
    sequence = open_dataset("synthetic", scene="indoor", frames=2, sensor="rgbd")
    system = create("command", argv=[sys.executable, str(script)], sensor="mono", layout="folder")
    result = system.run(sequence, folder / "work", timeout=1.0)
    assert result.failure == "timed out after 1 s and was killed", result.failure
    return result.wall_time_s - 1.0


def overlap_share() -> float:
    """Wall time of 20 frames through ``prefetched`` (20 ms to produce, 20 ms to track each)
    as a share of the 0.8 s they take one after the other."""
    from sal_wrappers.prefetch import prefetched

    def frames() -> Iterator[int]:
        for i in range(20):
            time.sleep(0.02)
            yield i

    start = time.perf_counter()
    for _ in prefetched(frames(), ahead=3):
        time.sleep(0.02)
    return (time.perf_counter() - start) / (20 * 0.04)


def measure(repeats: int) -> list[tuple[str, str, float, str]]:
    """Rows (what, target, measured, unit): the worst of ``repeats`` runs, the median for the overlap."""
    rows: list[tuple[str, str, float, str]] = []
    with tempfile.TemporaryDirectory(prefix="sal-limits-") as tmp:
        folder = Path(tmp)
        for what, text in hostile_configs().items():
            rows.append((f"config rejected: {what}", "< 1000 ms CPU", worst(partial(rejection_cpu_s, text, folder), repeats) * 1e3, "ms"))
        rows.append(("cracked_lens overlay built, 1241x376", "< 1000 ms CPU", worst(crack_build_cpu_s, repeats) * 1e3, "ms"))
        rows.append(("hung command system: result after the timeout", "< 4 s", worst(partial(kill_delay_s, folder), repeats), "s"))
    rows.append(("prefetched: overlapped / serial wall time", "< 0.75", statistics.median(overlap_share() for _ in range(repeats)), ""))
    return rows


def worst(run: Callable[[], float], repeats: int) -> float:
    """The largest of ``repeats`` results of ``run`` (after one untimed warm-up run)."""
    run()
    return max(run() for _ in range(repeats))


def table(rows: list[tuple[str, str, float, str]]) -> str:
    lines = ["| what | target | measured |", "|---|---|---:|"]
    lines += [
        f"| {what} | {target} | {value:.{0 if unit == 'ms' else 2}f}{' ' + unit if unit else ''} |" for what, target, value, unit in rows
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per figure (default 5)")
    parser.add_argument("--write", action="store_true", help="replace the time-limits section of benchmarks/RESULTS.md")
    args = parser.parse_args()
    load_start = os.getloadavg()[0]
    rows = measure(args.repeats)
    header = (
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; load average "
        f"{load_start:.1f} at the start, {os.getloadavg()[0]:.1f} at the end. Worst of {args.repeats} runs (median for the "
        f"overlap). Command: `python benchmarks/bench_time_limits.py --repeats {args.repeats}`"
    )
    print(header + "\n\n" + table(rows))
    if args.write:
        write_section("time_limits", "Time limits the tests no longer assert (issue 14)", header + "\n\n" + table(rows))


if __name__ == "__main__":
    main()
