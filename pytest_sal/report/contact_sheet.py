"""Contact sheets: a few frames of a sequence side by side with their depth and right images."""

from __future__ import annotations

import cv2
import numpy as np

from sal_adapters import Sequence

__all__ = ["colorize_depth", "contact_sheet"]


def colorize_depth(depth_m: np.ndarray, max_m: float | None = None) -> np.ndarray:
    """Depth (m, 0 = invalid) as RGB with OpenCV's TURBO map on inverse depth; invalid is black."""
    valid = depth_m > 0
    far = max_m if max_m is not None else (float(np.percentile(depth_m[valid], 98)) if valid.any() else 1.0)
    near = float(depth_m[valid].min()) if valid.any() else 0.0
    inv = np.zeros_like(depth_m, dtype=np.float32)
    inv[valid] = 1.0 / np.maximum(depth_m[valid], 1e-3)
    lo, hi = 1.0 / max(far, 1e-3), 1.0 / max(near, 1e-3)
    scaled = np.clip((inv - lo) / max(hi - lo, 1e-9), 0, 1)
    rgb = cv2.cvtColor(cv2.applyColorMap((scaled * 255).astype(np.uint8), cv2.COLORMAP_TURBO), cv2.COLOR_BGR2RGB)
    rgb[~valid] = 0
    return rgb


def contact_sheet(sequence: Sequence, count: int = 4, tile_width: int = 480) -> np.ndarray:
    """RGB image: ``count`` evenly spaced frames as rows of (image, right image, depth) tiles,
    each labelled with frame index and time (s)."""
    positions = np.unique(np.linspace(0, len(sequence) - 1, num=min(count, len(sequence))).round().astype(int))
    rows = []
    for position in positions:
        frame = sequence[int(position)]
        tiles = [("left", frame.image)]
        if frame.right is not None:
            tiles.append(("right", frame.right))
        if frame.depth is not None:
            tiles.append(("depth", colorize_depth(frame.depth)))
        label = f"#{frame.index}  t={frame.timestamp:.3f} s"
        rows.append(np.hstack([_tile(image, f"{label}  {what}", tile_width) for what, image in tiles]))
    width = max(r.shape[1] for r in rows)
    return np.vstack([np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0))) for r in rows])


def _tile(image: np.ndarray, label: str, width: int) -> np.ndarray:
    height = max(1, round(image.shape[0] * width / image.shape[1]))
    tile = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)
    cv2.rectangle(tile, (0, 0), (width, 22), (0, 0, 0), thickness=-1)
    cv2.putText(tile, label, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return tile
