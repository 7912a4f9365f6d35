"""SLAM systems under test (registry: entry-point group ``sal.systems``).

>>> from sal_wrappers import create
>>> system = create("reference_vo")                       # doctest: +SKIP
>>> result = system.run(sequence, workdir, timeout=120)    # doctest: +SKIP
>>> result.tracking_rate, result.trajectory                # doctest: +SKIP

The registry and ``create`` are light; the other names load their module on first use
(``sal_adapters.common.lazy``), so naming a system does not pull numpy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from sal_adapters.common.lazy import lazy_exports
from sal_adapters.common.plugins import EntryPointRegistry

if TYPE_CHECKING:  # what type checkers see; at run time each name loads on first use
    from sal_wrappers.base import RunResult, SlamSystem, SlamSystemError, TrackState
    from sal_wrappers.pacing import machine_load, oversubscribed_warning

__all__ = ["SYSTEMS", "RunResult", "SlamSystem", "SlamSystemError", "TrackState", "create", "machine_load", "oversubscribed_warning"]

#: SLAM systems by name; built-ins and plug-ins register in ``sal.systems``.
SYSTEMS: EntryPointRegistry[type[SlamSystem]] = EntryPointRegistry("sal.systems", "SLAM system")


def create(kind: str, /, **options: Any) -> SlamSystem:
    """A configured SLAM system: ``create("orbslam3", features=2000)``. An unknown kind lists
    the known ones; a bad option is a ``SlamSystemError`` naming it. ``kind`` is the registry
    name; an option ``name=`` goes to the system (``command`` takes it as its display name)."""
    return SYSTEMS.get(kind)(**options)


__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "sal_wrappers.base": ["RunResult", "SlamSystem", "SlamSystemError", "TrackState"],
        "sal_wrappers.pacing": ["machine_load", "oversubscribed_warning"],
    },
)
