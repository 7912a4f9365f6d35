"""Per-thread work arrays that modules reuse from frame to frame.

Allocating ~20 MB of fresh temporaries per frame costs more in page faults than the
arithmetic on them, so the per-frame hot paths (fog, rain, snow, defocus, night, sensor_noise)
write into these.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np

__all__ = ["scratch"]

_SCRATCH = threading.local()


def scratch(name: str, shape: tuple[int, ...], dtype: Any = np.float32) -> np.ndarray:
    """The work array ``name`` of ``shape`` and ``dtype`` kept for this thread (contents undefined)."""
    arrays = _SCRATCH.__dict__.setdefault("arrays", {})
    key = (name, tuple(shape), np.dtype(dtype).str)
    if key not in arrays:
        arrays[key] = np.empty(shape, dtype)
    return arrays[key]
