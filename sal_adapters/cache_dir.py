"""Where pytest-sal keeps rendered and computed data between runs."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["user_cache_dir"]


def user_cache_dir(*parts: str) -> Path:
    """``$SAL_CACHE_DIR`` or ``$XDG_CACHE_HOME/sal`` or ``~/.cache/sal``, joined with ``parts``
    (not created)."""
    root = os.environ.get("SAL_CACHE_DIR")
    if not root:
        base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
        root = str(Path(base) / "sal")
    return Path(root).expanduser().joinpath(*parts)
