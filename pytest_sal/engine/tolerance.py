"""A boundary search's ``tolerance``: how narrow the bracket around the failure point must get
before the search stops. One meaning wherever it is given (``sal.require(tolerance=)``, the ini
key ``sal_tolerance``, the YAML key ``robustness_boundary.tolerance``):

* a number is a width in the parameter's unit: ``tolerance=5`` on ``fog.visibility_m`` stops
  once the bracket is at most 5 m wide (20-25 m);
* a string ``"N%"`` is a share of the bracket's larger end (by magnitude): ``"10%"`` stops at
  20-22 m, and suits a parameter searched over decades (0.08-0.09 Mbit/s) as well.

The ini key sets the default of every requirement, whatever its parameter's unit, so it takes
the percent form only; a bare number there is its old form, still read as a percent with a
``SalDeprecationWarning`` (``ini_tolerance_percent``).
"""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["TOLERANCE_FORMS", "Tolerance", "ini_tolerance_percent", "parse_tolerance", "search_tolerances"]

#: the forms a tolerance takes, in words (every error about one says this)
TOLERANCE_FORMS = "a number > 0 in the parameter's unit, or a percent of the bracket's larger end such as \"10%\""

_PERCENT = re.compile(r"\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*%\s*")


@dataclass(frozen=True)
class Tolerance:
    """A tolerance read: ``absolute`` (the parameter's unit) or ``percent`` (of the bracket's
    larger end); exactly one is set."""

    absolute: float | None = None
    percent: float | None = None

    @property
    def share(self) -> float | None:
        """``percent`` as a share (10 % -> 0.1), ``None`` for an absolute tolerance."""
        return None if self.percent is None else self.percent / 100

    def step(self, low: float, high: float) -> float:
        """The widest bracket it allows within ``low .. high`` (the percent form: of the larger end)."""
        if self.absolute is not None:
            return self.absolute
        return (self.share or 0.0) * max(abs(low), abs(high))

    def text(self, unit: str = "") -> str:
        """``5 m``, or ``10% of the bracket's larger end``."""
        if self.absolute is not None:
            return f"{self.absolute:g}{f' {unit}' if unit else ''}"
        return f"{self.percent:g}% of the bracket's larger end"


def parse_tolerance(value: Any) -> Tolerance:
    """``value`` as a ``Tolerance``: a number > 0 (absolute) or a string ``"N%"`` with N > 0;
    a ``ValueError`` saying the forms (``TOLERANCE_FORMS``) otherwise."""
    if isinstance(value, numbers.Real) and not isinstance(value, bool):
        number = float(value)
        if math.isfinite(number) and number > 0:
            return Tolerance(absolute=number)
    elif isinstance(value, str):
        match = _PERCENT.fullmatch(value)
        if match is not None and math.isfinite(float(match[1])) and float(match[1]) > 0:
            return Tolerance(percent=float(match[1]))
    raise ValueError(f"must be {TOLERANCE_FORMS}")


def search_tolerances(options: Mapping[str, Any], default_percent: float) -> tuple[float | None, float | None]:
    """``(tolerance, rel_tolerance)`` as the searches take them: a requirement's ``tolerance``
    option read by ``parse_tolerance``, else ``default_percent`` (ini ``sal_tolerance``) as a share."""
    given = options.get("tolerance")
    if given is None:
        return None, default_percent / 100
    tolerance = parse_tolerance(given)
    return tolerance.absolute, tolerance.share


def ini_tolerance_percent(text: str) -> tuple[float, str | None]:
    """The ini ``sal_tolerance`` ``text`` as a percent, and a deprecation message when it is the
    old form (a bare number, read as a percent); a ``ValueError`` when it is neither."""
    try:
        tolerance = parse_tolerance(text)
    except ValueError:
        try:
            old = parse_tolerance(float(text))
        except ValueError:
            raise ValueError('expected a percent > 0 of the bracket\'s larger end, such as "10%"') from None
        percent = float(old.absolute or 0)
        return percent, (
            f"ini option sal_tolerance = {text.strip()}: a bare number is the old form, read as {percent:g}% of the bracket's "
            f"larger end; write sal_tolerance = {percent:g}% (a number alone means the parameter's unit in sal.require "
            "and in YAML)"
        )
    return float(tolerance.percent or 0), None
