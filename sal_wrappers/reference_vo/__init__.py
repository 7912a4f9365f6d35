"""``reference_vo``: the built-in, deterministic visual odometry (OpenCV only, in process).

``system`` is the :class:`~sal_wrappers.base.SlamSystem`; ``odometry`` its per-frame state
machine; ``lens`` the working camera; ``features`` ORB features and matching; ``geometry``
depth, poses and triangulation; ``bundle`` the local bundle adjustment of the monocular mode.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sal_adapters.common.lazy import lazy_exports

if TYPE_CHECKING:
    from sal_wrappers.reference_vo.system import ReferenceVO

__all__ = ["ReferenceVO"]

__getattr__, __dir__ = lazy_exports(__name__, {"sal_wrappers.reference_vo.system": ["ReferenceVO"]})
