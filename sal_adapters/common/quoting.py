"""Values quoted in error messages: ``repr`` cut to a few dozen characters, safe for any value
a config or a caller can give (an integer of thousands of digits, which ``repr`` refuses past
Python's 4300-digit limit, a list of a million items)."""

from __future__ import annotations

import math
import reprlib
from typing import Any

__all__ = ["short_repr"]

#: Digits of an integer quoted whole; a longer one is shown by its number of digits.
_INT_DIGITS = 100


class _Short(reprlib.Repr):
    def repr_int(self, x: int, level: int) -> str:
        digits = int(abs(x).bit_length() * math.log10(2)) + 1
        if digits > _INT_DIGITS:
            return f"<an integer of about {digits} digits>"
        return repr(x)


_SHORT = _Short()


def short_repr(value: Any, limit: int = 80) -> str:
    """``repr(value)`` of at most ``limit`` characters (containers shortened item by item, an
    integer of more than 100 digits shown by its number of digits)."""
    if isinstance(value, (dict, list, tuple, set, frozenset, int)):
        text = _SHORT.repr(value)
    else:
        text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
