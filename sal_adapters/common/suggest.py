"""The hint after a misspelt name: ``; did you mean 'visibility_m'?``, else the names there are.

>>> "fog has no parameter 'visibilty_m'" + suggestion("visibilty_m", ["visibility_m", "heterogeneity"], "parameters")
"fog has no parameter 'visibilty_m'; did you mean 'visibility_m'?"
>>> "unknown metric 'xyz'" + suggestion("xyz", ["ate_rmse", "tracking_rate"], "metrics")
"unknown metric 'xyz'; metrics: ate_rmse, tracking_rate"

Every place a user types a name (a parameter, a module, a metric, an address) uses it, so they
all answer a typo the same way.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable

__all__ = ["closest", "suggestion"]


def closest(name: str, known: Iterable[str]) -> str | None:
    """The known name most like ``name`` (``difflib`` similarity ratio >= 0.6), or ``None``."""
    found = difflib.get_close_matches(str(name), [str(k) for k in known], n=1)
    return found[0] if found else None


def suggestion(name: str, known: Iterable[str], listing: str) -> str:
    """``; did you mean 'close'?`` when a known name is close to ``name``, else
    ``; <listing>: a, b, c`` (``none`` when nothing is known)."""
    names = list(dict.fromkeys(str(k) for k in known))
    close = closest(name, names)
    if close is not None:
        return f"; did you mean {close!r}?"
    return f"; {listing}: {', '.join(names) or 'none'}"
