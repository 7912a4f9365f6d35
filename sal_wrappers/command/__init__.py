"""``command``: any external program as the system under test.

``system`` is the :class:`~sal_wrappers.base.SlamSystem` (``CommandSystem``); ``options`` its
options; ``placeholders`` the ``{placeholders}`` of its command line; ``files`` the files whose
content is part of its identity; ``output`` reading the trajectory the program writes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sal_adapters.common.lazy import lazy_exports

if TYPE_CHECKING:
    from sal_wrappers.command.system import CommandSystem

__all__ = ["CommandSystem"]

__getattr__, __dir__ = lazy_exports(__name__, {"sal_wrappers.command.system": ["CommandSystem"]})
