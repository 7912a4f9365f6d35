"""Fault injection shared by the tests and the inner suites they run: a read-only mount
simulated in-process (the tests run as root, which ignores file modes), and a snapshot of a
folder to show that a fault left it untouched."""

from __future__ import annotations

import errno
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["refuse_writes_under", "stamps"]


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


def stamps(root: Path) -> dict[str, tuple[int, int]]:
    """Every path under ``root`` with its size and modification time (ns): equal before and
    after means nothing was written, removed or touched."""
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in sorted(root.rglob("*"))}
