"""The root error class of every pytest-sal package, and the adapters' shared errors and warnings.

``SalError`` is the one root: the plugin and the ``sal`` command catch it and print its message
without a traceback. Every other error class derives from it and lives beside the code that
raises it (``sal_modules.errors``, ``sal_wrappers.base.SlamSystemError``,
``pytest_sal.engine.execution.executor.ExecutorError``, ...; ARCHITECTURE.md lists them).
``DatasetError`` names the file (and line) that is wrong; ``WriteError`` the file or folder that
could not be written. ``CacheWarning`` says that a damaged cache entry (a stored frame of the
synthetic world, a stored run) was discarded and computed again, or that a cache cannot be
written (read-only, full).
``SalDeprecationWarning`` says that an old form of a YAML key or an ini value was read, and names
the new one.
"""

from __future__ import annotations

from os import PathLike

__all__ = ["MAX_PROBLEM_CHARS", "CacheWarning", "DatasetError", "DatasetWarning", "SalDeprecationWarning", "SalError", "WriteError"]


#: Characters of a ``DatasetError``'s problem (past the file and line): one line, never a dump.
MAX_PROBLEM_CHARS = 300


class SalError(Exception):
    """Root of every error pytest-sal raises on bad input or a failed run."""


class DatasetError(SalError, ValueError):
    """A dataset folder, file or option is missing or malformed.

    The message starts with the file (and line) so that a user can open it directly:
    ``/data/kitti/sequences/07/times.txt:12: expected 1 number, got 'abc'``.
    """

    def __init__(self, message: str, path: str | PathLike[str] | None = None, line: int | None = None):
        self.path = None if path is None else str(path)
        self.line = line
        self.problem = message  # what is wrong, without the file and line
        where = ""
        if self.path is not None:
            where = f"{self.path}:{line}: " if line is not None else f"{self.path}: "
        if len(message) > MAX_PROBLEM_CHARS:  # a reader quoted a whole hostile line or value
            message = message[: MAX_PROBLEM_CHARS - 3] + "..."
        text = where + message
        if not text.isprintable():  # a path or a value read from a hostile file: one line, escaped
            text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
        super().__init__(text)


class WriteError(SalError, OSError):
    """A file or folder could not be written (disk full, read-only, a file where a folder
    belongs): ``cannot write PATH: No space left on device``. It is an ``OSError`` too, with
    the cause's ``errno`` and ``strerror`` and ``filename`` = the path."""

    def __init__(self, path: str | PathLike[str], cause: OSError):
        super().__init__(cause.errno, cause.strerror or str(cause), str(path))

    def __str__(self) -> str:
        return f"cannot write {self.filename}: {self.strerror}"

    def __reduce__(self) -> tuple[type[WriteError], tuple[str, OSError]]:
        """Pickled as its path and cause, so one raised in another process (a Ray worker)
        comes back whole."""
        return WriteError, (self.filename, OSError(self.errno, self.strerror))


class DatasetWarning(UserWarning):
    """Something in a dataset was skipped or guessed (a missing image, assumed intrinsics)."""


class CacheWarning(UserWarning):
    """A bad cache entry was discarded (it is computed again), or the cache cannot be written (read-only, full)."""


class SalDeprecationWarning(FutureWarning):
    """An old form (a YAML key, an ini value) was read as it always was; the message names the
    new form. A ``FutureWarning``, so users see it by default."""
