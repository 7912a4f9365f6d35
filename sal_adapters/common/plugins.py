"""Registries fed by entry-point groups (``sal.datasets``, ``sal.perturbations``, ``sal.systems``).

Built-ins register through the same groups as third-party packages (see ``pyproject.toml``), so
both are found the same way. Entries are imported only when first asked for, and an entry that
fails to import is reported by name with the reason, never silently left out.
"""

from __future__ import annotations

from importlib.metadata import EntryPoint, entry_points
from typing import Generic, TypeVar

from sal_adapters.common.errors import SalError
from sal_adapters.common.suggest import suggestion

__all__ = ["EntryPointRegistry", "PluginError"]

T = TypeVar("T")


class PluginError(SalError, LookupError):
    """An unknown name, or a registered entry that cannot be loaded."""


class EntryPointRegistry(Generic[T]):
    """Name -> object, from an entry-point group plus objects registered in code.

    Args:
        group: entry-point group, e.g. ``"sal.datasets"``.
        what: what the entries are, for messages (``"dataset kind"``).
    """

    def __init__(self, group: str, what: str):
        self.group = group
        self.what = what
        self._registered: dict[str, T] = {}
        self._loaded: dict[str, T] = {}

    def _entry_points(self) -> dict[str, EntryPoint]:
        return {ep.name: ep for ep in entry_points(group=self.group)}

    def names(self) -> list[str]:
        """Every known name, sorted."""
        return sorted(set(self._entry_points()) | set(self._registered))

    def register(self, name: str, obj: T) -> None:
        """Add ``obj`` under ``name`` in this process (replaces an entry point of that name)."""
        self._registered[name] = obj

    def unregister(self, name: str) -> None:
        """Forget an object added with ``register``."""
        self._registered.pop(name, None)

    def get(self, name: str) -> T:
        """The object registered as ``name``; ``PluginError`` lists the known names."""
        if name in self._registered:
            return self._registered[name]
        if name in self._loaded:
            return self._loaded[name]
        eps = self._entry_points()
        if name not in eps:
            raise PluginError(self.unknown(name))
        try:
            obj = eps[name].load()
        except Exception as exc:  # a plug-in's import error must name the plug-in
            raise PluginError(f"{self.what} {name!r} ({eps[name].value}) failed to load: {type(exc).__name__}: {exc}") from exc
        self._loaded[name] = obj
        return obj

    def unknown(self, name: str) -> str:
        """``unknown perturbation module 'fgo'; did you mean 'fog'? (entry-point group ...)``, or
        the known names when none is close."""
        return f"unknown {self.what} {name!r}" + suggestion(name, self.names(), "known") + f" (entry-point group {self.group!r})"

    def items(self) -> list[tuple[str, T]]:
        """``(name, object)`` for every entry, loading each."""
        return [(name, self.get(name)) for name in self.names()]
