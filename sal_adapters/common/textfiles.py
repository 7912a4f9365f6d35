"""Reading and writing the small text files of dataset layouts, with file:line errors.

Tables (trajectories, frame and time lists) are read line by line, within stated limits, so that
a file far larger than any real sequence's is refused with one error before its memory is
spent: ``MAX_TABLE_BYTES``, ``MAX_TABLE_ROWS`` and ``MAX_LINE_BYTES``.
"""

from __future__ import annotations

import math
import os
from array import array
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, BinaryIO

from sal_adapters.common.atomic import staged_file
from sal_adapters.common.errors import DatasetError

if TYPE_CHECKING:  # numpy loads with read_numeric_table: writers such as the sal commands stay light
    import numpy as np

__all__ = [
    "MAX_LINE_BYTES",
    "MAX_TABLE_BYTES",
    "MAX_TABLE_ROWS",
    "MAX_TEXT_BYTES",
    "atomic_write",
    "atomic_write_text",
    "check_size",
    "check_times",
    "format_float",
    "iter_rows",
    "read_numeric_table",
    "read_rows",
    "read_text",
]

#: Largest table file read (bytes): 256 MiB. A trajectory of 1 hour at 100 Hz (360,000 poses)
#: takes about 90 MB in KITTI with timestamps (13 values of ~19 characters a line), the widest
#: pose format; EuRoC ground truth (17 columns) of 1 hour at 200 Hz about 125 MB.
MAX_TABLE_BYTES = 256 * 1024 * 1024
#: Most rows read from a table (poses, frames or times): 2,000,000, over 5 hours at 100 Hz.
#: It bounds the memory of files of short lines (``0 0 0 0 0 0 0 1``) within ``MAX_TABLE_BYTES``.
MAX_TABLE_ROWS = 2_000_000
#: Longest line of a table (bytes, with its line break): 64 KiB; a pose line takes under 300.
MAX_LINE_BYTES = 64 * 1024


#: Largest text file a dataset reader reads (bytes): the longest real list or trajectory
#: (EuRoC ground truth, 36 000 rows) is a few MB.
MAX_TEXT_BYTES = 64 * 2**20


def read_text(path: Path, what: str = "file", max_bytes: int = MAX_TEXT_BYTES) -> str:
    """UTF-8 content of a text file of at most ``max_bytes``, its size checked before it is
    read; ``DatasetError`` naming it when missing, unreadable or too large (``what`` names it
    in messages)."""
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{what} not found", path)
    try:
        with path.open("rb") as handle:
            size = os.fstat(handle.fileno()).st_size
            data = handle.read(max_bytes + 1) if size <= max_bytes else b""
        if size > max_bytes or len(data) > max_bytes:  # a file that grows while read
            raise DatasetError(f"the file is {max(size, len(data))} bytes; the limit is {max_bytes} bytes", path)
        return data.decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"cannot read text file ({_reason(exc)})", path) from None


def _reason(exc: OSError | UnicodeDecodeError) -> str:
    """Why a file could not be read, in one short line (a decode error quotes no bytes)."""
    if isinstance(exc, UnicodeDecodeError):
        return f"not UTF-8 text: byte {exc.start} is not valid"
    return exc.strerror or str(exc)


def check_size(path: Path, size: int, limit: int = MAX_TABLE_BYTES) -> None:
    """``DatasetError`` naming ``path`` when ``size`` (bytes: the file's, or what was read of
    it so far) is over ``limit`` (bytes)."""
    if size > limit:
        raise DatasetError(f"{size} bytes, over the limit of {limit} bytes ({limit / 2**20:g} MiB) for a table file: not read", path)


