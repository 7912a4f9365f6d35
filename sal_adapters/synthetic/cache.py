"""Lazily rendered sequences whose frames are kept on disk, in the synthetic layout.

Opening renders nothing: each frame's image, right image and depth sources load the file
from the cache folder or render the frame, writing every file that rendering produced
(left view: image and depth; right view: image). Files are written through uniquely named
temporary files and ``os.replace``, so processes rendering the same frame at the same time
only ever see complete files. A stored file that cannot be read or decoded, or is not the array
a render gives (its size; floats for depth), is discarded with one ``CacheWarning`` naming it:
the frame is rendered again and the file replaced, identical to a fresh render. Opened inside
``no_cache_writes()`` (``sal perturb --dry-run``), a sequence reads what the folder holds and
renders the rest (and any bad file) in memory, storing nothing.
"""

from __future__ import annotations

import warnings
from functools import partial
from pathlib import Path

import numpy as np

from sal_adapters.common.cache_dir import cache_writes_allowed, user_cache_dir
from sal_adapters.common.errors import CacheWarning, DatasetError
from sal_adapters.images import read_depth, read_image, read_stored, write_depth, write_image
from sal_adapters.sequence import FrameRecord, Sequence, as_sensor
from sal_adapters.synthetic.layout import (
    DEPTH,
    LEFT,
    METADATA,
    RIGHT,
    FrameRow,
    read_metadata,
    write_metadata,
)
from sal_adapters.synthetic.world import World

__all__ = ["RENDERER_VERSION", "FrameStore", "frame_stem", "rendered_frames_dir", "rendered_sequence"]

#: Bump whenever rendered pixels or depth change: it is part of the cache folder name and
#: of every rendered sequence's fingerprint.
RENDERER_VERSION = 3


def rendered_frames_dir(scene: str, seed: int) -> Path:
    """``<user cache>/synthetic/<scene>-seed<seed>-r<RENDERER_VERSION>``."""
    return user_cache_dir("synthetic", f"{scene}-seed{seed}-r{RENDERER_VERSION}")


def frame_stem(index: int) -> str:
    """File name stem of frame ``index``: six digits, like KITTI."""
    return f"{index:06d}"


