"""Decoding and encoding of frame images and depth maps, with errors that name the file."""

from __future__ import annotations

import io
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from sal_adapters.atomic import staged_file
from sal_adapters.errors import DatasetError

__all__ = [
    "IMAGE_SUFFIXES",
    "is_grey",
    "probe_image",
    "read_depth",
    "read_image",
    "read_stored",
    "scaled_to_width",
    "write_depth",
    "write_image",
]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".pgm")


def read_image(path: Path) -> np.ndarray:
    """Decode an image file to HxWx3 uint8 RGB (grey images are expanded to three channels)."""
    raw = _imread(path, cv2.IMREAD_UNCHANGED)
    if raw.dtype == np.uint16:
        raw = (raw >> 8).astype(np.uint8)
    elif raw.dtype != np.uint8:
        raise DatasetError(f"unsupported image pixel type {raw.dtype} (expected 8- or 16-bit)", path)
    if raw.ndim == 2:
        return cv2.cvtColor(raw, cv2.COLOR_GRAY2RGB)
    if raw.shape[2] == 4:
        return cv2.cvtColor(raw, cv2.COLOR_BGRA2RGB)
    return cv2.cvtColor(raw, cv2.COLOR_BGR2RGB)


def probe_image(path: Path) -> tuple[int, int, bool]:
    """``(width, height, single_channel)`` of an image file (decodes it once)."""
    raw = _imread(path, cv2.IMREAD_UNCHANGED)
    return int(raw.shape[1]), int(raw.shape[0]), raw.ndim == 2 or raw.shape[2] == 1


def read_depth(path: Path, depth_scale: float | None) -> np.ndarray:
    """Decode a depth map to float32 metres (0 = invalid).

    ``.npy`` files hold metres already (floats, 2-D); 16-bit images hold ``metres * depth_scale``
    (TUM: 5000).
    """
    path = Path(path)
    if path.suffix == ".npy":
        try:
            depth = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError) as exc:  # EOFError: an empty file
            raise DatasetError(f"cannot read depth array ({exc})", path) from None
        if depth.ndim != 2:
            raise DatasetError(f"depth array must be 2-D, got shape {depth.shape}", path)
        if not np.issubdtype(depth.dtype, np.floating):
            raise DatasetError(f"depth array must hold floats (m), got {depth.dtype}", path)
        return depth.astype(np.float32, copy=False)
    raw = _imread(path, cv2.IMREAD_UNCHANGED)
    if raw.ndim != 2:
        raise DatasetError(f"depth image must have one channel, got {raw.shape[2]}", path)
    if depth_scale is None or depth_scale <= 0:
        raise DatasetError("depth image needs a positive depth scale (units per metre)", path)
    return raw.astype(np.float32) / np.float32(depth_scale)


def read_stored(path: Path, read: Callable[[Path], np.ndarray]) -> tuple[np.ndarray | None, str | None]:
    """A cache's stored array: ``(array, None)``; ``(None, None)`` when there is no file;
    ``(None, problem)`` when ``read`` cannot decode it or the file cannot be opened (the
    caches warn with ``problem`` and compute the array again)."""
    if not path.is_file():
        return None, None
    try:
        return read(path), None
    except DatasetError as exc:
        return None, exc.problem
    except OSError as exc:  # a file this user may not read
        return None, exc.strerror or str(exc)


def write_image(path: Path, rgb: np.ndarray, grey: bool = False) -> None:
    """Encode HxWx3 RGB (or HxW grey) uint8; ``grey=True`` stores one channel (luma)."""
    if rgb.ndim == 3 and grey:
        data = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    elif rgb.ndim == 3:
        data = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    else:
        data = rgb
    _imwrite(path, data)


def write_depth(path: Path, depth_m: np.ndarray, depth_scale: float | None) -> None:
    """Store float32 metres: ``.npy`` exactly, a 16-bit image as ``round(m * depth_scale)``."""
    path = Path(path)
    if path.suffix == ".npy":
        buffer = io.BytesIO()  # np.save into a real file reports a full disk without errno
        np.save(buffer, np.asarray(depth_m, dtype=np.float32), allow_pickle=False)
        _store(path, buffer.getbuffer())
        return
    if depth_scale is None:
        raise ValueError(f"{path}: a 16-bit depth image needs a depth scale")
    raw = np.clip(np.round(depth_m * depth_scale), 0, 65535).astype(np.uint16)
    _imwrite(path, raw)


def is_grey(rgb: np.ndarray) -> bool:
    """True when all three channels are equal (a grey image stored as RGB)."""
    return rgb.ndim == 2 or (np.array_equal(rgb[..., 0], rgb[..., 1]) and np.array_equal(rgb[..., 1], rgb[..., 2]))


def _imread(path: Path, flags: int) -> np.ndarray:
    path = Path(path)
    if not path.is_file():
        raise DatasetError("image file not found", path)
    data = np.fromfile(path, dtype=np.uint8)
    image = cv2.imdecode(data, flags) if data.size else None
    if image is None:
        raise DatasetError("cannot decode image (corrupt or not an image)", path)
    return image


def _imwrite(path: Path, data: np.ndarray) -> None:
    """Encode to memory, then write through a temporary file and ``os.replace``."""
    path = Path(path)
    ok, encoded = cv2.imencode(path.suffix or ".png", data)
    if not ok:
        raise ValueError(f"{path}: OpenCV cannot encode this image type")
    _store(path, encoded.data)


def _store(path: Path, data: memoryview) -> None:
    """Write ``data`` to ``path`` through a uniquely named temporary file beside it (concurrent
    writers of one file never share it); ``WriteError`` naming ``path`` on failure."""
    with staged_file(path) as temp, open(temp, "wb") as handle:
        handle.write(data)


def scaled_to_width(rgb: np.ndarray, width: int) -> np.ndarray:
    """``rgb`` resized (area averaging) to ``width`` px, keeping its aspect ratio (thumbnails)."""
    height = max(1, round(rgb.shape[0] * width / rgb.shape[1]))
    return cv2.resize(rgb, (width, height), interpolation=cv2.INTER_AREA)
