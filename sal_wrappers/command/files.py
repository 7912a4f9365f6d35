"""The files a ``command`` system runs, hashed for its identity (and so for the cache key).

The executable (``argv[0]``, looked up on ``PATH``), every other ``argv`` item that names an
existing file, and the ``depends`` files and folders: a change to any of them gives another
identity, so no stale result is served.
"""

from __future__ import annotations

import hashlib
import os
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path

from sal_wrappers.base import SlamSystemError, file_sha256
from sal_wrappers.command.placeholders import placeholders_in, render

__all__ = ["DEPENDS_MAX_BYTES", "DEPENDS_MAX_FILES", "file_digest", "program_files", "tree_digest"]

#: Most a ``depends`` folder may hold (its files are hashed for the cache key).
DEPENDS_MAX_BYTES = 1 << 30
DEPENDS_MAX_FILES = 20_000
#: Skipped in a ``depends`` folder: caches that running the program rewrites, version control.
_SKIPPED_DIRS = {"__pycache__", ".git", ".hg", ".svn", ".mypy_cache", ".pytest_cache", ".ruff_cache"}


def program_files(argv: Sequence[str], cwd: str | None, env: Mapping[str, str]) -> list[tuple[str, Path | None]]:
    """``(argv item, file)`` for the executable (``None``: not found) and each other argv
    item that names an existing file (relative ones against ``cwd``); items with
    placeholders are left out. ``env["PATH"]`` replaces the process's ``PATH`` when given."""
    folder = Path(cwd).expanduser() if cwd is not None and not placeholders_in(cwd) else None
    base = folder if folder is not None and folder.is_absolute() else Path.cwd()
    path_var = env.get("PATH")
    search = path_var if path_var is not None and not placeholders_in(path_var) else os.environ.get("PATH")
    out: list[tuple[str, Path | None]] = []
    for i, arg in enumerate(argv):
        if placeholders_in(arg) or not arg:
            continue
        text = render(arg, {})
        if i == 0 and os.sep not in text:
            found = shutil.which(text, path=search)
            out.append((arg, None if found is None else Path(found)))
            continue
        path = Path(text).expanduser()
        path = path if path.is_absolute() else base / path
        if path.is_file():
            out.append((arg, path))
        elif i == 0:
            out.append((arg, None))
    return out


def file_digest(path: Path, what: str) -> str:
    """SHA-256 of the file at ``path`` (``what`` it is, for the error when it cannot be read)."""
    try:
        return file_sha256(path)
    except OSError as exc:
        raise SlamSystemError(f"command: cannot read {what} {path} to hash it for the cache key ({exc.strerror or exc})") from None


def tree_digest(folder: Path) -> str:
    """SHA-256 over the sorted relative paths and contents of the files under ``folder``
    (caches and version-control folders left out); at most ``DEPENDS_MAX_FILES`` files and
    ``DEPENDS_MAX_BYTES`` bytes."""
    files: list[tuple[str, Path]] = []
    total = 0
    for root, dirs, names in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if d not in _SKIPPED_DIRS)
        for name in names:
            path = Path(root) / name
            if name.endswith((".pyc", ".pyo")) or not path.is_file():
                continue
            files.append((path.relative_to(folder).as_posix(), path))
            total += path.stat().st_size
            if len(files) > DEPENDS_MAX_FILES or total > DEPENDS_MAX_BYTES:
                raise SlamSystemError(
                    f"command: depends folder {folder} holds more than {DEPENDS_MAX_FILES} files or {DEPENDS_MAX_BYTES >> 20} MiB; "
                    "list the files and smaller folders that decide the results instead"
                )
    digest = hashlib.sha256()
    for relative, path in sorted(files):
        digest.update(f"{relative}\0{file_digest(path, 'the depends file')}\n".encode())
    return digest.hexdigest()
