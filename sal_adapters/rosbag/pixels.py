"""Pixels of ``sensor_msgs/Image`` and ``CompressedImage`` messages, both ways.

Raw images: every 8-bit encoding ``rosbags-image`` knows (``mono8``, ``rgb8``, ``bgr8``,
``rgba8``, ``bgra8``, Bayer, YUV 4:2:2) become HxWx3 uint8 RGB, honouring ``step`` (padded
rows) and ``is_bigendian``; depth maps are ``16UC1`` / ``mono16`` in millimetres or ``32FC1`` in
metres (REP 118) and become float32 metres (0 = no depth). Compressed images are whatever
OpenCV decodes (JPEG, PNG). ``BagImage`` is the lazy frame source a sequence holds.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from sal_adapters.common.errors import DatasetError, DatasetWarning
from sal_adapters.rosbag.bag import MessageRef, open_bag

__all__ = ["DEPTH_ENCODINGS", "BagImage", "check_encoding", "decode_depth", "decode_image", "encode_like"]

#: Depth encodings and their units per metre (REP 118).
DEPTH_ENCODINGS = {"16UC1": 1000.0, "mono16": 1000.0, "32FC1": 1.0}
_REWRITTEN_AS_IS = ("mono8", "rgb8", "bgr8", "rgba8", "bgra8", "8UC1", "8UC3")


def check_encoding(message: Any, topic: str, bag: Path, depth: bool = False) -> bool:
    """True when the images of ``topic`` are grey; a ``DatasetError`` naming the bag, the topic
    and the encoding when pytest-sal cannot decode it (listing the ones it can)."""
    if _is_compressed(message):
        fmt = str(message.format)
        if depth or "compresseddepth" in fmt.lower():
            raise DatasetError(f"topic {topic}: compressed depth ({fmt!r}) is not supported; record depth as raw 16UC1 or 32FC1", bag)
        return _decoded_compressed(message, topic, bag).ndim == 2
    encoding = str(message.encoding)
    if depth:
        if encoding not in DEPTH_ENCODINGS:
            raise DatasetError(f"topic {topic}: depth encoding {encoding!r} is not supported; supported: {', '.join(DEPTH_ENCODINGS)}", bag)
        return False
    from rosbags.image import ImageFormatError
    from rosbags.image.image import to_cvtype

    try:
        bits, _, _, channels = to_cvtype(encoding)
    except ImageFormatError:
        bits, channels = 0, 0
    if bits != 8 or channels not in (1, 2, 3, 4):
        raise DatasetError(
            f"topic {topic}: image encoding {encoding!r} is not supported; supported: 8-bit encodings such as "
            "mono8, rgb8, bgr8, rgba8, bgra8, bayer_*8, yuv422 (and CompressedImage JPEG/PNG)",
            bag,
        )
    return encoding in ("mono8", "8UC1")


def decode_image(message: Any, topic: str = "", bag: Path | None = None) -> np.ndarray:
    """HxWx3 uint8 RGB of an image message (grey images repeat their one channel)."""
    if _is_compressed(message):
        pixels = _decoded_compressed(message, topic, bag)
        if pixels.ndim == 2:
            return np.repeat(pixels[..., None], 3, axis=2)
        return np.ascontiguousarray(pixels[..., 2::-1])  # OpenCV decodes to BGR(A)
    pixels = _raw_pixels(message, topic, bag)
    encoding = str(message.encoding)
    if encoding in ("mono8", "8UC1"):
        return np.repeat(pixels[..., None], 3, axis=2)
    from rosbags.image.image import convert_color

    return np.ascontiguousarray(convert_color(pixels, "bgr8" if encoding == "8UC3" else encoding, "rgb8"))


def decode_depth(message: Any, topic: str = "", bag: Path | None = None) -> np.ndarray:
    """HxW float32 depth (m) of a ``16UC1``/``mono16`` (mm) or ``32FC1`` (m) message; NaN and
    negative values become 0 (no depth)."""
    per_metre = DEPTH_ENCODINGS[str(message.encoding)]
    depth = _raw_pixels(message, topic, bag).astype(np.float32) / np.float32(per_metre)
    depth[~np.isfinite(depth) | (depth < 0)] = 0.0
    return depth


def encode_like(original: Any, rgb: np.ndarray, grey: bool, topic: str) -> Any:
    """A copy of the image message ``original`` (same header, type, encoding or compression
    format) holding ``rgb`` (HxWx3 uint8). Encodings that cannot be rebuilt from RGB (Bayer,
    YUV) are written as ``mono8``/``rgb8`` with a ``DatasetWarning``."""
    if _is_compressed(original):
        ext = ".png" if "png" in str(original.format).lower() else ".jpg"
        pixels = rgb[..., 0] if grey else rgb[..., ::-1]
        ok, data = cv2.imencode(ext, np.ascontiguousarray(pixels), [cv2.IMWRITE_JPEG_QUALITY, 95] if ext == ".jpg" else [])
        if not ok:
            raise DatasetError(f"topic {topic}: OpenCV could not encode a frame as {ext}")
        return _with(original, data=np.asarray(data, dtype=np.uint8).reshape(-1))
    encoding = str(original.encoding)
    if encoding not in _REWRITTEN_AS_IS:
        encoding = "mono8" if grey else "rgb8"
        warnings.warn(f"topic {topic}: {original.encoding} frames are written back as {encoding}", DatasetWarning, stacklevel=3)
    match encoding:
        case "mono8" | "8UC1":
            pixels = rgb[..., 0]
        case "bgr8" | "8UC3":
            pixels = rgb[..., ::-1]
        case "rgba8" | "bgra8":
            colour = rgb if encoding == "rgba8" else rgb[..., ::-1]
            pixels = np.concatenate([colour, np.full(rgb.shape[:2] + (1,), 255, np.uint8)], axis=2)
        case _:
            pixels = rgb
    data = np.ascontiguousarray(pixels, dtype=np.uint8)
    return _with(
        original,
        encoding=encoding,
        height=data.shape[0],
        width=data.shape[1],
        step=data.shape[1] * (data.shape[2] if data.ndim == 3 else 1),
        is_bigendian=0,
        data=data.reshape(-1),
    )


@dataclass(frozen=True)
class BagImage:
    """A frame source: the image (or depth map) at ``ref`` in the bag at ``path``, decoded
    when called (RGB uint8, or depth in float32 m)."""

    path: Path
    ref: MessageRef
    depth: bool = False

    def __call__(self) -> np.ndarray:
        bag = open_bag(self.path)
        message = bag.read(self.ref)
        if self.depth:
            return decode_depth(message, self.ref.topic, self.path)
        return decode_image(message, self.ref.topic, self.path)


def _is_compressed(message: Any) -> bool:
    return hasattr(message, "format")


def _decoded_compressed(message: Any, topic: str, bag: Path | None) -> np.ndarray:
    pixels = cv2.imdecode(_bytes(message), cv2.IMREAD_UNCHANGED)
    if pixels is None or pixels.dtype != np.uint8 or pixels.ndim not in (2, 3):
        raise DatasetError(f"topic {topic}: a CompressedImage ({message.format!r}) that OpenCV cannot decode as an 8-bit image", bag)
    return pixels[..., :3] if pixels.ndim == 3 else pixels


def _raw_pixels(message: Any, topic: str, bag: Path | None) -> np.ndarray:
    """The pixel array of a raw ``Image``, rows cut to ``width`` (``step`` may pad them)."""
    from rosbags.image.image import to_cvtype

    _, _, typestr, channels = to_cvtype(str(message.encoding))
    dtype = np.dtype(typestr).newbyteorder(">" if message.is_bigendian else "<")
    height, width, step = int(message.height), int(message.width), int(message.step)
    row = width * channels * dtype.itemsize
    data = _bytes(message)
    if step < row or data.size < step * height:
        raise DatasetError(
            f"topic {topic}: an image of {width}x{height} px {message.encoding} holds {data.size} bytes with step {step}; expected {row * height}",
            bag,
        )
    rows = data[: step * height].reshape(height, step)[:, :row]
    pixels = np.ascontiguousarray(rows).view(dtype).reshape((height, width, channels) if channels > 1 else (height, width))
    return pixels.astype(dtype.newbyteorder("="), copy=False)


def _bytes(message: Any) -> np.ndarray:
    """The ``data`` of a message as a flat uint8 array (no copy where it is one already)."""
    data = message.data
    return data.view(np.uint8).reshape(-1) if isinstance(data, np.ndarray) else np.frombuffer(bytes(data), np.uint8)


def _with(message: Any, **fields: Any) -> Any:
    """``message`` (a rosbags dataclass) with ``fields`` replaced."""
    return replace(message, **fields)
