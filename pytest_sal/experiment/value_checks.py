"""The value checks every section of an experiment config goes through: a mapping with known
keys, a typed value (with a minimum), a path a file system can take, a folder name, a
registered plug-in, a dataset option against its annotation. Each failed check is one
``ConfigError`` naming the file, the key's path and what is allowed.
"""

from __future__ import annotations

import math
import os
import re
import types
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeGuard, TypeVar

from pytest_sal.experiment.schema import MAX_FRAMES, MAX_NAME_BYTES, MAX_PATH_BYTES, MAX_SEARCH_RUNS, MAX_SEARCH_TRIALS
from pytest_sal.experiment.yaml_loader import NAME_CHARS, ConfigError, key_text
from sal_adapters.common.bounded_yaml import QUOTE_CHARS, one_line, quote, type_name
from sal_adapters.common.plugins import EntryPointRegistry, PluginError
from sal_adapters.common.suggest import suggestion
from sal_adapters.datasets import DatasetKind

__all__ = ["SAFE_NAME_TEXT", "ValueChecks", "is_finite", "is_number", "option_hints"]

T = TypeVar("T")

SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,99}")
SAFE_NAME_TEXT = "1 to 100 letters, digits, '_', '-', '.' (not first)"


def is_number(value: Any) -> TypeGuard[int | float]:
    """An int or a float (not a bool)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def is_finite(value: Any) -> bool:
    """A number, not NaN nor infinite (nor an integer too large for a float)."""
    try:
        return is_number(value) and math.isfinite(value)
    except OverflowError:  # an integer beyond any float
        return False


#: What a dataset option annotated with each type takes from YAML: (words, check).
_OPTION_TYPES: dict[Any, tuple[str, Callable[[Any], bool]]] = {
    type(None): ("null", lambda v: v is None),
    bool: ("true or false", lambda v: isinstance(v, bool)),
    int: ("an integer", lambda v: isinstance(v, int) and not isinstance(v, bool)),
    float: ("a number", is_finite),
    str: ("a string", lambda v: isinstance(v, str)),
    Path: ("a path", lambda v: isinstance(v, str)),
}


def _alternatives(hint: Any) -> tuple[Any, ...]:
    """The types of the annotation ``hint`` (``str | None``: ``str``, ``NoneType``)."""
    return typing.get_args(hint) if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union else (hint,)


def _option_types(hint: Any) -> list[tuple[str, Callable[[Any], bool]]] | None:
    """(words, check) of each type an option annotated ``hint`` may be (``tuple[float, ...]``:
    a list of numbers), or ``None`` for an annotation not known here."""
    found = []
    alternatives = _alternatives(hint)
    for alt in alternatives:
        items = typing.get_args(alt) if typing.get_origin(alt) is tuple else ()
        if alt is str and Path in alternatives:
            continue
        if alt in _OPTION_TYPES:
            found.append(_OPTION_TYPES[alt])
        elif items and set(items) <= {int, float, Ellipsis}:
            n = None if Ellipsis in items else len(items)

            def numbers(v: Any, n: int | None = n) -> bool:
                return isinstance(v, list) and n in (None, len(v)) and all(is_finite(x) for x in v)

            found.append((f"a list of {n or 'some'} numbers", numbers))
        else:
            return None
    return found


def option_hints(kind: DatasetKind) -> dict[str, Any]:
    """The annotations of the options of a dataset kind (none where they cannot be read)."""
    try:
        return typing.get_type_hints(kind.open)
    except Exception:  # a plug-in's annotation naming what its module does not import
        return {}


class ValueChecks:
    """Checks of the values of the config read from ``source`` (the file's name in errors)."""

    def __init__(self, source: str):
        self.source = source

    def error(self, where: str, message: str) -> ConfigError:
        """The ``ConfigError`` of the key at ``where``."""
        return ConfigError(self.source, where, message)

    def mapping(self, value: Any, where: str, known: tuple[str, ...], required: tuple[str, ...] = ()) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.error(where or "top level", f"must be a mapping with keys {', '.join(known)}; got {type_name(value)}")
        prefix = f"{where}." if where else ""
        for key in value:
            if key not in known:
                raise self.error(f"{prefix}{key_text(key)}", "unknown key" + suggestion(str(key), known, "known"))
        for key in required:
            if value.get(key) is None:
                raise self.error(f"{prefix}{key}", "is required")
        return value

    def typed(
        self, value: Any, where: str, kind: str, *, optional: bool = False, minimum: float | None = None, maximum: int | None = None
    ) -> Any:
        """``value`` if it is of ``kind`` (``str``, ``bool``, ``int``, ``number``: an int or a
        float, not an integer beyond any float; ``dict``, ``list``) and within ``minimum`` ..
        ``maximum``, else one ``ConfigError`` naming ``where``; a number as a float."""
        if value is None and optional:
            return None
        ok = {
            "str": isinstance(value, str),
            "bool": isinstance(value, bool),
            "int": isinstance(value, int) and not isinstance(value, bool),
            "number": is_number(value) and (isinstance(value, float) or is_finite(value)),  # NaN: the caller's words
            "dict": isinstance(value, dict),
            "list": isinstance(value, list),
        }[kind]
        words = {
            "str": "a string",
            "bool": "true or false",
            "int": "an integer",
            "number": "a number",
            "dict": "a mapping",
            "list": "a list",
        }[kind]
        if minimum is not None:
            words += f" >= {minimum:g}"
        if maximum is not None:
            words += f" and <= {maximum}" if minimum is not None else f" <= {maximum}"
        if optional:
            words += " or null"
        if not ok or (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
            raise self.error(where, f"{quote(value)} is not valid; must be {words}")
        return float(value) if kind == "number" else value

    def search_trials(self, value: Any, where: str) -> int:
        """A number of boundary search trials, 1 .. ``MAX_SEARCH_TRIALS``."""
        trials = self.typed(value, where, "int", minimum=1)
        if trials > MAX_SEARCH_TRIALS:
            raise self.error(where, f"{trials} is not valid; the limit is {MAX_SEARCH_TRIALS} trials")
        return trials

    def search_runs(self, value: Any, where: str) -> int:
        """A noisy system's run budget, 1 .. ``MAX_SEARCH_RUNS``."""
        runs = self.typed(value, where, "int", minimum=1)
        if runs > MAX_SEARCH_RUNS:
            raise self.error(where, f"{runs} is not valid; the limit is {MAX_SEARCH_RUNS} runs")
        return runs

    def frame_count(self, value: Any, where: str) -> int | None:
        """An optional frame count, 1 .. ``MAX_FRAMES``."""
        count = self.typed(value, where, "int", optional=True, minimum=1)
        if count is not None and count > MAX_FRAMES:
            raise self.error(where, f"{count} is not valid; the limit is {MAX_FRAMES} frames")
        return count

    def path(self, value: Any, where: str, *, optional: bool = False) -> str | None:
        """A path-valued key (every one is checked by ``checked_path``): a string a file system
        can take, with no NUL character, at most ``MAX_PATH_BYTES`` long and ``MAX_NAME_BYTES``
        per name."""
        text = self.typed(value, where, "str", optional=optional)
        return None if text is None else self.checked_path(text, where)

    def checked_path(self, text: str, where: str) -> str:
        """``text``, refused if it cannot be a path (see ``path``)."""
        if "\0" in text:
            raise self.error(where, f"contains a NUL character ({quote(text)}); no path can hold one")
        try:
            encoded = os.fsencode(text)
        except UnicodeEncodeError:
            raise self.error(where, f"{quote(text)} holds a character no file name can hold here") from None
        longest = max(encoded.split(b"/"), key=len)
        if len(encoded) > MAX_PATH_BYTES or len(longest) > MAX_NAME_BYTES:
            raise self.error(
                where,
                f"{quote(text)} is too long ({len(encoded)} bytes, a name of {len(longest)}); "
                f"a path may have at most {MAX_PATH_BYTES} bytes and each name in it {MAX_NAME_BYTES}",
            )
        return text

    def folder(self, value: Any, where: str) -> Path:
        """A path-valued key with ``$VARIABLES`` and ``~`` expanded, then checked."""
        text = self.typed(value, where, "str")
        return Path(self.checked_path(os.path.expanduser(os.path.expandvars(text)), where))

    def option(self, value: Any, where: str, hint: Any) -> None:
        """A dataset option checked against its annotation in the dataset kind's ``open``
        (a value of an annotation ``_option_types`` does not know is left to the kind)."""
        allowed = _option_types(hint)
        if allowed is None:
            return
        if not any(fits(value) for _, fits in allowed):
            words = [w for w, _ in allowed]
            raise self.error(
                where, f"{quote(value)} is not valid; must be {', '.join(words[:-1]) + ' or ' if len(words) > 1 else ''}{words[-1]}"
            )
        if isinstance(value, str) and Path in _alternatives(hint):
            self.checked_path(value, where)

    def registered(
        self, registry: EntryPointRegistry[T], name: str, where: str, known: tuple[str, ...] = (), hidden: tuple[str, ...] = ()
    ) -> T:
        """The entry ``name`` of ``registry``. Only an error lists the names (``known`` first,
        not ``hidden``): listing reads the entry points of every installed package."""
        try:
            return registry.get(name)
        except PluginError as exc:
            names = [n for n in registry.names() if n not in hidden]
            if name in names:  # installed, but it cannot be loaded
                raise self.error(where, one_line(str(exc), 3 * QUOTE_CHARS)) from None
            raise self.error(
                where, f"unknown {registry.what} {quote(name, NAME_CHARS)}" + suggestion(name, [*known, *names], "known")
            ) from None

    def safe_name(self, value: Any, where: str) -> str:
        self.typed(value, where, "str")
        if not SAFE_NAME.fullmatch(value):  # fullmatch: "name\n" is refused too (match's $ allows it)
            raise self.error(where, f"{quote(value)} cannot be a folder name; use {SAFE_NAME_TEXT}")
        return value
