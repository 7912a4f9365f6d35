"""Bounds the fuzz tests (test_experiment_fuzz.py, test_dataset_fuzz.py) and
benchmarks/fuzz_dataset_readers.py put on each input: CPU time, address space, peak memory."""

from __future__ import annotations

import resource
import signal
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

__all__ = ["WALL_FACTOR", "Hang", "memory_limit", "peak_rss", "time_limit"]

WALL_FACTOR = 30  # an input blocked this many times its CPU seconds on the clock hangs


class Hang(BaseException):
    """An input still being checked after its time limit (a BaseException: no ``except Exception`` hides it)."""


@contextmanager
def time_limit(seconds: float, wall_factor: float | None = WALL_FACTOR) -> Iterator[None]:
    """Raise ``Hang`` in the block after ``seconds`` of this process's CPU time (the bound does
    not move with the machine's load), or after ``wall_factor`` times as long on the clock (an
    input that blocks without computing; ``None``: no bound on the clock)."""

    def expire(signum: int, frame: Any) -> None:
        raise Hang(
            f"still running after {seconds} s of CPU time" if signum == signal.SIGPROF else f"blocked for {seconds * (wall_factor or 0)} s"
        )

    previous = {sig: signal.signal(sig, expire) for sig in (signal.SIGPROF, signal.SIGALRM)}
    signal.setitimer(signal.ITIMER_PROF, seconds)
    if wall_factor is not None:
        signal.setitimer(signal.ITIMER_REAL, seconds * wall_factor)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.setitimer(signal.ITIMER_REAL, 0)
        for sig, handler in previous.items():
            signal.signal(sig, handler)


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
