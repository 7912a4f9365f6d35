"""Fuzz of the experiment YAML schema (issue 12): every config ``sal perturb --dry-run`` reads
ends in a plan or in one short ``sal: error:`` line, within a time and a memory bound.

Two kinds of configs are generated: mappings built from the schema's real keys, dataset
options, perturbation modules and parameters, with some values replaced by random ones of
random types, and YAML text (the example configs and generated ones) mutated by inserting
anchors, aliases, tags, nesting, duplicated lines, tabs and binary junk. Each is checked as
the dry run checks it: validated, its dataset opened and each module built, nothing rendered
and nothing written. A sample goes through the real ``sal`` command. The counts are printed
at the end of the module (``-s``) and written to ``schema_fuzz_counts.json`` in pytest's
base temporary folder.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
import tracemalloc
import warnings
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from experiment_fuzz_configs import EXAMPLES, FOLDER, alias_bomb, raw_configs, schema_configs
from fuzz_limits import Hang, memory_limit, peak_rss, time_limit
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pytest_sal.experiment.config import build_modules, build_sequence, load_config
from sal_adapters import SalError
from sal_adapters.common.cache_dir import no_cache_writes
from sal_adapters.images import write_image

CONFIG = "c.yaml"  # read from the working folder, so messages start with this short name
SECONDS = 2.0  # of CPU time per config
MEMORY = 200 * 2**20  # bytes of address space a config may take (beyond: MemoryError)
LINE = 300  # characters of an error message
FUZZ = settings(derandomize=True, database=None, deadline=None, suppress_health_check=list(HealthCheck), print_blob=False)

#: What the fuzz saw: configs tried, each outcome in all and by strategy, the slowest, the alias bomb.
TALLY: Counter[str] = Counter()
OUTCOMES = ("clean errors", "plans", "tracebacks", "hangs", "over memory", "bad lines")


def is_one_line(message: str) -> bool:
    """Whether ``sal`` prints ``message`` as one clean error line: printable, short."""
    return message.isprintable() and len(message) <= LINE


def check(data: bytes, folder: Path, strategy: str) -> str | None:
    """The error message of the config ``data`` (``None``: a plan) from the dry run's checks in
    the working folder (validation, opening the dataset, building each module), within
    ``SECONDS`` and ``MEMORY``, writing nothing; counted in ``TALLY`` by outcome, in all and by
    ``strategy``."""
    Path(CONFIG).write_bytes(data.replace(FOLDER.encode(), str(folder).encode()))
    started = time.process_time()
    outcome = "tracebacks"  # unless one of the outcomes below
    try:
        with time_limit(SECONDS), memory_limit(MEMORY), no_cache_writes(), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # sal prints them as warnings, not errors
            config = load_config(CONFIG)
            build_sequence(config)
            build_modules(config)
        message, outcome = None, "plans"
    except SalError as exc:
        message, outcome = str(exc), "clean errors"
        if not is_one_line(message):
            outcome = "bad lines"
            raise AssertionError(f"not one short printable line ({len(message)} chars): {message[:2000]!r}") from None
    except Hang:
        outcome = "hangs"
        raise
    except MemoryError:
        outcome = "over memory"
        raise
    finally:
        TALLY[outcome] += 1
        TALLY[f"{strategy}: {outcome}"] += 1
    TALLY["slowest ms"] = max(TALLY["slowest ms"], round(1000 * (time.process_time() - started)))
    assert sorted(p.name for p in Path.cwd().iterdir()) == [CONFIG], "the checks wrote in the working folder"
    return message


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The working folder of the fuzz, with a three-image folder dataset beside it; at the
    end, the counts (printed and in ``schema_fuzz_counts.json``)."""
    root = tmp_path_factory.mktemp("schema-fuzz")
    folder = root / "images"
    folder.mkdir()
    for i in range(3):
        write_image(folder / f"{i:03d}.png", np.full((8, 12, 3), 40 * i, np.uint8))
    work = root / "work"
    work.mkdir()
    start = peak_rss()
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(work)
        yield folder
    TALLY["configs tried"] = sum(TALLY[o] for o in OUTCOMES)
    TALLY["peak RSS growth MiB"] = (peak_rss() - start) // 2**20
    (tmp_path_factory.getbasetemp() / "schema_fuzz_counts.json").write_text(json.dumps(TALLY, indent=2) + "\n")
    print("\nschema fuzz:", ", ".join(f"{TALLY[k]} {k}" for k in ("configs tried", *OUTCOMES)))
    print("schema fuzz details:", json.dumps(TALLY))


# ------------------------------------------------------------------------------ tests


@settings(FUZZ, max_examples=2000)
@given(data=schema_configs())
def test_generated_configs_end_in_a_plan_or_one_line(workdir: Path, data: bytes) -> None:
    check(data, workdir, "schema")


@settings(FUZZ, max_examples=2000)
@given(data=raw_configs())
def test_mutated_yaml_ends_in_a_plan_or_one_line(workdir: Path, data: bytes) -> None:
    check(data, workdir, "yaml text")


def test_alias_bomb_is_one_line_in_under_20_mib(workdir: Path) -> None:
    """Nine levels of nine aliases (10^9 strings once expanded) before a valid config; its CPU
    time (target: under 1 s) is benchmarks/bench_time_limits.py's."""
    data = (alias_bomb(9) + (EXAMPLES / "fog_rain_urban.yaml").read_text()).encode()
    tracemalloc.start()
    started = time.process_time()  # CPU time, for the tally only
    message = check(data, workdir, "alias bomb")
    seconds = time.process_time() - started
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    TALLY["alias bomb ms"] = round(1000 * seconds)
    TALLY["alias bomb peak KiB"] = peak // 1024
    assert peak < 20 * 2**20
    assert message == "c.yaml:6: holds more than 100000 values once its YAML aliases are expanded; a config needs a few hundred"


@settings(FUZZ, max_examples=20)
@given(data=st.one_of(schema_configs(), raw_configs()))
def test_sal_perturb_dry_run_prints_the_same_line_and_writes_nothing(workdir: Path, data: bytes) -> None:
    """The real command on a sample: exit 2 with the one ``sal: error:`` line the checks
    gave, or exit 0 with the plan (or one error line from a module that cannot apply to
    the dataset); nothing written in the working folder or the cache."""
    message = check(data, workdir, "sal sample")
    sal = Path(sys.executable).with_name("sal")
    run = subprocess.run([str(sal), "perturb", CONFIG, "--dry-run", "--cache-dir", "cache"], capture_output=True, text=True, timeout=60)
    errors = [line for line in run.stderr.splitlines() if not line.startswith("sal: warning: ")]
    TALLY["sal runs"] += 1
    assert sorted(p.name for p in Path.cwd().iterdir()) == [CONFIG]  # no output, no cache
    if message is not None:
        assert (run.returncode, errors) == (2, [f"sal: error: {message}"])
    elif run.returncode == 0:
        assert "dry run: nothing written" in run.stdout and errors == []
    else:
        assert run.returncode == 2 and len(errors) == 1 and errors[0].startswith("sal: error: ") and errors[0].isprintable(), run.stderr
