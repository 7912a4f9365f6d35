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
    def slow(n: int):
        for i in range(n):
            time.sleep(0.02)  # producing one frame (releases the GIL, like numpy and OpenCV)
            yield i

    start = time.perf_counter()
    for _ in prefetched(slow(20), ahead=3):
        time.sleep(0.02)  # tracking one frame
    overlapped = time.perf_counter() - start
    assert overlapped < 0.75 * (20 * 0.04)  # serial would take 0.8 s; overlapped about 0.42 s
