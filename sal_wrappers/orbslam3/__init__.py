"""``orbslam3``: ORB-SLAM3 through the ``pyorbslam3`` wheel, run in a child process.

``system`` is the :class:`~sal_wrappers.base.SlamSystem`; ``child`` the tracking loop in the
child process; ``states`` its tracking states mapped to ``TrackState``; ``settings`` the
settings file it reads; ``vocabulary`` finding or building the ORB vocabulary it loads,
``vocabulary_tree`` the DBoW2 tree and its text format, ``vocabulary_training`` training it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sal_adapters.common.lazy import lazy_exports

if TYPE_CHECKING:
    from sal_wrappers.orbslam3.system import OrbSlam3

__all__ = ["OrbSlam3"]

__getattr__, __dir__ = lazy_exports(__name__, {"sal_wrappers.orbslam3.system": ["OrbSlam3"]})
