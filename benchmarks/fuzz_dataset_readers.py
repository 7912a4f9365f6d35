#!/usr/bin/env python3
"""Fuzz of the dataset readers, at length (issue 23, items 7 and 8): ``--inputs`` hostile
versions of real KITTI, EuRoC and TUM files (tests/dataset_fuzz_inputs.py), each read in a
worker process under a CPU-time limit; prints inputs tried, clean errors, opened datasets,
tracebacks, hangs and the peak memory (maxrss) of the workers, and records them in RESULTS.md.

    PYTHONPATH=. python benchmarks/fuzz_dataset_readers.py --inputs 2000 --data ../shared/data
"""

from __future__ import annotations

import argparse
import random
import resource
import sys
import tempfile
import traceback
import warnings
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from dataset_fuzz_inputs import mutate, prepare
from fuzz_limits import Hang, time_limit
from results_file import write_section  # benchmarks/ is on sys.path when run as a script

SECONDS = 10.0  # of CPU time per input before it counts as a hang


def run_chunk(data: Path, seeds: list[int]) -> tuple[Counter[str], list[str], int]:
    """Outcomes of the inputs ``seeds`` (each picks a file and its edits), the first lines of
    any traceback, and this worker's peak RSS (KiB)."""
    from sal_adapters import DatasetError, open_dataset

    tally: Counter[str] = Counter()
    problems: list[str] = []
    with tempfile.TemporaryDirectory() as root:
        targets = prepare(data, Path(root))
        for seed in seeds:
            rng = random.Random(seed)
            target = targets[rng.randrange(len(targets))]
            original = target.file.read_bytes()
            mutate(original, rng).write(target.file)
            try:
                with time_limit(SECONDS), warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    sequence = open_dataset(target.kind, target.folder)
                    for frame in sequence.select(range(min(2, len(sequence)))):
                        frame.image  # noqa: B018
                    if sequence.groundtruth is not None:
                        sequence.groundtruth.positions  # noqa: B018
                tally["opened"] += 1
            except DatasetError as exc:
                tally["clean errors"] += 1
                if not str(exc).isprintable():
                    tally["bad lines"] += 1
            except Hang:
                tally["hangs"] += 1
                problems.append(f"{target.name} seed {seed}: hang")
            except Exception as exc:  # what the fuzz looks for
                tally["tracebacks"] += 1
                problems.append(f"{target.name} seed {seed}: {traceback.format_exception_only(exc)[-1].strip()[:200]}")
            finally:
                target.file.write_bytes(original)
    return tally, problems, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--inputs", type=int, default=2000, help="hostile inputs to try. Default: %(default)r")
    parser.add_argument("--workers", type=int, default=2, help="worker processes. Default: %(default)r")
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared" / "data", help="the shared/data folder")
    parser.add_argument("--no-record", action="store_true", help="print only, do not write RESULTS.md")
    args = parser.parse_args()
    chunks = [list(range(k, args.inputs, args.workers)) for k in range(args.workers)]
    tally: Counter[str] = Counter()
    problems: list[str] = []
    peak_kib = 0
    with ProcessPoolExecutor(args.workers) as pool:
        for counts, found, rss in pool.map(run_chunk, [args.data] * len(chunks), chunks):
            tally.update(counts)
            problems += found
            peak_kib = max(peak_kib, rss)
    tried = sum(tally[k] for k in ("opened", "clean errors", "hangs", "tracebacks"))
    line = (
        f"{tried} inputs tried: {tally['clean errors']} clean errors ({tally['bad lines']} not one printable line), "
        f"{tally['opened']} opened, {tally['tracebacks']} tracebacks, {tally['hangs']} hangs (over {SECONDS:g} s of CPU); "
        f"peak memory of a worker {peak_kib // 1024} MiB (maxrss)"
    )
    print(line)
    for problem in problems[:20]:
        print("  ", problem)
    if not args.no_record:
        command = f"PYTHONPATH=. python benchmarks/fuzz_dataset_readers.py --inputs {args.inputs} --workers {args.workers}"
        write_section("dataset-fuzz", "Fuzz of the dataset readers (issue 23, items 7 and 8)", f"```sh\n{command}\n```\n\n{line}")


if __name__ == "__main__":
    main()
