"""Decoding and encoding of frame images and depth maps, with errors that name the file."""

from __future__ import annotations

import io
import struct
import warnings
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from sal_adapters.camera import MAX_FRAME_PIXELS, frame_size_problem
from sal_adapters.common.atomic import staged_file
from sal_adapters.common.errors import DatasetError

__all__ = [
    "IMAGE_SUFFIXES",
    "Size",
    "header_size",
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


#: An image's ``(width, height)`` in px.
Size = tuple[int, int]


def read_image(path: Path, size: Size | None = None) -> np.ndarray:
    """Decode an image file to HxWx3 uint8 RGB (grey images are expanded to three channels).

    Its header is read first: an image over ``MAX_FRAME_PIXELS`` or, when ``size`` (px) is
    given, of another size is refused without being decoded (``DatasetError`` naming the file).
    """
    raw = _imread(path, cv2.IMREAD_UNCHANGED, size)
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
    """``(width, height, single_channel)`` of an image file (decodes it once, within
    ``MAX_FRAME_PIXELS``)."""
    raw = _imread(path, cv2.IMREAD_UNCHANGED)
    return int(raw.shape[1]), int(raw.shape[0]), raw.ndim == 2 or raw.shape[2] == 1


def read_depth(path: Path, depth_scale: float | None, size: Size | None = None) -> np.ndarray:
    """Decode a depth map to float32 metres (0 = invalid).

    ``.npy`` files hold metres already (floats, 2-D); 16-bit images hold ``metres * depth_scale``
    (TUM: 5000). With ``size`` (px), a map of another size is refused (an image before decoding).
    """
    path = Path(path)
    if path.suffix == ".npy":
        try:
            depth = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError) as exc:  # EOFError: an empty file
            raise DatasetError(f"cannot read depth array ({exc})", path) from None
        if depth.ndim != 2:
            raise DatasetError(f"depth array must be 2-D, got shape {depth.shape}", path)
        _check_size((depth.shape[1], depth.shape[0]), size, path)
        if not np.issubdtype(depth.dtype, np.floating):
            raise DatasetError(f"depth array must hold floats (m), got {depth.dtype}", path)
        return depth.astype(np.float32, copy=False)
    raw = _imread(path, cv2.IMREAD_UNCHANGED, size)
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


def _imread(path: Path, flags: int, size: Size | None = None) -> np.ndarray:
    """Decode ``path`` after checking the size its header states (``_check_size``)."""
    path = Path(path)
    try:
        if not path.is_file():
            raise DatasetError("image file not found", path)
        data = np.fromfile(path, dtype=np.uint8)
    except OSError as exc:  # a name too long for the file system, a file this user may not read
        raise DatasetError(f"cannot read image ({exc.strerror or exc})", path) from None
    _check_size(header_size(data.data, path), size, path)
    image = cv2.imdecode(data, flags) if data.size else None
    if image is None:
        raise DatasetError("cannot decode image (corrupt or not an image)", path)
    return image


def _check_size(found: Size, expected: Size | None, path: Path) -> None:
    """``DatasetError`` naming ``path`` unless ``found`` (px) is a frame's size
    (``frame_size_problem``) and, when given, the ``expected`` one."""
    problem = frame_size_problem(*found)
    if problem:
        raise DatasetError(f"image refused: {problem}", path)
    if expected is not None and tuple(found) != tuple(expected):
        raise DatasetError(
            f"image is {found[0]}x{found[1]} px but the sequence's camera is {expected[0]}x{expected[1]} px "
            "(every frame of a camera must have its size)",
            path,
        )


#: JPEG start-of-frame markers, whose segment holds the image size.
_JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


def header_size(data: bytes | memoryview, path: Path) -> Size:
    """``(width, height)`` (px) an image file's header states, read without decoding: PNG's
    ``IHDR`` and JPEG's start-of-frame here, other formats by PIL (which reads only the
    header). ``DatasetError`` naming ``path`` when no header is found."""
    if data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR" and len(data) >= 24:
        width, height = struct.unpack(">II", data[16:24])
        return int(width), int(height)
    if data[:2] == b"\xff\xd8":
        position = 2
        while position + 9 <= len(data) and data[position] == 0xFF:
            if data[position + 1] == 0xFF:  # a fill byte
                position += 1
                continue
            marker, length = data[position + 1], int.from_bytes(data[position + 2 : position + 4], "big")
            if marker in _JPEG_SOF:
                height, width = struct.unpack(">HH", data[position + 5 : position + 9])
                return int(width), int(height)
            position += 2 + length
        raise DatasetError("cannot decode image (a JPEG without a readable frame header)", path)
    from PIL import Image  # only here: BMP, TIFF, PNM are rare in datasets

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(io.BytesIO(data)) as image:
                return image.size
    except Image.DecompressionBombError:
        raise DatasetError(f"image refused: its header states more than {MAX_FRAME_PIXELS} pixels", path) from None
    except (OSError, ValueError, SyntaxError, struct.error):  # what PIL raises for a file it cannot read
        raise DatasetError("cannot decode image (corrupt or not an image)", path) from None


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
