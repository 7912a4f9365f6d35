"""Lazy package namespaces (PEP 562): a package's public names import their module on first use.

pytest imports the plugin in every session of an environment with pytest-sal installed, so
``import pytest_sal`` and ``import sal_adapters`` must not pull numpy, OpenCV or scipy; a name
such as ``sal_adapters.open_dataset`` loads ``sal_adapters.datasets`` the first time it is read.

In a package's ``__init__.py``::

    __getattr__, __dir__ = lazy_exports(__name__, {"sal_adapters.datasets": ["DATASETS", "open_dataset"]})
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from sal_adapters.common.suggest import suggestion

__all__ = ["lazy_exports"]


def lazy_exports(
    package: str, exports: Mapping[str, Iterable[str]], fallback: Callable[[str], Any] | None = None
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The module ``__getattr__`` and ``__dir__`` of ``package``.

    Args:
        package: the package's ``__name__``.
        exports: module -> the public names it defines (as the ``from module import ...``
            lines would say); a name read once is stored on the package, so later reads cost
            nothing.
        fallback: called with any other public name (``sal_modules.fog``: a registered class);
            it raises ``AttributeError`` for names it does not know.
    """

    home = {name: module for module, names in exports.items() for name in names}

    def __getattr__(name: str) -> Any:
        module = home.get(name)
        if module is not None:
            value = getattr(importlib.import_module(module), name)
            setattr(sys.modules[package], name, value)
            return value
        if fallback is not None and not name.startswith("_"):
            return fallback(name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}" + suggestion(name, home, "names"))

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(home))

    return __getattr__, __dir__
