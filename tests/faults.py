"""Fault injection shared by the tests and the inner suites they run: a read-only mount and a
full disk simulated in-process (the tests run as root, which ignores file modes), and a
snapshot of a folder to show that a fault left it untouched."""

from __future__ import annotations

import builtins
import errno
import io
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["fill_disk_under", "refuse_writes_under", "stamps"]


def refuse_writes_under(root: Path, setattr: Callable[[Any, str, Any], None] = setattr) -> None:
    """From now on every write under ``root`` (open for writing, mkdir, rename, replace,
    unlink, rmdir, utime) fails with EROFS, as on a read-only mount. ``setattr`` is
    ``monkeypatch.setattr`` in a test (undone after it) or the builtin in a throwaway process."""

    def guard(real: Callable[..., Any]) -> Callable[..., Any]:
        def refuse(path: Any, *args: Any, **kwargs: Any) -> Any:
            writes = real is not real_open or args[0] & (os.O_WRONLY | os.O_RDWR | os.O_CREAT)
            if writes and os.path.abspath(os.fspath(path)).startswith(str(root)):
                raise OSError(errno.EROFS, os.strerror(errno.EROFS), os.fspath(path))
            return real(path, *args, **kwargs)

        return refuse

    real_open = os.open
    for name in ("open", "mkdir", "rename", "replace", "unlink", "rmdir", "utime"):
        setattr(os, name, guard(getattr(os, name)))


def fill_disk_under(root: Path, setattr: Callable[[Any, str, Any], None] = setattr) -> None:
    """From now on the disk under ``root`` is full: a file opened for writing there is created
    (as on a real full disk, where inodes remain), but writing bytes to it fails with ENOSPC.
    ``setattr`` as in ``refuse_writes_under``."""
    real_open, real_write = builtins.open, os.write

    def under(path: Any) -> bool:
        return isinstance(path, (str, os.PathLike)) and os.path.abspath(os.fspath(path)).startswith(str(root))

    def full_open(file: Any, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
        handle = real_open(file, mode, *args, **kwargs)
        return _FullFile(handle) if under(file) and set(mode) & set("wxa+") else handle

    def full_write(fd: int, data: Any) -> int:
        try:
            target = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:  # not a file (or not Linux): the real write decides
            target = ""
        if under(target):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_write(fd, data)

    setattr(builtins, "open", full_open)
    setattr(io, "open", full_open)
    setattr(os, "write", full_write)


class _FullFile:
    """A file on a full disk: every write fails with ENOSPC; the rest is the real file's."""

    def __init__(self, handle: Any):
        self._handle = handle

    def write(self, data: Any) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def __getattr__(self, name: str) -> Any:
        return getattr(self._handle, name)

    def __enter__(self) -> _FullFile:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._handle.close()


def stamps(root: Path) -> dict[str, tuple[int, int]]:
    """Every path under ``root`` with its size and modification time (ns): equal before and
    after means nothing was written, removed or touched."""
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in sorted(root.rglob("*"))}
