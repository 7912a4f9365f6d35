"""Error and warning classes shared by every pytest-sal package.

``SalError`` is the one root: the plugin and the ``sal`` command catch it and print its
message without a traceback. ``DatasetError`` names the file (and line) that is wrong.
"""

from __future__ import annotations

from os import PathLike

__all__ = ["SalError", "DatasetError", "DatasetWarning"]


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
        where = ""
        if self.path is not None:
            where = f"{self.path}:{line}: " if line is not None else f"{self.path}: "
        super().__init__(where + message)


class DatasetWarning(UserWarning):
    """Something in a dataset was skipped or guessed (a missing image, assumed intrinsics)."""