def iter_rows(path: Path, delimiter: str | None = None) -> Iterator[tuple[int, list[str]]]:
    """Non-empty, non-comment (``#``) rows of a text file as ``(line number, fields)``, read
    line by line (line numbers as ``str.splitlines`` counts them).

    ``delimiter=None`` splits on whitespace; ``","`` splits CSV fields and strips them. A file
    over ``MAX_TABLE_BYTES``, a row past ``MAX_TABLE_ROWS`` or a line over ``MAX_LINE_BYTES``
    raises ``DatasetError`` naming the file, the limit and its unit, as does a missing or
    unreadable file.
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetError("file not found", path)
    try:
        with open(path, "rb") as handle:
            yield from _rows(handle, path, delimiter)
    except OSError as exc:
        raise DatasetError(f"cannot read text file ({_reason(exc)})", path) from None


def _rows(handle: BinaryIO, path: Path, delimiter: str | None) -> Iterator[tuple[int, list[str]]]:
    check_size(path, os.fstat(handle.fileno()).st_size)
    number = rows = consumed = 0
    while raw := handle.readline(MAX_LINE_BYTES + 1):
        consumed += len(raw)
        check_size(path, consumed)  # the file grew while read
        if len(raw) > MAX_LINE_BYTES:
            raise DatasetError(f"line longer than the limit of {MAX_LINE_BYTES} bytes for a table: not read", path, number + 1)
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise DatasetError(f"cannot read text file ({_reason(exc)})", path, number + 1) from None
        for line in text.splitlines():
            number += 1
            stripped = line.strip()
            if not stripped or stripped.startswith("#"):
                continue
            rows += 1
            if rows > MAX_TABLE_ROWS:
                raise DatasetError(
                    f"more than the limit of {MAX_TABLE_ROWS} rows (poses, frames or times) for a table: not read further", path, number
                )
            yield number, stripped.split() if delimiter is None else [f.strip() for f in stripped.split(delimiter)]


def read_rows(path: Path, delimiter: str | None = None) -> list[tuple[int, list[str]]]:
    """The rows of ``iter_rows`` as a list (for small files: frame lists, calibration)."""
    return list(iter_rows(path, delimiter))


def read_numeric_table(
    path: Path,
    columns: int | Iterable[int],
    delimiter: str | None = None,
    what: str = "values",
) -> tuple[np.ndarray, array[int]]:
    """Parse a whitespace or CSV table of floats; every row must have an allowed column count.

    Returns the float64 array (rows x columns, the first allowed count that matches, all rows
    equal) and the source line numbers. It is read line by line into compact arrays (8 bytes a
    value) within the limits of ``iter_rows``. A bad row raises ``DatasetError`` naming file
    and line.
    """
    allowed = (columns,) if isinstance(columns, int) else tuple(columns)
    values = array("d")
    lines = array("q")
    width: int | None = None
    for number, fields in iter_rows(path, delimiter):
        if len(fields) not in allowed or (width is not None and len(fields) != width):
            expected = width if width is not None else " or ".join(map(str, allowed))
            raise DatasetError(f"expected {expected} {what} per line, got {len(fields)}", path, number)
        width = len(fields)
        try:
            values.extend([float(f) for f in fields])
        except ValueError:
            bad = next(f for f in fields if not _is_float(f))
            raise DatasetError(f"expected numbers, got {bad!r}", path, number) from None
        lines.append(number)
    if width is None:
        raise DatasetError(f"no {what} found", path)
    import numpy as np

    return np.frombuffer(values, dtype=np.float64).reshape(-1, width), lines  # shares the array's memory: no copy


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def check_times(rows: Iterable[tuple[int, float]], path: Path, unit: str = "s", increasing: bool = True) -> None:
    """Check the ``(line number, time)`` rows of a frame list when a dataset is opened.

    Every time must be finite; with ``increasing`` each must come strictly after the previous
    row's, by a step that gives a frame rate (``1 / step``, Hz) that is a finite positive number,
    so that any two frames give a positive period. ``unit`` is the times' unit (``s`` or ``ns``)
    for messages. The first offending row raises ``DatasetError`` naming the file and line:
    ``times.txt:5: time 0.3 s is not after line 4's 0.4 s (frame times must increase)``.
    """
    previous: tuple[int, float] | None = None
    for number, t in rows:
        if not _finite(t):
            problem = "is too large" if isinstance(t, int) else "is not a finite number"
            raise DatasetError(f"time {_shown(t)} {unit} {problem}", path, number)
        if increasing and previous is not None:
            line, before = previous
            if not t > before:
                raise DatasetError(
                    f"time {_shown(t)} {unit} is not after line {line}'s {_shown(before)} {unit} (frame times must increase)", path, number
                )
            step = t - before
            if not (_finite(step) and _finite(1.0 / step)):
                raise DatasetError(
                    f"time {_shown(t)} {unit} is {_shown(step)} {unit} after line {line}'s: no usable frame period", path, number
                )
        previous = (number, t)


def _finite(value: float) -> bool:
    """``math.isfinite``, with ``False`` for an integer too large for a float."""
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def _shown(value: float) -> str:
    """A time as in messages: integers exactly (at most 40 characters), floats as ``format_float``."""
    text = str(value) if isinstance(value, int) else format_float(value)
    return text if len(text) <= 40 else f"{text[:20]}...({len(text)} digits)"


def format_float(value: float) -> str:
    """Shortest text that reads back as exactly the same float64 (``repr``)."""
    return repr(float(value))


def atomic_write(path: str | Path, write: Callable[[IO[Any]], object], binary: bool = False) -> Path:
    """Create ``path`` through a temporary file in the same folder, filled by ``write(handle)``,
    flushed to disk and moved into place with ``os.replace``: readers see the old file or the
    whole new one, never a part. The file gets the usual permissions (0666 less the umask); an
    ``OSError`` raises ``WriteError`` naming ``path``."""
    with staged_file(path) as temp, open(temp, "wb") if binary else open(temp, "w", encoding="utf-8", newline="\n") as handle:
        write(handle)
        handle.flush()
        os.fsync(handle.fileno())
    return Path(path)


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (see ``atomic_write``)."""
    return atomic_write(path, lambda handle: handle.write(text))
