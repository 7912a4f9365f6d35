"""Opening datasets by kind and writing sequences back in a dataset layout.

A dataset kind is an object with ``name``, ``description``, ``open(path, **options)`` and
``write(sequence, out_dir) -> path``; built-ins and plug-ins register in the ``sal.datasets``
entry-point group.
"""

from __future__ import annotations

import inspect
import json
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sal_adapters.common.atomic import Replacement, replacing_dir, writing
from sal_adapters.common.errors import DatasetError
from sal_adapters.common.plugins import EntryPointRegistry
from sal_adapters.common.textfiles import atomic_write_text

if TYPE_CHECKING:  # the registry (DATASETS.names() in the sal command's help) needs no numpy
    from sal_adapters.sequence import Frame, Sequence

__all__ = [
    "DATASETS",
    "WRITTEN_MARKER",
    "DatasetKind",
    "open_dataset",
    "truncate",
    "write_sequence",
]

#: File left in every folder ``write_sequence`` made: what was written and how to reopen it.
WRITTEN_MARKER = "sal_sequence.json"


class DatasetKind(ABC):
    """A dataset layout: how to open it and how to write a sequence in it.

    Each kind defines ``open(self, path, *, <options>) -> Sequence``: open the dataset at
    ``path`` (``None`` where a kind needs none); its keyword-only parameters are the kind's
    options (``option_names``), so each kind declares its own signature.
    """

    name: str = ""
    description: str = ""
    #: ``open`` takes a file as well as a folder (a ROS 1 bag, an MCAP file, a video).
    opens_files: bool = False
    #: Suffixes of the single files ``write_file`` writes (``.bag``, ``.mcap``, ``.mp4``);
    #: ``write_sequence(seq, "out.mcap")`` writes that file instead of a folder.
    file_suffixes: tuple[str, ...] = ()
    #: ``open(path, **options) -> Sequence`` with the keyword-only options the kind declares.
    open: Callable[..., Sequence]

    @abstractmethod
    def write(self, sequence: Sequence, out_dir: Path, frames: Iterable[Frame]) -> Path:
        """Write ``sequence`` under the empty folder ``out_dir``, taking the decoded frames from
        ``frames`` (``sequence``'s frames in order, perhaps behind a progress bar); return the
        path that ``open`` reads the copy back from."""

    def write_file(self, sequence: Sequence, path: Path, frames: Iterable[Frame]) -> None:
        """Write ``sequence`` as the one file ``path`` (its suffix is one of ``file_suffixes``),
        plus any sidecar files beside it, in a folder of its own that ``write_sequence`` moves
        into place when complete."""
        raise DatasetError(f"dataset kind {self.name!r} writes folders, not single files")

    def details(self, sequence: Sequence) -> list[tuple[str, str]]:
        """Extra ``(label, text)`` lines ``sal dataset info`` prints about where the frames come
        from (a bag's topics, a video's codec); none by default."""
        return []

    def option_names(self) -> list[str]:
        """Keyword options ``open`` accepts."""
        params = inspect.signature(self.open).parameters.values()
        return [p.name for p in params if p.kind is inspect.Parameter.KEYWORD_ONLY]


DATASETS: EntryPointRegistry[DatasetKind] = EntryPointRegistry("sal.datasets", "dataset kind")


def open_dataset(
    kind: str,
    path: str | Path | None = None,
    *,
    start: int = 0,
    max_frames: int | None = None,
    **options: Any,
) -> Sequence:
    """Open a dataset as a lazily decoded ``Sequence``.

    Args:
        kind: ``kitti``, ``tum``, ``euroc``, ``folder``, ``synthetic`` or a plug-in kind.
        path: the dataset folder (optional for ``synthetic``).
        start: first frame to keep (0-based).
        max_frames: keep at most this many frames from ``start``.
        options: kind-specific options, e.g. ``sequence="07"``, ``stereo=True``.

    Raises:
        DatasetError: the folder, a file or an option is wrong (the message names it).
    """
    dataset = DATASETS.get(kind)
    allowed = dataset.option_names()
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise DatasetError(
            f"unknown option{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))} for dataset kind {kind!r}; "
            f"allowed: start, max_frames, {', '.join(allowed)}"
        )
    if path is not None:
        path = Path(path).expanduser()
        if not path.exists():
            raise DatasetError(f"{kind} dataset {'path' if dataset.opens_files else 'folder'} not found", path)
        if not path.is_dir() and not dataset.opens_files:
            raise DatasetError(f"{kind} dataset path is not a folder", path)
    sequence = dataset.open(path, **options)
    return truncate(sequence, start, max_frames)


