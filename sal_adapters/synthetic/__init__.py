"""The synthetic world: deterministic textured 3-D scenes with exact depth, stereo and poses.

>>> from sal_adapters import open_dataset
>>> seq = open_dataset("synthetic", scene="indoor", frames=30, seed=1)   # doctest: +SKIP

Scenes: ``urban`` (KITTI-like street, 1240x376 px, 10 Hz, stereo baseline 0.54 m) and
``indoor`` (TUM-like room, 640x480 px, 30 Hz, baseline 0.1 m, depth scale 5000). Frames
are rendered on first access and cached on disk (``cache_dir`` or the user cache folder).
Every frame carries its exact ground-truth depth, whatever the sensor.
Modules: ``textures``/``urban_tiles``/``indoor_tiles`` paint tiles, ``atlas`` packs them,
``geometry`` and ``render`` draw boxes, ``world``/``urban``/``indoor`` define scenes and
motion, ``cache`` renders lazily, ``layout`` reads and writes the folder layout.
"""

from __future__ import annotations

from collections.abc import Iterable
from numbers import Integral
from pathlib import Path
from typing import Any

from sal_adapters.common.errors import DatasetError
from sal_adapters.datasets import DatasetKind
from sal_adapters.sequence import SENSORS, Frame, Sequence
from sal_adapters.synthetic.cache import (
    RENDERER_VERSION,
    rendered_frames_dir,
    rendered_sequence,
)
from sal_adapters.synthetic.indoor import IndoorWorld
from sal_adapters.synthetic.layout import read_layout, read_metadata, write_layout
from sal_adapters.synthetic.urban import UrbanWorld
from sal_adapters.synthetic.world import World, shared_world

__all__ = ["RENDERER_VERSION", "SYNTHETIC", "WORLDS", "SyntheticDataset", "make_world"]

#: Scene name -> world class.
WORLDS: dict[str, type[World]] = {"urban": UrbanWorld, "indoor": IndoorWorld}


def make_world(scene: str, seed: int) -> World:
    """The world of ``scene`` and ``seed`` (shared, so its texture atlas is painted once)."""
    return shared_world(WORLDS[scene], seed)


class SyntheticDataset(DatasetKind):
    """Dataset kind ``synthetic``: rendered scenes, or folders in the synthetic layout."""

    name = "synthetic"
    description = "Rendered textured 3-D worlds (urban street, indoor room) with exact depth, stereo and ground-truth poses"

    def open(
        self,
        path: Path | None,
        *,
        scene: str = "urban",
        frames: int = 100,
        seed: int = 0,
        sensor: str | None = None,
        cache_dir: str | Path | None = None,
    ) -> Sequence:
        """Render ``frames`` frames of ``scene`` (lazily, cached), or open the folder ``path``.

        Args:
            path: a folder in the synthetic layout (a written copy or a render cache); then
                ``scene``, ``frames``, ``seed`` and ``cache_dir`` are ignored: they are read
                from the folder's ``sequence.json``.
            scene: ``urban`` or ``indoor``.
            frames: number of frames (>= 1); frame ``i`` is at ``i / fps`` seconds.
            seed: world and motion variant (integer >= 0).
            sensor: ``mono``, ``stereo`` or ``rgbd``; default ``stereo`` (urban), ``rgbd``
                (indoor), or the stored sensor of a folder.
            cache_dir: where rendered frames are kept; default
                ``<user cache>/synthetic/<scene>-seed<seed>-r<RENDERER_VERSION>``.

        Raises:
            DatasetError: an option value is not allowed, or the folder is malformed.
        """
        if sensor is not None and sensor not in SENSORS:
            raise DatasetError(f"option sensor={sensor!r} is not allowed; use one of {', '.join(SENSORS)}")
        if path is not None:
            return self._open_folder(Path(path), sensor)
        if scene not in WORLDS:
            raise DatasetError(f"option scene={scene!r} is not allowed; use one of {', '.join(WORLDS)}")
        frames = _integer("frames", frames, 1)
        seed = _integer("seed", seed, 0)
        world = make_world(scene, seed)
        folder = Path(cache_dir).expanduser() if cache_dir is not None else rendered_frames_dir(scene, seed)
        return rendered_sequence(world, folder, frames, sensor or world.default_sensor)

    def write(self, sequence: Sequence, out_dir: Path, frames: Iterable[Frame]) -> Path:
        """Write ``sequence`` (any kind and sensor) in the synthetic layout under ``out_dir``."""
        return write_layout(sequence, out_dir, frames)

    def _open_folder(self, folder: Path, sensor: str | None) -> Sequence:
        """A written copy, or a render cache (rendered on, with the renderer that made it)."""
        info = read_metadata(folder)
        if not info.get("cache"):
            return read_layout(folder, info, sensor)
        scene, seed, version = info.get("scene"), info.get("seed"), info.get("renderer_version")
        if scene not in WORLDS or not isinstance(seed, int) or seed < 0:
            raise DatasetError(f"render cache metadata names an unknown world: scene={scene!r} seed={seed!r}", folder / "sequence.json")
        if version != RENDERER_VERSION:
            raise DatasetError(
                f"frames were rendered by renderer version {version!r}, this is version {RENDERER_VERSION}; "
                f"open scene={scene!r} seed={seed} without a path to render afresh",
                folder / "sequence.json",
            )
        world = make_world(scene, seed)
        return rendered_sequence(world, folder, int(info["frames"]), sensor or world.default_sensor)


def _integer(option: str, value: Any, minimum: int) -> int:
    """``value`` as an int >= ``minimum`` (integers or decimal strings), else ``DatasetError``."""
    if isinstance(value, str) and value.strip().isdigit():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, Integral) or value < minimum:
        raise DatasetError(f"option {option}={value!r} is not allowed; use an integer >= {minimum}")
    return int(value)


#: The entry point of dataset kind ``synthetic``.
SYNTHETIC = SyntheticDataset()
