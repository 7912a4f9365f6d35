"""SLAM systems under test (registry: entry-point group ``sal.systems``)."""

from sal_adapters.plugins import EntryPointRegistry

__all__ = ["SYSTEMS"]

#: SLAM systems by name; built-ins and plug-ins register in ``sal.systems``.
SYSTEMS: EntryPointRegistry[type] = EntryPointRegistry("sal.systems", "SLAM system")
