"""An experiment folder as the experiment page reads it: its JSON summaries (a broken one is
noted, never raised), its pictures copied beside the page under ``assets/`` and the problems met
on the way, which the page lists."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pytest_sal.report.html_page import asset_src, esc
from sal_adapters.common.atomic import copy_file

__all__ = ["CLEAN", "ExperimentFolder"]

#: the name of the clean sequence in an experiment's summaries
CLEAN = "baseline"


class ExperimentFolder:
    """The experiment folder ``root`` read for a page written into ``out_dir``; ``warn`` is
    told each problem (``warning: ...``) as it is met."""

    def __init__(self, root: Path, out_dir: Path, warn: Callable[[str], None]):
        self.root, self.out_dir, self.warn = root, out_dir, warn
        self.problems: list[str] = []

    def json(self, path: Path) -> dict[str, Any] | None:
        """The JSON object at ``path``, or ``None`` with the problem noted (never raises)."""
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            self.problem(f"{self.rel(path)}: cannot be read ({exc}); its part of the report is left out")
            return None
        if not isinstance(data, dict):
            self.problem(f"{self.rel(path)}: holds a JSON {type(data).__name__}, not an object; its part of the report is left out")
            return None
        return data

    def summaries(self, part: str, pattern: str) -> list[tuple[Path, dict[str, Any]]] | None:
        """The readable JSON files matching ``pattern`` under ``root/part``, sorted by path;
        ``None`` when there is none at all (that command was not run)."""
        root = self.root / part
        found = root.glob(pattern) if root.is_dir() else []  # not in hidden folders: outputs being replaced
        paths = sorted(p for p in found if not any(part.startswith(".") for part in p.relative_to(root).parts))
        if not paths:
            return None
        return [(path, data) for path in paths if (data := self.json(path)) is not None]

    def problem(self, message: str) -> None:
        """Note ``message`` on the page and warn."""
        self.problems.append(message)
        self.warn(f"warning: {message}")

    def picture(self, source: Path, name: str, alt: str, css: str = "plot") -> str:
        """Copy the PNG ``source`` to ``assets/<name>`` and return its <img>, or a note when absent."""
        if not source.is_file():
            return f"<p class='dim'>missing: {esc(self.rel(source))}</p>"
        target = self.out_dir / "assets" / name
        copy_file(source, target)
        return f"<img class='{css}' src='{asset_src(target, self.out_dir)}' alt='{esc(alt)}' loading='lazy'>"

    def rel(self, path: Path) -> str:
        """``path`` relative to the experiment folder (as it is, when outside it)."""
        try:
            return path.relative_to(self.root).as_posix()
        except ValueError:
            return str(path)
