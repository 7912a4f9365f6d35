"""A lock file shared by processes (xdist workers, parallel CI jobs): whoever holds it computes,
the others wait and then find the result."""

from __future__ import annotations

import errno
import fcntl
import os
from pathlib import Path
from typing import Self

from sal_adapters.common.errors import SalError

__all__ = ["FileLock", "LockError"]


class LockError(SalError):
    """A lock file cannot be opened or locked; the message starts with its path."""

    def __init__(self, message: str, path: Path):
        super().__init__(f"{path}: {message}")
        self.path = str(path)


class FileLock:
    """An exclusive ``flock(2)`` on a lock file that is unlinked on release (``with FileLock(p):``);
    released by the kernel when the holder dies, so a killed process never leaves it locked.

    Unlinking is safe because a process that locked a file checks, once it holds the lock,
    that the path still names that file; when it does not (the holder unlinked it meanwhile),
    it locks the new file instead.
    """

    def __init__(self, path: Path):
        self.path = path
        self._fd: int | None = None

    def acquire(self, blocking: bool = True) -> bool:
        while True:
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
            except FileNotFoundError:  # locks/ removed by hand: make it again
                self.path.parent.mkdir(parents=True, exist_ok=True)
                continue
            except OSError as exc:
                raise LockError(f"cannot open lock file: {exc.strerror}", self.path) from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | (0 if blocking else fcntl.LOCK_NB))
            except OSError as exc:
                os.close(fd)
                if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN):
                    return False
                raise LockError(f"cannot lock: {exc.strerror}", self.path) from None
            try:
                same = os.stat(self.path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                self._fd = fd
                return True
            os.close(fd)

    def release(self) -> None:
        if self._fd is None:
            return
        try:
            os.unlink(self.path)
        except FileNotFoundError:
            pass
        finally:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> Self:
        self.acquire()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.release()
