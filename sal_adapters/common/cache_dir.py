"""Where pytest-sal keeps rendered and computed data between runs, and a switch that keeps
it in memory instead (``sal perturb --dry-run`` writes nothing)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path

__all__ = ["cache_writes_allowed", "no_cache_writes", "user_cache_dir"]

_WRITES: ContextVar[bool] = ContextVar("sal_cache_writes", default=True)


def user_cache_dir(*parts: str) -> Path:
    """``$SAL_CACHE_DIR`` or ``$XDG_CACHE_HOME/sal`` or ``~/.cache/sal``, joined with ``parts``
    (not created)."""
    root = os.environ.get("SAL_CACHE_DIR")
    if not root:
        base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
        root = str(Path(base) / "sal")
    return Path(root).expanduser().joinpath(*parts)


@contextmanager
def no_cache_writes() -> Iterator[None]:
    """Within the block, datasets and depth providers opened compute what is asked in memory
    and store nothing on disk, then or later (rendered frames, their metadata, depth)."""
    token = _WRITES.set(False)
    try:
        yield
    finally:
        _WRITES.reset(token)


def cache_writes_allowed() -> bool:
    """False inside ``no_cache_writes()``; a cache decides it when it is opened."""
    return _WRITES.get()
