"""The helper the synthetic world tests share (test_synthetic_world.py, test_synthetic_cache.py):
the RGB-D sequence they open."""

from __future__ import annotations

from sal_adapters import (
    Sequence,
    open_dataset,
)

__all__ = ["rgbd"]


def rgbd(scene: str, frames: int, **options) -> Sequence:
    return open_dataset("synthetic", scene=scene, frames=frames, sensor="rgbd", **options)
