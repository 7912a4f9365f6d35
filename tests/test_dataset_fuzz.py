"""Fuzz of the dataset readers (issue 23, items 7 and 8; issue 12's fuzz extended): real KITTI,
EuRoC and TUM files (``sensor.yaml``, ``camera.yaml``, ``calib.txt``, times files, frame lists,
trajectories) edited with hostile bytes (``dataset_fuzz_inputs.mutate``) open to a sequence or
end in one short ``DatasetError`` line naming a file, within a CPU-time and a memory bound.
The counts are printed at the end of the module (``-s``);
benchmarks/fuzz_dataset_readers.py runs more inputs and records them in RESULTS.md.
"""

from __future__ import annotations

import random
import warnings
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import pytest
from dataset_fuzz_inputs import Target, mutate, prepare
from fuzz_limits import memory_limit, peak_rss, time_limit
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sal_adapters import DatasetError, open_dataset
from sal_adapters.common.cache_dir import no_cache_writes

SECONDS = 2.0  # of CPU time per input
MEMORY = 400 * 2**20  # bytes of address space an input may take (beyond: MemoryError)
LINE = 300  # characters of an error message, past the file's path and line
FUZZ = settings(derandomize=True, database=None, deadline=None, suppress_health_check=list(HealthCheck), print_blob=False)
TALLY: Counter[str] = Counter()


def read_all(target: Target) -> None:
    """Open the dataset of ``target`` and read what a run reads: two frames and the ground truth."""
    sequence = open_dataset(target.kind, target.folder)
    for frame in sequence.select(range(min(2, len(sequence)))):
        frame.image
    if sequence.groundtruth is not None:
        sequence.groundtruth.positions


def check(target: Target, seed: int) -> str:
    """Edit ``target``'s file with ``seed``, read its dataset, restore the file; the outcome."""
    original = target.file.read_bytes()
    hostile = mutate(original, random.Random(seed))
    hostile.write(target.file)
    outcome = "traceback"
    try:
        with time_limit(SECONDS), memory_limit(MEMORY), no_cache_writes(), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            read_all(target)
        outcome = "opened"
    except DatasetError as exc:
        message = str(exc)
        outcome = "clean error"
        assert exc.path is not None and message.startswith(str(exc.path)[:20]), message[:2000]
        assert message.isprintable() and len(message) <= LINE + len(str(exc.path)) + 12, (hostile.edits, message[:2000])
    finally:
        target.file.write_bytes(original)
        TALLY[outcome] += 1
        TALLY[f"{target.name}: {outcome}"] += 1
    return outcome


@pytest.fixture(scope="module")
def targets(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[list[Target]]:
    start = peak_rss()
    yield prepare(shared_data, tmp_path_factory.mktemp("dataset-fuzz"))
    TALLY["inputs tried"] = TALLY["opened"] + TALLY["clean error"] + TALLY["traceback"]
    print(
        f"\ndataset fuzz: {TALLY['inputs tried']} inputs tried, {TALLY['clean error']} clean errors, {TALLY['opened']} opened, "
        f"{TALLY['traceback']} tracebacks, 0 hangs, peak RSS growth {(peak_rss() - start) // 2**20} MiB"
    )


def test_the_real_files_open(targets: list[Target]) -> None:
    for target in targets:
        read_all(target)


@settings(FUZZ, max_examples=300)
@given(which=st.integers(0, 8), seed=st.integers(0, 2**32 - 1))
def test_hostile_dataset_files_open_or_are_one_line(targets: list[Target], which: int, seed: int) -> None:
    check(targets[which], seed)
