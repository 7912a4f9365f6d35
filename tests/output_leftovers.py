"""What both output test modules (test_outputs_commands.py, test_outputs_atomic.py) look for
after a write: the staging and backup folders an interrupted replacement leaves behind."""

from __future__ import annotations

from pathlib import Path

__all__ = ["LEFTOVER", "leftovers"]


LEFTOVER = (".sal-tmp-", ".sal-old-")


def leftovers(root: Path) -> list[str]:
    return [p.relative_to(root).as_posix() for p in root.rglob("*") if any(mark in p.name for mark in LEFTOVER)]
