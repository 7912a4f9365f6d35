"""Cache keys: the SHA-256 of the canonical JSON of everything that decides a cached result.

``cache_key(dataset=..., module=..., seed=..., system=..., runs=...)`` names a trial; equal
values give equal keys whatever the order of keywords or mapping keys, and any change of a part
gives another key. :mod:`pytest_sal.store.content_cache` stores entries under these keys.
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import json
import math
import os
from collections.abc import Mapping
from pathlib import PurePath
from typing import Any

from sal_adapters.common.errors import SalError

__all__ = ["CacheError", "cache_key", "canonical_json"]


class CacheError(SalError):
    """The cache folder or an entry cannot be used; the message starts with the path."""

    def __init__(self, message: str, path: str | os.PathLike[str] | None = None):
        self.path = None if path is None else str(path)
        super().__init__(message if self.path is None else f"{self.path}: {message}")


def canonical_json(value: Any) -> str:
    """The canonical JSON text that :func:`cache_key` hashes.

    Compact separators, mapping keys sorted, UTF-8 text kept as is. Values are normalised so
    that equal values give equal text: tuples and lists are lists; sets are sorted lists;
    integral floats are ints (``30.0`` and ``30`` are the same parameter) and ``-0.0`` is ``0``;
    other floats use Python's shortest round-trip ``repr`` (stable across platforms); NaN and
    infinities become ``{"__float__": "nan" | "inf" | "-inf"}``; ``bool`` stays distinct from
    ``int``; paths become POSIX strings; enums their value; numpy scalars and arrays their
    Python values; dataclass instances a mapping of their fields. Mapping keys must be strings.

    Raises:
        CacheError: for a value of another type, naming where it sits (``parts['system']['x']``).
    """
    return json.dumps(_canonical(value, "parts"), sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False)


def cache_key(**parts: Any) -> str:
    """SHA-256 hex digest of :func:`canonical_json` of ``parts`` (a mapping of the keyword names).

    Any change of a part changes the key; the order of keywords and of nested mapping keys does
    not. ``cache_key(b=(1, 2), a=1)`` is ``sha256(b'{"a":1,"b":[1,2]}')``. Put a format version
    among the parts when the meaning of a stored result changes.
    """
    return hashlib.sha256(canonical_json(parts).encode("utf-8")).hexdigest()


def _canonical(value: Any, where: str) -> Any:
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, enum.Enum):
        return _canonical(value.value, where)
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return {"__float__": repr(float(value))}
        if value.is_integer() and abs(value) < 2**53:
            return int(value)
        return float(value)
    if type(value).__module__ == "numpy" and hasattr(value, "tolist"):
        return _canonical(value.tolist(), where)
    if isinstance(value, PurePath):
        return value.as_posix()
    if isinstance(value, Mapping):
        out = {}
        for name, item in value.items():
            if not isinstance(name, str):
                raise CacheError(f"cache_key: {where}: mapping key {name!r} is a {type(name).__name__}; use strings")
            out[name] = _canonical(item, f"{where}[{name!r}]")
        return out
    if isinstance(value, (list, tuple)):
        return [_canonical(item, f"{where}[{i}]") for i, item in enumerate(value)]
    if isinstance(value, (set, frozenset)):
        items = [_canonical(item, f"{where}{{...}}") for item in value]
        return sorted(items, key=lambda item: json.dumps(item, sort_keys=True, allow_nan=False))
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        fields = {field.name: getattr(value, field.name) for field in dataclasses.fields(value)}
        return _canonical(fields, where)
    raise CacheError(f"cache_key: {where}: cannot hash a {type(value).__name__} ({value!r:.60}); pass JSON-ready values")
