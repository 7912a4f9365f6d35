"""A frame whose size is not its camera's is one ``DatasetError`` naming the file, and a frame
over ``MAX_FRAME_PIXELS`` is refused from its header, undecoded (issue 23, item 7)."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
from kitti_excerpt import kitti_copy

from sal_adapters import DatasetError, open_dataset
from sal_adapters.images import read_image

KITTI_SIZE = "1226x370 px"


def png_header_only(path: Path, width: int, height: int) -> Path:
    """A PNG whose ``IHDR`` says ``width`` x ``height`` (grey, 8 bit) followed by a few bytes
    of image data: a few hundred bytes on disk, whatever size it states."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    idat = zlib.compress(bytes(1 + width))[:64]  # the first row's start: the rest is missing
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b""))
    return path


def test_a_frame_of_another_size_is_one_error_naming_it(shared_data: Path, tmp_path: Path) -> None:
    sequence_dir = kitti_copy(shared_data, tmp_path)
    frame = sequence_dir / "image_0" / "000001.png"
    cv2.imwrite(str(frame), np.full((200, 600), 128, np.uint8))
    sequence = open_dataset("kitti", sequence_dir)
    assert sequence[0].image.shape == (370, 1226, 3)
    with pytest.raises(DatasetError) as info:
        [f.image for f in sequence]
    assert str(info.value) == (
        f"{frame}: image is 600x200 px but the sequence's camera is {KITTI_SIZE} (every frame of a camera must have its size)"
    )


@pytest.mark.parametrize("position", [0, 2], ids=["first frame", "later frame"])
def test_a_20000x20000_frame_is_refused_from_its_header(shared_data: Path, tmp_path: Path, position: int) -> None:
    sequence_dir = kitti_copy(shared_data, tmp_path)
    frame = png_header_only(sequence_dir / "image_0" / f"{position:06d}.png", 20000, 20000)
    with pytest.raises(DatasetError) as info:
        [f.image for f in open_dataset("kitti", sequence_dir)]
    assert str(info.value) == f"{frame}: image refused: 20000x20000 px is over the limit of 50000000 pixels a frame"


@pytest.mark.parametrize("suffix", [".png", ".jpg", ".bmp", ".tiff", ".pgm", ".ppm"])
def test_the_header_size_is_the_decoded_size(tmp_path: Path, suffix: str) -> None:
    from sal_adapters.images import header_size

    path = tmp_path / f"frame{suffix}"
    channels = (5, 7) if suffix == ".pgm" else (5, 7, 3)
    cv2.imwrite(str(path), np.random.default_rng(0).integers(0, 256, channels, np.uint8))
    assert header_size(path.read_bytes(), path) == (7, 5)
    assert read_image(path, (7, 5)).shape == (5, 7, 3)


def test_an_image_that_is_no_image_is_one_error(tmp_path: Path) -> None:
    for data in (b"", b"\xff\xd8\xff\xe0\x00", b"not an image at all"):
        path = tmp_path / "frame.png"
        path.write_bytes(data)
        with pytest.raises(DatasetError, match=r"frame\.png: cannot decode image"):
            read_image(path)
