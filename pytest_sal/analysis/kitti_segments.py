"""The KITTI odometry devkit's segment lengths and their parsing, without numpy (the plugin
reads ini ``sal_kitti_segments`` at session start; ``kitti_metrics`` does the computing)."""

from __future__ import annotations

import math
from collections.abc import Iterable
from numbers import Real

from sal_adapters.common.errors import SalError

__all__ = ["KITTI_SEGMENTS_M", "KITTI_STEP", "parse_segments", "segment_lengths"]

#: the devkit's segment lengths (m)
KITTI_SEGMENTS_M: tuple[float, ...] = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)
#: frames between segment starts (the devkit's ``step_size``: one second at 10 Hz)
KITTI_STEP = 10


def segment_lengths(lengths: Iterable[float]) -> tuple[float, ...]:
    """``lengths`` (m) as sorted distinct floats; ``SalError`` unless each is a finite number > 0."""
    items: list[object] = [lengths] if isinstance(lengths, (str, bytes)) else list(lengths)
    numbers = [float(v) for v in items if isinstance(v, Real) and not isinstance(v, bool)]
    if not items or len(numbers) != len(items) or not all(math.isfinite(v) and v > 0 for v in numbers):
        raise SalError(f"KITTI segment lengths must be one or more numbers > 0 (m), got {items!r}")
    return tuple(sorted(set(numbers)))


def parse_segments(text: str) -> tuple[float, ...]:
    """``"10,20,30,40"`` (m, comma-separated) as ``segment_lengths``; ``SalError`` naming the text."""
    try:
        return segment_lengths(float(part) for part in text.split(",") if part.strip())
    except (ValueError, SalError):
        raise SalError(f"KITTI segment lengths {text!r}: expected numbers > 0 in metres separated by commas, e.g. 10,20,30,40") from None
