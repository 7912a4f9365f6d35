"""prefetched(): order, errors at their place, early exit, and real overlap with the consumer."""

from __future__ import annotations

import threading
import time

import pytest

from sal_wrappers.prefetch import prefetched


def test_items_arrive_in_order_and_all_of_them() -> None:
    assert list(prefetched(range(100), ahead=3)) == list(range(100))


def test_an_error_while_producing_is_raised_at_its_place() -> None:
    def items():
        yield 1
        yield 2
        raise ValueError("frame 3 is unreadable")

    seen = []
    with pytest.raises(ValueError, match="frame 3 is unreadable"):
        for item in prefetched(items()):
            seen.append(item)
    assert seen == [1, 2]


def test_leaving_early_stops_the_producer() -> None:
    produced = []

    def items():
        for i in range(1000):
            produced.append(i)
            yield i

    for item in prefetched(items(), ahead=2):
        if item == 5:
            break
    time.sleep(0.05)
    assert len(produced) <= 5 + 2 + 2  # at most `ahead` (plus the one in hand) beyond the break
    assert not any(t.name == "sal-prefetch" and t.is_alive() for t in threading.enumerate())


def test_production_overlaps_consumption() -> None:
    """With the first item in hand, the next ``ahead`` are produced without being asked for:
    production runs beside consumption (the wall time that saves is benchmarks/bench_time_limits.py's)."""
    produced = threading.Semaphore(0)

    def items():
        for i in range(10):
            produced.release()
            yield i

    stream = prefetched(items(), ahead=3)
    assert next(stream) == 0
    assert all(produced.acquire(timeout=10) for _ in range(1 + 3))  # items 0-3 produced, only item 0 taken
    assert list(stream) == list(range(1, 10))
