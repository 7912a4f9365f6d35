"""The synthetic world's render cache heals (issue 12 point 5): a stored frame that cannot be
read, or is not the array a render gives, is discarded with one ``CacheWarning`` naming the file,
rendered again and replaced, identical to a fresh render; a dry run leaves the file alone."""

from __future__ import annotations

import io
import warnings
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from sal_adapters import Sequence, open_dataset
from sal_adapters.common.cache_dir import no_cache_writes
from sal_adapters.common.errors import CacheWarning

FRAME = 1


def npy(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=False)
    return buffer.getvalue()


def png(image: np.ndarray) -> bytes:
    return cv2.imencode(".png", image)[1].tobytes()


#: damage -> the file's new bytes, from the stored ones
DAMAGE: dict[str, Callable[[bytes], bytes]] = {
    "truncated": lambda raw: raw[: len(raw) // 3],
    "garbage": lambda raw: bytes(range(256)) * 8,
    "empty": lambda raw: b"",
}

#: (scene, sensor, stored file, the frame's array it holds)
STREAMS = {
    "left image": ("indoor", "rgbd", "image_left/000001.png", lambda frame: frame.image),
    "depth": ("indoor", "rgbd", "depth/000001.npy", lambda frame: frame.depth),
    "right image": ("urban", "stereo", "image_right/000001.png", lambda frame: frame.right),
}

#: what the reader of a file type says about any of the damages above (numpy's reason follows)
PROBLEMS = {"png": "cannot decode image (corrupt or not an image)", "npy": "cannot read depth array ("}


def rendered(tmp_path: Path, name: str, scene: str, sensor: str) -> Sequence:
    return open_dataset("synthetic", scene=scene, frames=3, sensor=sensor, cache_dir=tmp_path / name)


def cache_warnings(fn: Callable[[], np.ndarray]) -> tuple[np.ndarray, list[str]]:
    """``fn()`` and the messages of the CacheWarnings it gave."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        value = fn()
    return value, [str(w.message) for w in caught if issubclass(w.category, CacheWarning)]


def healed(tmp_path: Path, stream: str, damage: Callable[[bytes], bytes], problem: str) -> None:
    """Store frame 1, replace its ``stream`` file's bytes by ``damage(bytes)``, read it back: one
    warning naming the file and ``problem``, the fresh render, and the file a fresh cache holds."""
    scene, sensor, name, array = STREAMS[stream]
    fresh = rendered(tmp_path, "fresh", scene, sensor)
    expected = array(fresh[FRAME])
    cached = rendered(tmp_path, "cache", scene, sensor)
    array(cached[FRAME])
    path = tmp_path / "cache" / name
    path.write_bytes(damage(path.read_bytes()))
    value, messages = cache_warnings(lambda: array(rendered(tmp_path, "cache", scene, sensor)[FRAME]))
    assert len(messages) == 1 and messages[0].startswith(f"{path}: bad cached frame, replaced by a fresh render: {problem}")
    assert "\n" not in messages[0]
    np.testing.assert_array_equal(value, expected)
    assert value.dtype == expected.dtype
    assert path.read_bytes() == (tmp_path / "fresh" / name).read_bytes()
    again, messages = cache_warnings(lambda: array(rendered(tmp_path, "cache", scene, sensor)[FRAME]))
    assert messages == [] and np.array_equal(again, expected)


@pytest.mark.parametrize("damage", DAMAGE)
@pytest.mark.parametrize("stream", STREAMS)
def test_a_damaged_stored_frame_is_rendered_again(tmp_path: Path, stream: str, damage: str) -> None:
    healed(tmp_path, stream, DAMAGE[damage], PROBLEMS[STREAMS[stream][2].rsplit(".", 1)[1]])


@pytest.mark.parametrize(
    ("stream", "content", "problem"),
    [
        ("depth", npy(np.zeros((10, 10), np.float32)), "holds an array of shape (10, 10), a render gives (480, 640)"),
        ("depth", npy(np.zeros((480, 640, 2), np.float32)), "depth array must be 2-D, got shape (480, 640, 2)"),
        ("depth", npy(np.ones((480, 640), np.int32)), "depth array must hold floats (m), got int32"),
        ("left image", png(np.zeros((24, 32, 3), np.uint8)), "holds an array of shape (24, 32, 3), a render gives (480, 640, 3)"),
    ],
    ids=["npy of another shape", "npy of three dimensions", "npy of integers", "png of another size"],
)
def test_a_stored_frame_of_the_wrong_shape_or_dtype_is_rendered_again(tmp_path: Path, stream: str, content: bytes, problem: str) -> None:
    healed(tmp_path, stream, lambda raw: content, problem)


def test_a_dry_run_renders_a_damaged_frame_in_memory_and_leaves_the_file(tmp_path: Path) -> None:
    fresh = rendered(tmp_path, "fresh", "indoor", "rgbd")[FRAME].image
    rendered(tmp_path, "cache", "indoor", "rgbd")[FRAME].image
    path = tmp_path / "cache" / "image_left" / "000001.png"
    path.write_bytes(b"")
    with no_cache_writes():
        sequence = rendered(tmp_path, "cache", "indoor", "rgbd")
        image, messages = cache_warnings(lambda: sequence[FRAME].image)
        again, repeated = cache_warnings(lambda: sequence[FRAME].image)
    assert messages == [
        f"{path}: bad cached frame, ignored (nothing is stored) and rendered again: cannot decode image (corrupt or not an image)"
    ]
    assert repeated == []  # one warning per file
    assert np.array_equal(image, fresh) and np.array_equal(again, fresh)
    assert path.read_bytes() == b""


def test_a_stored_frame_that_cannot_be_opened_is_rendered_again(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A file this user may not read (another user's 0600 file; the tests run as root, which
    reads anything, so the refusal is simulated)."""

    fresh = rendered(tmp_path, "fresh", "indoor", "rgbd")[FRAME].image
    rendered(tmp_path, "cache", "indoor", "rgbd")[FRAME].image
    path = tmp_path / "cache" / "image_left" / "000001.png"

    def refused(file: object, *args: object, **kwargs: object) -> np.ndarray:
        raise PermissionError(13, "Permission denied", str(file))

    monkeypatch.setattr(np, "fromfile", refused)
    image, messages = cache_warnings(lambda: rendered(tmp_path, "cache", "indoor", "rgbd")[FRAME].image)
    monkeypatch.undo()
    assert messages == [f"{path}: bad cached frame, replaced by a fresh render: cannot read image (Permission denied)"]
    assert np.array_equal(image, fresh) and path.read_bytes() == (tmp_path / "fresh" / "image_left" / "000001.png").read_bytes()