class FrameStore:
    """Frames of ``world`` in ``folder``: read when present and sound, rendered otherwise (and
    stored there unless ``store`` is false)."""

    def __init__(self, world: World, folder: Path, store: bool = True):
        self.world = world
        self.folder = Path(folder)
        self.store = store
        self._warned: set[Path] = set()  # bad files already said (warned once each)

    def _path(self, stream: str, index: int) -> Path:
        return self.folder / stream / f"{frame_stem(index)}{'.npy' if stream == DEPTH else '.png'}"

    def left(self, index: int) -> np.ndarray:
        """Left RGB image of frame ``index``."""
        stored = self._stored(LEFT, index)
        return stored if stored is not None else self._render_left(index)[0]

    def depth(self, index: int) -> np.ndarray:
        """Left z-depth (float32 m, 0 = sky) of frame ``index``."""
        stored = self._stored(DEPTH, index)
        return stored if stored is not None else self._render_left(index)[1]

    def right(self, index: int) -> np.ndarray:
        """Right RGB image of frame ``index``."""
        stored = self._stored(RIGHT, index)
        if stored is not None:
            return stored
        rgb, _ = self.world.render(index, right=True)
        if self.store:
            write_image(self._path(RIGHT, index), rgb)
        return rgb

    def _stored(self, stream: str, index: int) -> np.ndarray | None:
        """The stored ``stream`` file of frame ``index``; ``None`` when there is none, or when it
        cannot be read or is not the array a render gives (HxWx3 uint8 RGB, HxW float32 depth):
        then one ``CacheWarning`` names it, and the caller renders the frame again."""
        path = self._path(stream, index)
        width, height = self.world.intrinsics[4:]
        expected = (height, width) if stream == DEPTH else (height, width, 3)
        data, problem = read_stored(path, partial(read_depth, depth_scale=None) if stream == DEPTH else read_image)
        if data is not None and data.shape != expected:
            problem = f"holds an array of shape {data.shape}, a render gives {expected}"
            data = None
        if problem is not None:
            self._discard(path, problem)
        return data

    def _discard(self, path: Path, problem: str) -> None:
        """Say once that the stored file ``path`` is bad; rendering again replaces it (when storing)."""
        if path in self._warned:
            return
        self._warned.add(path)
        done = "replaced by a fresh render" if self.store else "ignored (nothing is stored) and rendered again"
        warnings.warn(CacheWarning(f"{path}: bad cached frame, {done}: {problem}"), stacklevel=4)

    def _render_left(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Render the left view and store both of its files."""
        rgb, depth = self.world.render(index)
        if self.store:
            write_image(self._path(LEFT, index), rgb)
            write_depth(self._path(DEPTH, index), depth, None)
        return rgb, depth


def rendered_sequence(world: World, folder: Path, frames: int, sensor: str) -> Sequence:
    """The first ``frames`` frames of ``world`` as ``sensor``, rendered on demand into ``folder``.

    The folder's metadata (a synthetic layout with ``cache: true``) is written or extended
    to at least ``frames`` frames (not inside ``no_cache_writes()``: nothing is stored then);
    a folder holding another world raises ``DatasetError``.
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise DatasetError("synthetic cache_dir is not a folder", folder)
    groundtruth = world.groundtruth(np.arange(frames))
    store = cache_writes_allowed()
    if _cached_frames(world, folder) < frames and store:
        folder.mkdir(parents=True, exist_ok=True)
        info = {
            "kind": "synthetic",
            "name": _name(world),
            "scene": world.name,
            "seed": world.seed,
            "renderer_version": RENDERER_VERSION,
            "sensor": world.default_sensor,
            "fps": world.fps,
            "camera": world.camera(world.default_sensor).to_dict(),
            "grayscale": False,
            "frames": frames,
            "cache": True,
        }
        rows = [FrameRow(frame_stem(i), i, i / world.fps) for i in range(frames)]
        write_metadata(folder, info, rows, groundtruth)
    frame_store = FrameStore(world, folder, store)
    records = [
        FrameRecord(
            index=i,
            timestamp=i / world.fps,
            stem=frame_stem(i),
            image=partial(frame_store.left, i),
            right=partial(frame_store.right, i) if sensor == "stereo" else None,
            depth=partial(frame_store.depth, i),
        )
        for i in range(frames)
    ]
    return Sequence(
        kind="synthetic",
        name=_name(world),
        camera=world.camera(sensor),
        sensor=as_sensor(sensor),
        fps=world.fps,
        records=records,
        groundtruth=groundtruth,
        source=folder,
        meta={"scene": world.name, "seed": world.seed, "renderer_version": RENDERER_VERSION},
        content_key=f"synthetic:{world.name}:seed={world.seed}:sensor={sensor}:renderer={RENDERER_VERSION}",
    )


def _name(world: World) -> str:
    return f"synthetic/{world.name}-seed{world.seed}"


def _cached_frames(world: World, folder: Path) -> int:
    """Frames listed in the cache folder's metadata (0 when there is none yet)."""
    if not (folder / METADATA).is_file():
        return 0
    info = read_metadata(folder)
    found = (info.get("scene"), info.get("seed"), info.get("renderer_version"), info.get("cache"))
    if found != (world.name, world.seed, RENDERER_VERSION, True):
        raise DatasetError(
            f"folder holds synthetic frames of scene={found[0]!r} seed={found[1]!r} renderer_version={found[2]!r} cache={found[3]!r}, "
            f"not of scene={world.name!r} seed={world.seed} renderer_version={RENDERER_VERSION}; use another cache_dir",
            folder / METADATA,
        )
    return int(info["frames"])
