"""How a number reads in every message and report: ``num`` (``12.35``, 4 significant digits by
default) and ``with_unit`` (``12.35 m``); both say ``-`` for an unknown value.

This is the engine's, below the reports, because the engine's own words need it: the boundary
interval's text (``Boundary.text`` and ``Boundary.short_text`` in ``pytest_sal.engine.outcomes.outcome``)
is written into a failing test's message (``pytest_sal.engine.search.requirement_search``) as well as
into every report. ``pytest_sal.report.formatting`` builds the reports' other texts (metrics,
changes, trial lines) on these two, so a value is formatted by one function wherever it shows.
"""

from __future__ import annotations

__all__ = ["num", "with_unit"]


def num(value: float | None, digits: int = 4) -> str:
    """``value`` to ``digits`` significant digits (``12.35``, ``1e+05``; ``digits=6`` is Python's
    ``:g``, the value as the search set it); ``-`` when unknown."""
    return "-" if value is None else f"{value:.{digits}g}"


def with_unit(value: float | None, unit: str, digits: int = 4) -> str:
    """``num(value, digits)`` followed by ``unit`` (``12.35 m``; no space without a unit);
    ``-`` when unknown."""
    return "-" if value is None else f"{num(value, digits)}{' ' + unit if unit else ''}"
