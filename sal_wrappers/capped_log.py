"""A run's log with a stated size: the program writes into a pipe, and a thread copies what it
reads into the log file up to ``MAX_LOG_BYTES`` in all, the first half as it comes and the last
half at the end, with ``[... N bytes cut ...]`` between them. A program that prints gigabytes
costs ``MAX_LOG_BYTES`` of disk and half of it of memory; it never waits on the log, which is
read as fast as it writes.

>>> with CappedLog(path, header=b"$ program\\n") as log:          # doctest: +SKIP
...     process = subprocess.Popen(argv, stdout=log.fd, stderr=subprocess.STDOUT)
...     log.detach()  # the program holds the pipe now
...     process.wait()
"""

from __future__ import annotations

import fcntl
import os
import select
import threading
from collections import deque
from pathlib import Path
from types import TracebackType
from typing import IO

__all__ = ["MAX_LOG_BYTES", "CappedLog"]

#: Most bytes of a program's output kept in its log (4 MiB): the first and the last 2 MiB.
MAX_LOG_BYTES = 4 * 1024 * 1024
#: Bytes read from the pipe at a time.
_CHUNK = 64 * 1024
#: Size asked for the pipe (bytes), and the most read once the run is over: what its dead
#: writers left in the pipe (a Linux pipe holds 1 MiB at most unless raised by root), not the
#: output of a process that outlived the run.
_DRAIN_BYTES = 1024 * 1024


class CappedLog:
    """The log file ``path``, at most ``limit`` bytes (with ``header``) plus the cut marker.

    Entering creates the file and the pipe and starts the reading thread; ``fd`` is the pipe's
    write end, for the program's stdout and stderr; ``detach`` closes this process's copy of it
    once the program started. Leaving (after the program's processes are gone) reads what is
    left in the pipe and writes the kept tail. A log that cannot be written (disk full) is left
    as far as it got, as when the program wrote it itself: the pipe is still read.
    """

    _file: IO[bytes]

    def __init__(self, path: Path, header: bytes = b"", limit: int = MAX_LOG_BYTES) -> None:
        self.path = Path(path)
        self._header = header
        self._head_left = limit - limit // 2  # bytes still written as they come
        self._tail_size = limit // 2
        self._tail: deque[bytes] = deque()
        self._tail_bytes = 0
        self._cut = 0
        self.fd = -1
        self._read = self._wake_read = self._wake_write = -1
        self._thread: threading.Thread | None = None
        self._failed = False  # writing the file failed: nothing more is written

    def __enter__(self) -> CappedLog:
        self._file = open(self.path, "wb")  # closed in __exit__, after the thread
        self._keep(self._header)
        self._read, self.fd = os.pipe()
        try:  # a larger pipe (Linux): the program runs on while this thread waits for the GIL
            fcntl.fcntl(self.fd, fcntl.F_SETPIPE_SZ, _DRAIN_BYTES)
        except (AttributeError, OSError):
            pass  # the system's size (64 KiB), or more than an unprivileged process may set
        self._wake_read, self._wake_write = os.pipe()
        self._thread = threading.Thread(target=self._pump, name=f"log {self.path}", daemon=True)
        self._thread.start()
        return self

    def detach(self) -> None:
        """Close this process's write end (the program keeps its own): the thread sees the end
        of the output when the program and its children are gone."""
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None) -> None:
        self.detach()
        os.write(self._wake_write, b"x")
        assert self._thread is not None
        self._thread.join()
        for fd in (self._read, self._wake_read, self._wake_write):
            os.close(fd)
        if self._cut:
            self._write(f"\n[... {self._cut} bytes cut ...]\n".encode())
        for chunk in self._tail:
            self._write(chunk)
        self._file.close()

    def _pump(self) -> None:
        """Read the pipe until its end, or until told the run is over: then drain it."""
        while True:
            ready, _, _ = select.select([self._read, self._wake_read], [], [])
            if self._wake_read in ready:
                self._drain()
                return
            chunk = os.read(self._read, _CHUNK)
            if not chunk:
                return
            self._keep(chunk)

    def _drain(self) -> None:
        os.set_blocking(self._read, False)
        drained = 0
        while drained < _DRAIN_BYTES:
            try:
                chunk = os.read(self._read, _CHUNK)
            except BlockingIOError:
                return
            if not chunk:
                return
            drained += len(chunk)
            self._keep(chunk)

    def _keep(self, data: bytes) -> None:
        """Write ``data`` while the head has room, then keep the last ``_tail_size`` bytes."""
        head, rest = data[: self._head_left], data[self._head_left :]
        if head:
            self._write(head)
            self._head_left -= len(head)
        if not rest:
            return
        self._tail.append(rest)
        self._tail_bytes += len(rest)
        while self._tail_bytes - len(self._tail[0]) >= self._tail_size:
            self._tail_bytes -= len(self._tail[0])
            self._cut += len(self._tail.popleft())
        if self._tail_bytes > self._tail_size:  # cut the oldest chunk to size
            over = self._tail_bytes - self._tail_size
            self._tail[0] = self._tail[0][over:]
            self._tail_bytes -= over
            self._cut += over

    def _write(self, data: bytes) -> None:
        if not self._failed:
            try:
                self._file.write(data)
                self._file.flush()  # the head is on disk while the program runs
            except OSError:
                self._failed = True
