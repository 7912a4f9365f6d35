"""Reading and writing the small text files of dataset layouts, with file:line errors."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import IO, Any

import numpy as np

from sal_adapters.atomic import staged_file
from sal_adapters.errors import DatasetError

__all__ = ["read_text", "read_rows", "read_numeric_table", "atomic_write", "atomic_write_text", "format_float"]


def read_text(path: Path, what: str = "file") -> str:
    """UTF-8 content of a text file; ``DatasetError`` naming it when missing or unreadable."""
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{what} not found", path)
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"cannot read text file ({exc})", path) from None


def read_rows(path: Path, delimiter: str | None = None) -> list[tuple[int, list[str]]]:
    """Non-empty, non-comment (``#``) rows of a text file as ``(line number, fields)``.

    ``delimiter=None`` splits on whitespace; ``","`` splits CSV fields and strips them.
    """
    text = read_text(path)
    rows = []
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        fields = stripped.split() if delimiter is None else [f.strip() for f in stripped.split(delimiter)]
        rows.append((number, fields))
    return rows


def read_numeric_table(
    path: Path,
    columns: int | Iterable[int],
    delimiter: str | None = None,
    what: str = "values",
) -> tuple[np.ndarray, list[int]]:
    """Parse a whitespace or CSV table of floats; every row must have an allowed column count.

    Returns the float64 array (rows x columns, the first allowed count that matches, all rows
    equal) and the source line numbers. A bad row raises ``DatasetError`` naming file and line.
    """
    allowed = (columns,) if isinstance(columns, int) else tuple(columns)
    rows = read_rows(path, delimiter)
    values: list[list[float]] = []
    lines: list[int] = []
    width: int | None = None
    for number, fields in rows:
        if len(fields) not in allowed or (width is not None and len(fields) != width):
            expected = width if width is not None else " or ".join(map(str, allowed))
            raise DatasetError(f"expected {expected} {what} per line, got {len(fields)}", path, number)
        width = len(fields)
        try:
            values.append([float(f) for f in fields])
        except ValueError:
            bad = next(f for f in fields if not _is_float(f))
            raise DatasetError(f"expected numbers, got {bad!r}", path, number) from None
        lines.append(number)
    if not values:
        raise DatasetError(f"no {what} found", path)
    return np.asarray(values, dtype=np.float64), lines


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def format_float(value: float) -> str:
    """Shortest text that reads back as exactly the same float64 (``repr``)."""
    return repr(float(value))


def atomic_write(path: str | Path, write: Callable[[IO[Any]], None], binary: bool = False) -> Path:
    """Create ``path`` through a temporary file in the same folder, filled by ``write(handle)``,
    flushed to disk and moved into place with ``os.replace``: readers see the old file or the
    whole new one, never a part. The file gets the usual permissions (0666 less the umask); an
    ``OSError`` raises ``WriteError`` naming ``path``."""
    with staged_file(path) as temp, open(temp, "wb" if binary else "w", **({} if binary else {"encoding": "utf-8", "newline": "\n"})) as handle:
        write(handle)
        handle.flush()
        os.fsync(handle.fileno())
    return Path(path)


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (see ``atomic_write``)."""
    return atomic_write(path, lambda handle: handle.write(text))
