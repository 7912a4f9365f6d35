"""Produce the next frames in a background thread while the system tracks the current one.

Decoding, depth and perturbation run in numpy and OpenCV, which release the GIL, so frame
production overlaps tracking on a second core instead of adding to the trial's wall time.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterable, Iterator
from typing import TypeVar

__all__ = ["prefetched"]

T = TypeVar("T")
_DONE = object()


def prefetched(items: Iterable[T], ahead: int = 3) -> Iterator[T]:
    """Iterate ``items`` with up to ``ahead`` of them produced in advance by a daemon thread.

    An exception raised while producing an item is raised here, at that item's place; leaving
    the loop early stops the producer after at most ``ahead`` further items.
    """
    buffer: queue.Queue = queue.Queue(maxsize=max(1, ahead))
    stop = threading.Event()

    def produce() -> None:
        try:
            for item in items:
                if stop.is_set():
                    return
                buffer.put((item, None))
        except BaseException as exc:  # handed to the consumer, raised there
            buffer.put((_DONE, exc))
            return
        buffer.put((_DONE, None))

    worker = threading.Thread(target=produce, name="sal-prefetch", daemon=True)
    worker.start()
    try:
        while True:
            item, error = buffer.get()
            if error is not None:
                raise error
            if item is _DONE:
                return
            yield item
    finally:
        stop.set()
        while worker.is_alive():  # unblock a producer waiting on a full buffer
            try:
                buffer.get_nowait()
            except queue.Empty:
                worker.join(timeout=0.05)
