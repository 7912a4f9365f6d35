"""Replace one marked section of benchmarks/RESULTS.md, keeping everything around it."""

from __future__ import annotations

from pathlib import Path

__all__ = ["write_section"]

RESULTS = Path(__file__).with_name("RESULTS.md")


def write_section(key: str, title: str, body: str, path: Path = RESULTS) -> None:
    """Put ``body`` between ``<!-- key:begin -->`` and ``<!-- key:end -->`` in ``path``; a new
    section (headed ``## title``) is appended when the markers are not there yet."""
    begin, end = f"<!-- {key}:begin -->", f"<!-- {key}:end -->"
    text = path.read_text()
    section = f"{begin}\n{body}\n{end}"
    if begin in text:
        text = text[: text.index(begin)] + section + text[text.index(end) + len(end) :]
    else:
        text = text.rstrip() + f"\n\n## {title}\n\n" + section + "\n"
    path.write_text(text)
