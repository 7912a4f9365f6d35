"""Bounds the fuzz tests (test_experiment_fuzz.py, test_dataset_fuzz.py) and
benchmarks/fuzz_dataset_readers.py put on each input: CPU time, address space, peak memory."""

from __future__ import annotations

import resource
import signal
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

__all__ = ["Hang", "memory_limit", "peak_rss", "time_limit"]


class Hang(BaseException):
    """An input still being checked after its time limit (a BaseException: no ``except Exception`` hides it)."""


@contextmanager
def time_limit(seconds: float) -> Iterator[None]:
    """Raise ``Hang`` in the block after ``seconds`` of this process's CPU time: the bound does
    not move with the machine's load, and no clock bounds an input (a config that is not a
    regular file is refused before it is read, so no input can block)."""

    def expire(signum: int, frame: Any) -> None:
        raise Hang(f"still running after {seconds} s of CPU time")

    previous = signal.signal(signal.SIGPROF, expire)
    signal.setitimer(signal.ITIMER_PROF, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.signal(signal.SIGPROF, previous)


@contextmanager
def memory_limit(extra: int) -> Iterator[None]:
    """Let the block take at most ``extra`` more bytes of address space (then ``MemoryError``)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    in_use = int(Path("/proc/self/statm").read_text().split()[0]) * resource.getpagesize()
    resource.setrlimit(resource.RLIMIT_AS, (in_use + extra if hard == resource.RLIM_INFINITY else min(hard, in_use + extra), hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def peak_rss() -> int:
    """The process's peak resident memory so far, in bytes."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
