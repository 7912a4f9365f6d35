"""``json_safe``: any result value as plain JSON data, the one conversion every JSON writer uses.

``json.dumps(json_safe(value), allow_nan=False)`` then never fails and never writes ``NaN``.
Hashes of identities (cache keys, system identity digests) do not go through here: their
bytes must stay stable, so they keep their own canonical encodings.

Imports nothing heavy: numpy values are recognised by their ``tolist`` method, so
``sal_adapters`` stays free of numpy at import time.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import PurePath
from typing import Any

__all__ = ["json_safe"]


def json_safe(value: Any) -> Any:
    """``value`` as ``dict`` / ``list`` / ``str`` / ``int`` / ``float`` / ``bool`` / ``None`` only.

    Rules, in order:

    * ``None``, ``bool``, ``str`` and ``int`` (subclasses too, e.g. an ``IntEnum``) stay as
      they are, as ``json`` writes them.
    * a ``float`` (``numpy.float64`` too) stays a float when finite; NaN and +-infinity
      become ``None``: a number that is not one counts as not available.
    * a path (``pathlib.PurePath``) becomes its text.
    * a mapping becomes a ``dict`` with ``str(key)`` keys and converted values.
    * a ``list`` or ``tuple`` becomes a list of converted items.
    * a ``set`` or ``frozenset`` becomes a sorted list of converted items (sorted by value,
      or by their JSON text when the values do not compare), so the output is stable.
    * anything with ``tolist()`` (numpy scalars and arrays) becomes the converted
      ``tolist()``: a Python scalar or nested lists.
    * anything else raises ``TypeError`` naming its type.
    """
    if value is None or isinstance(value, (bool, str, int)):
        return value
    if isinstance(value, float):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, PurePath):
        return str(value)
    if isinstance(value, Mapping):
        return {str(key): json_safe(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(item) for item in value]
    if isinstance(value, (set, frozenset)):
        return _sorted([json_safe(item) for item in value])
    if hasattr(value, "tolist"):
        return json_safe(value.tolist())
    raise TypeError(f"cannot write {type(value).__name__} {value!r} as JSON")


def _sorted(items: list[Any]) -> list[Any]:
    try:
        return sorted(items)
    except TypeError:  # mixed types (1 and "a"), dicts: order by their JSON text
        return sorted(items, key=lambda item: json.dumps(item, sort_keys=True))
