"""Depth providers: metric depth of the clean frames for depth-aware modules.

A provider turns a sequence into ``depth(index, stream) -> float32 HxW metres`` (0 = invalid,
e.g. sky). Computed depth is stored once per sequence on disk, keyed by provider name, its
settings and the sequence fingerprint, so every module, severity and process reuses it.
"""

from __future__ import annotations

import hashlib
import json
import warnings
from abc import ABC, abstractmethod
from collections import OrderedDict
from functools import partial
from pathlib import Path
from threading import Lock
from typing import Any, ClassVar

import numpy as np

from sal_adapters.common.cache_dir import cache_writes_allowed, user_cache_dir
from sal_adapters.common.errors import CacheWarning
from sal_adapters.images import read_depth, read_stored, write_depth
from sal_adapters.sequence import Sequence
from sal_modules.context import DepthLookup

__all__ = ["CachedDepth", "DepthProvider", "fill_unknown"]


class DepthProvider(ABC):
    """One way to get depth: native maps, stereo matching, a monocular network.

    Subclasses set ``name``, implement ``unavailable`` and ``compute``, and return their
    settings (anything that changes the result) from ``settings``.
    """

    name: ClassVar[str] = ""

    def caches(self, stream: str) -> bool:
        """Whether computed depth of ``stream`` is stored in the depth cache (worth it when
        computing costs more than reading a ``.npy`` file back)."""
        return True

    def settings(self) -> dict[str, Any]:
        """Everything that changes the computed depth (JSON types); part of the cache key."""
        return {}

    @abstractmethod
    def unavailable(self, sequence: Sequence) -> str | None:
        """Why this provider cannot serve ``sequence``, or ``None`` when it can."""
        raise NotImplementedError(f"{type(self).__name__}.unavailable")

    @abstractmethod
    def compute(self, sequence: Sequence, position: int, stream: str) -> np.ndarray:
        """Depth (float32 m, 0 = invalid) of frame ``position`` of ``sequence`` in ``stream``."""
        raise NotImplementedError(f"{type(self).__name__}.compute")

    def key(self, sequence: Sequence) -> str:
        """Cache key: SHA-256 of provider name, settings and the sequence fingerprint."""
        text = json.dumps({"provider": self.name, "settings": self.settings(), "sequence": sequence.fingerprint}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()

    def lookup(self, sequence: Sequence, cache_dir: Path | None = None) -> DepthLookup:
        """``depth(index, stream)`` for the frames of ``sequence``, stored where ``caches``."""
        return CachedDepth(self, sequence, cache_dir)

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.settings().items())
        return f"{type(self).__name__}({args})"


class CachedDepth:
    """Depth by dataset index and stream: memory (a few frames) -> disk -> ``compute``.

    Disk entries live in ``<cache>/depth/<key>/<index>_<stream>.npy`` and are written
    atomically, so concurrent processes computing the same frame never see a partial file;
    none is written when the lookup was made inside ``no_cache_writes()``. A stored file that
    cannot be read or is not an image-sized float map is computed again and replaced, with one
    ``CacheWarning`` naming it.
    """

    def __init__(self, provider: DepthProvider, sequence: Sequence, cache_dir: Path | None = None, keep: int = 4):
        self.provider = provider
        self.sequence = sequence
        self.folder = (Path(cache_dir) / "depth" if cache_dir else user_cache_dir("depth")) / provider.key(sequence)
        self._positions = {record.index: position for position, record in enumerate(sequence.records)}
        self._recent: OrderedDict[tuple[int, str], np.ndarray] = OrderedDict()
        self._keep = keep
        self._lock = Lock()
        self._store = cache_writes_allowed()

    def __call__(self, index: int, stream: str) -> np.ndarray:
        key = (index, stream)
        with self._lock:
            if key in self._recent:
                self._recent.move_to_end(key)
                return self._recent[key]
        depth = self._load(index, stream)
        with self._lock:
            self._recent[key] = depth
            while len(self._recent) > self._keep:
                self._recent.popitem(last=False)
        return depth

    def _load(self, index: int, stream: str) -> np.ndarray:
        position = self._positions[index]
        if not self.provider.caches(stream):
            return self.provider.compute(self.sequence, position, stream)
        path = self.folder / f"{index}_{stream}.npy"
        stored = self._stored(path)
        if stored is not None:
            return stored
        depth = np.ascontiguousarray(self.provider.compute(self.sequence, position, stream), dtype=np.float32)
        if self._store:
            write_depth(path, depth, None)
        return depth

    def _stored(self, path: Path) -> np.ndarray | None:
        """The stored depth at ``path``; ``None`` when there is none, or when it is damaged
        (then one warning names it and the caller computes it again)."""
        camera = self.sequence.camera
        depth, problem = read_stored(path, partial(read_depth, depth_scale=None))
        if depth is not None and depth.shape != (camera.height, camera.width):
            problem = f"depth array of shape {depth.shape}, the frames are {camera.height}x{camera.width} px"
            depth = None
        if problem is not None:
            done = "computed again and replaced" if self._store else "computed again (nothing is stored)"
            warnings.warn(CacheWarning(f"{path}: bad cached depth, {done}: {problem}"), stacklevel=4)
        return depth


def fill_unknown(depth: np.ndarray) -> np.ndarray:
    """Fill unknown pixels (NaN) along each row with the farther of the nearest known pixels
    to their left and right (an occlusion hole shows the background); ``inf`` marks sky,
    which is farthest of all. Rows with nothing known stay NaN.
    """
    depth = np.asarray(depth, dtype=np.float32)
    h, w = depth.shape
    known = ~np.isnan(depth)
    cols = np.broadcast_to(np.arange(w), (h, w))
    left_idx = np.maximum.accumulate(np.where(known, cols, -1), axis=1)
    right_idx = np.minimum.accumulate(np.where(known, cols, w)[:, ::-1], axis=1)[:, ::-1]
    rows = np.broadcast_to(np.arange(h)[:, None], (h, w))
    left_val = np.where(left_idx >= 0, depth[rows, np.clip(left_idx, 0, w - 1)], np.nan)
    right_val = np.where(right_idx < w, depth[rows, np.clip(right_idx, 0, w - 1)], np.nan)
    return np.where(known, depth, np.fmax(left_val, right_val))
