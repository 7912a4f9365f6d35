"""Sizes in bytes written as text: ``parse_size("500MB")`` for ``--sal-cache-size`` and friends."""

from __future__ import annotations

import re

__all__ = ["parse_size"]

_UNITS = {"": 1, "b": 1}
for _power, _letter in enumerate("kmgt", start=1):
    _UNITS[_letter] = _UNITS[_letter + "b"] = 1000**_power
    _UNITS[_letter + "i"] = _UNITS[_letter + "ib"] = 1024**_power
_SIZE = re.compile(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([a-z]*)\s*", re.IGNORECASE)


def parse_size(text: str | int) -> int:
    """Bytes of a size such as ``"500MB"``, ``"2G"``, ``"1.5GiB"``, ``"4096"`` or ``"2 gb"``.

    ``K``/``M``/``G``/``T`` (with or without ``B``) are powers of 1000, ``Ki``/``Mi``/``Gi``/``Ti``
    (with or without ``B``) powers of 1024; case does not matter; fractions are rounded to bytes.

    Raises:
        ValueError: for anything else, quoting the text.
    """
    if isinstance(text, int) and not isinstance(text, bool):
        if text < 0:
            raise ValueError(f"invalid size {text}: must be >= 0 bytes")
        return text
    match = _SIZE.fullmatch(str(text))
    unit = match.group(2).lower() if match else None
    if match is None or unit not in _UNITS:
        raise ValueError(
            f"invalid size {text!r}: expected bytes with an optional unit, e.g. 500MB, 2G, 1.5GiB, 4096 "
            "(K, M, G, T = powers of 1000; Ki, Mi, Gi, Ti = powers of 1024)"
        )
    return round(float(match.group(1)) * _UNITS[unit])