def truncate(sequence: Sequence, start: int = 0, max_frames: int | None = None) -> Sequence:
    """Frames ``start .. start + max_frames - 1``; time-indexed ground truth is cropped to
    their time span (plus one frame period either side). A kind whose sequences carry an
    ``excerpt`` key in ``meta`` gets ``[start, stop)`` there (the rosbag writer copies the
    other topics over the excerpt's time span)."""
    if start < 0:
        raise DatasetError(f"start must be >= 0 (frame number), got {start}")
    if max_frames is not None and max_frames < 1:
        raise DatasetError(f"max_frames must be >= 1, got {max_frames}")
    if start == 0 and (max_frames is None or max_frames >= len(sequence)):
        return sequence
    if start >= len(sequence):
        raise DatasetError(f"start={start} is past the last frame: {sequence.name} has {len(sequence)} frames")
    stop = len(sequence) if max_frames is None else min(len(sequence), start + max_frames)
    was_per_frame = sequence.groundtruth_is_per_frame
    cut = sequence.select(range(start, stop))
    if cut.groundtruth is not None and not was_per_frame:
        margin = 1.0 / sequence.fps
        t = cut.timestamps
        cropped = cut.groundtruth.crop(t[0] - margin, t[-1] + margin)
        cut = cut.replace(groundtruth=cropped if len(cropped) else None)
    if "excerpt" in cut.meta:
        cut = cut.replace(meta={**cut.meta, "excerpt": [start, stop]})
    return cut


def write_sequence(sequence: Sequence, out_dir: str | Path, layout: str | None = None, progress: bool = False) -> Path:
    """Write ``sequence`` in its own dataset layout (or ``layout``) under ``out_dir``, or as the
    single file ``out_dir`` when its suffix is one a layout writes (``out.bag`` and ``out.mcap``:
    ``rosbag``; ``out.mp4``: ``video``; chosen by the suffix when ``layout`` is not given).

    The folder is filled through a hidden sibling and swapped into place when complete
    (``sal_adapters.common.atomic``), so a run killed midway leaves the previous copy, never a half
    written one. An existing ``out_dir`` must be empty or an earlier output of this function
    (it is replaced). Never writes into the sequence's source folder. A folder that cannot be
    written raises ``WriteError`` naming it.

    Returns:
        The path to give ``open_dataset(layout, path)`` to read the copy back.
    """
    kind = layout or _layout_for_suffix(sequence.kind, Path(out_dir).suffix.lower())
    dataset = DATASETS.get(kind)
    try:
        out_dir = Path(out_dir).expanduser().resolve()
    except RuntimeError:  # Python < 3.13 on a symlink loop
        raise DatasetError("the output path runs into a symlink loop; choose another output folder", out_dir) from None
    _refuse_source_overlap(sequence, out_dir)
    if out_dir.suffix.lower() in dataset.file_suffixes:
        return _write_file(dataset, sequence, out_dir, _frames(sequence, progress))
    if out_dir.exists() and any(out_dir.iterdir()) and not (out_dir / WRITTEN_MARKER).is_file():
        raise DatasetError("output folder is not empty and was not written by pytest-sal; choose an empty folder", out_dir)
    with writing(out_dir), replacing_dir(out_dir) as staging:
        reopen = str(dataset.write(sequence, staging, _frames(sequence, progress)).relative_to(staging))
        marker = {
            "layout": kind,
            "path": reopen,
            "name": sequence.name,
            "frames": len(sequence),
            "source_fingerprint": sequence.fingerprint,
        }
        atomic_write_text(staging / WRITTEN_MARKER, json.dumps(marker, indent=2) + "\n")
    return out_dir / reopen


def _layout_for_suffix(kind: str, suffix: str) -> str:
    """``kind``, or the kind that writes single files ending in ``suffix`` when ``kind`` does
    not (``write_sequence(kitti, "out.mcap")`` writes a bag, ``"out.mp4"`` a video)."""
    if not suffix or suffix in DATASETS.get(kind).file_suffixes:
        return kind
    return next((name for name, other in DATASETS.items() if suffix in other.file_suffixes), kind)


def _frames(sequence: Sequence, progress: bool) -> Iterable[Frame]:
    """The frames of ``sequence`` in order, behind a progress bar when asked."""
    if not progress:
        return iter(sequence)
    from tqdm.auto import tqdm

    return tqdm(iter(sequence), total=len(sequence), desc=f"writing {sequence.name}", unit="frame")


def _write_file(dataset: DatasetKind, sequence: Sequence, path: Path, frames: Iterable[Frame]) -> Path:
    """``dataset.write_file`` into a staging folder beside ``path``, whose files then replace
    their namesakes together (an existing ``path`` is refused: it may be a user's recording)."""
    if path.exists():
        raise DatasetError("output file exists; remove it or choose another name", path)
    with Replacement() as outputs:
        staging = outputs.entries(path.parent)
        with writing(path):
            dataset.write_file(sequence, staging / path.name, frames)
    return path


def _refuse_source_overlap(sequence: Sequence, out_dir: Path) -> None:
    if sequence.source is None:
        return
    source = sequence.source.resolve()
    if out_dir == source or out_dir.is_relative_to(source) or source.is_relative_to(out_dir):
        raise DatasetError(f"refusing to write into the source dataset folder {source}; choose another output folder", out_dir)
