"""Reading one run file of the history, trusting nothing in it (``History`` builds its
``RunRecord`` from what these return).

A run file is user-owned: it may have been edited by hand, merged by git or written by another
version. What is wrong is skipped, not raised, with one warning naming the file, the test and
the key: an outcome whose fields are not what ``Outcome`` declares (``test_id: 5``, a ``NaN``,
``1e999`` or a 5000-digit number anywhere in it, nesting deeper than
``json_shape.MAX_NESTING``) is left out and the run's other outcomes are kept; a file whose top
level is wrong (not JSON, another format version, ``name: ["main"]``, ``outcomes`` not a list,
nesting deeper than ``PARSE_NESTING``) is left out whole.
"""

from __future__ import annotations

import dataclasses
import json
import re
import warnings
from itertools import accumulate
from pathlib import Path
from typing import Any

from pytest_sal.engine.outcomes.json_shape import MAX_NESTING, nesting_problem, read_fields
from pytest_sal.engine.outcomes.outcome import Outcome

__all__ = ["FORMAT_VERSION", "PARSE_NESTING", "read_document", "read_outcomes"]

#: the ``version`` written into every run file
FORMAT_VERSION = 1
#: files nesting deeper are not parsed (the parser recurses once per level: far below
#: Python's recursion limit however deep the caller's stack)
PARSE_NESTING = 200

_STRING = re.compile(r'"(?:[^"\\]|\\.)*"')
_BRACKET = re.compile(r"[\[\]{}]")
_INT_DIGITS = 19  # longer integers are read as floats (inf beyond 1e308), refused where a field needs an int


@dataclasses.dataclass(frozen=True)
class _Header:
    """The top level of a run file, less its outcomes (their shape is ``Outcome``'s)."""

    version: int
    created: str = ""
    commit: str | None = None
    dirty: bool = False
    machine: dict[str, Any] = dataclasses.field(default_factory=dict)
    name: str | None = None


def read_document(path: Path) -> dict[str, Any]:
    """The run file at ``path``: its checked top level (``_Header``'s fields) and ``outcomes``,
    the stored outcomes as they are (``read_outcomes`` checks each).

    Raises:
        OSError: the file cannot be read.
        ValueError: it is not a run file of this format, naming the key that is wrong.
    """
    text = path.read_text(encoding="utf-8")
    levels = max(accumulate(1 if b in "[{" else -1 for b in _BRACKET.findall(_STRING.sub("", text))), default=0)
    if levels > PARSE_NESTING:
        raise ValueError(f"nests {levels} levels deep (a run file nests about 8, at most {PARSE_NESTING} are read)")
    data = json.loads(text, parse_int=_bounded_int)
    if not isinstance(data, dict):
        raise ValueError(f"the file holds a {type(data).__name__}, not a run")
    if data.get("version") != FORMAT_VERSION or isinstance(data.get("version"), bool):
        raise ValueError(f"format version {str(data.get('version'))[:20]!r}, this pytest-sal reads {FORMAT_VERSION}")
    problem = nesting_problem(data.get("machine"), MAX_NESTING)
    if problem is not None:
        raise ValueError(f"machine: {problem}")
    header = read_fields(_Header, data)
    outcomes = data.get("outcomes", [])
    if not isinstance(outcomes, list):
        raise ValueError("outcomes is not a list")
    return header | {"outcomes": outcomes}


def read_outcomes(path: Path, stored: list[Any]) -> list[Outcome]:
    """The run's outcomes; one that is not an outcome (``Outcome.from_dict`` refuses it) is
    skipped with a warning naming the file, the test and the key, the others are kept."""
    outcomes = []
    for number, data in enumerate(stored, 1):
        try:
            outcomes.append(Outcome.from_dict(data))
        except ValueError as exc:
            test = data.get("test_id", "?") if isinstance(data, dict) else "?"
            warnings.warn(f"{path}: outcome {number} ({str(test)[:200]}) skipped: {exc}", stacklevel=4)
    return outcomes


def _bounded_int(text: str) -> int | float:
    """An integer of the file; a longer one than any result has becomes a float (``inf``
    beyond 1e308), so that it is refused with its key instead of failing the whole parse."""
    return int(text) if len(text) <= _INT_DIGITS else float(text)
