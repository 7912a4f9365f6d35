"""Stored JSON checked against the dataclass it is read into: ``read_fields``.

A history file is user-owned and can be edited by hand, so nothing read back is trusted: every
field must have its declared type (``str``, ``int``, ``float``, ``bool``, ``X | None``,
``list[X]``, ``tuple[X, Y]``, ``tuple[X, ...]``, ``dict[str, X]``, a nested dataclass, a mapping
type such as ``RunRecord`` as a ``dict[str, Any]``), numbers must be finite,
and nesting is bounded (``MAX_NESTING``) before anything recurses into it. Free-form values
(``Any``: metrics, system options) may hold any JSON; a non-finite number there reads as
``None`` (not available), as ``json_safe`` writes it.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Mapping
from typing import Any

__all__ = ["MAX_NESTING", "nesting_problem", "read_fields"]

#: the deepest nesting of lists and mappings a stored value may have (an outcome needs 6)
MAX_NESTING = 32
#: the integer range a stored integer may have (int64; larger ones are edits, not results)
_INT_RANGE = range(-(2**63), 2**63)


def nesting_problem(value: Any, limit: int = MAX_NESTING) -> str | None:
    """Where ``value`` nests lists and mappings deeper than ``limit`` (``trials[0].runs``),
    or ``None``; iterative, so any depth is safe to check."""
    stack: list[tuple[Any, str, int]] = [(value, "", 0)]
    while stack:
        item, key, depth = stack.pop()
        if not isinstance(item, (dict, list)):
            continue
        if depth >= limit:
            return f"{key or 'the value'} nests deeper than {limit} levels"
        pairs = item.items() if isinstance(item, dict) else enumerate(item)
        stack += [(child, _join(key, name), depth + 1) for name, child in pairs]
    return None


def read_fields(cls: type, data: Any, key: str = "") -> dict[str, Any]:
    """``data`` (a mapping read from JSON) as keyword arguments of the dataclass ``cls``: each
    field of ``cls`` checked against its type and nested dataclasses read the same way (as
    dicts of their fields); keys ``cls`` does not have are left out.

    Raises:
        ValueError: a field is missing, of another type or not a finite number, naming its key
            (``boundary.pass_value = 'abc' is not a finite number``).
    """
    if not isinstance(data, dict):
        raise ValueError(f"{key or 'the value'} is not a mapping")
    hints = typing.get_type_hints(cls)
    read = {}
    for spec in dataclasses.fields(cls):
        name = _join(key, spec.name)
        if spec.name in data:
            read[spec.name] = _read(data[spec.name], hints[spec.name], name)
        elif spec.default is dataclasses.MISSING and spec.default_factory is dataclasses.MISSING:
            raise ValueError(f"{name} is missing")
    return read


def _read(value: Any, hint: Any, key: str) -> Any:
    """``value`` checked against ``hint``; free-form parts with non-finite numbers as ``None``."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is Any:
        return _free(value)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        (inner,) = [arg for arg in args if arg is not type(None)]
        return _read(value, inner, key)
    if isinstance(hint, type) and issubclass(hint, Mapping):  # a dict, or a type that reads like one
        hint = dict[str, Any]
        origin, args = dict, (str, Any)
    if dataclasses.is_dataclass(hint):
        return read_fields(hint, value, key)  # type: ignore[arg-type]
    if hint in (float, int):
        return _number(value, hint, key)
    if hint in (str, bool):
        if not isinstance(value, hint):
            raise ValueError(f"{key} = {_shown(value)} is not {'a text' if hint is str else 'true or false'}")
        return value
    if origin is list or origin is tuple:
        fixed = origin is tuple and args[-1:] != (...,)
        if not isinstance(value, (list, tuple)) or (fixed and len(value) != len(args)):
            raise ValueError(f"{key} is not a list" + (f" of {len(args)}" if fixed else ""))
        kinds = list(args) if fixed else [args[0]] * len(value)
        return [_read(item, kind, f"{key}[{i}]") for i, (item, kind) in enumerate(zip(value, kinds))]
    if origin is dict:
        if not isinstance(value, dict):
            raise ValueError(f"{key} is not a mapping")
        kind = args[1] if args else Any
        return {name: _read(item, kind, _join(key, name)) for name, item in value.items()}
    raise TypeError(f"{key}: no reader for the type {hint!r}")


def _number(value: Any, hint: type, key: str) -> float | int:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{key} = {_shown(value)} is not a finite number")
    if isinstance(value, int) and value not in _INT_RANGE:
        raise ValueError(f"{key} = {_shown(value)} is out of range")
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"{key} = {_shown(value)} is not a finite number")
    if hint is int and not isinstance(value, int):
        raise ValueError(f"{key} = {_shown(value)} is not an integer")
    return value


def _free(value: Any) -> Any:
    """Any JSON value; a non-finite or out-of-range number becomes ``None``."""
    if isinstance(value, dict):
        return {name: _free(item) for name, item in value.items()}
    if isinstance(value, list):
        return [_free(item) for item in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, int) and not isinstance(value, bool) and value not in _INT_RANGE:
        return None
    return value


def _join(key: str, name: object) -> str:
    if isinstance(name, int):
        return f"{key}[{name}]"
    return f"{key}.{name}" if key else str(name)


def _shown(value: Any) -> str:
    return repr(str(value)[:40])
