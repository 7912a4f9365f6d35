"""A plain folder of images (monocular), with optional timestamps, intrinsics and ground truth.

Frames are the images in the folder (``IMAGE_SUFFIXES``, hidden files skipped) in natural order
(``img2.png`` before ``img10.png``). Timestamps, in priority:

1. the ``timestamps=`` option, a file (absolute, or relative to the working or image folder);
2. ``timestamps.txt``, else ``times.txt``, in the folder.

   A timestamp file holds either one time (s) per line, for the images in natural order, or
   TUM-list lines ``timestamp filename``, which then define the frames and their order (file
   names relative to the image folder);
3. file stems that are times: ``1341847980.722988`` (seconds, with a decimal point) or
   ``1403715274312143104`` (16 or more digits: nanoseconds); frames are then sorted by time;
4. ``index / fps`` (``fps`` defaults to 30 Hz).

Intrinsics: the ``intrinsics=`` option, else ``camera.yaml`` in the folder (format in
``sal_adapters.layout_io``), else ``fx = fy = width``, ``cx = (width - 1) / 2``,
``cy = (height - 1) / 2`` px without distortion (warned). Ground truth: ``groundtruth.txt``
(TUM format) in the folder, when present.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path

import numpy as np

from sal_adapters.camera import Camera
from sal_adapters.common.bounded_yaml import one_line
from sal_adapters.common.errors import DatasetError, DatasetWarning
from sal_adapters.common.textfiles import atomic_write_text, format_float, read_rows
from sal_adapters.datasets import DatasetKind
from sal_adapters.images import IMAGE_SUFFIXES, probe_image, write_image
from sal_adapters.layout_io import (
    CAMERA_FILE,
    checked_image,
    fps_from_timestamps,
    frame_file_stem,
    natural_key,
    read_list,
    select_camera,
    write_camera_yaml,
)
from sal_adapters.sequence import Frame, FrameRecord, Sequence
from sal_adapters.trajectory import Trajectory

__all__ = ["DEFAULT_FPS", "FOLDER", "TIMESTAMP_FILES", "FolderDataset"]

#: Frame rate (Hz) assumed when neither timestamps nor ``fps`` are given.
DEFAULT_FPS = 30.0
#: Timestamp files looked for in the image folder, in priority.
TIMESTAMP_FILES = ("timestamps.txt", "times.txt")


class FolderDataset(DatasetKind):
    """A folder of images as a monocular sequence."""

    name = "folder"
    description = "folder of images (natural order) + optional timestamps.txt/times.txt, camera.yaml, groundtruth.txt"

    def open(
        self,
        path: Path | None,
        *,
        fps: float | None = None,
        timestamps: str | Path | None = None,
        intrinsics: tuple[float, float, float, float] | str | None = None,
        distortion: tuple[float, ...] | str | None = None,
        stereo: bool = False,
    ) -> Sequence:
        """Open a folder of images.

        Args:
            path: the image folder.
            fps: frame rate (Hz): the nominal rate, and the clock of frames without timestamps
                (default: ``1 / median interval`` of the timestamps, else 30 Hz).
            timestamps: a timestamp file, replacing ``timestamps.txt`` / ``times.txt``.
            intrinsics: ``(fx, fy, cx, cy)`` (px) replacing ``camera.yaml`` / the assumed ones;
                no distortion unless ``distortion`` is given too.
            distortion: OpenCV coefficients ``(k1, k2, p1, p2[, k3])``.
            stereo: must be False (a folder is one camera).
        """
        if stereo:
            raise DatasetError("the folder dataset is monocular; open it with stereo=False")
        if fps is not None and not float(fps) > 0:
            raise DatasetError(f"option fps must be > 0 Hz, got {fps!r}")
        if path is None:
            raise DatasetError("the folder dataset needs a path (the image folder)")
        folder = Path(path).expanduser()
        if not folder.is_dir():
            raise DatasetError("image folder not found", folder)

        list_path = _timestamp_file(folder, timestamps)
        ns: list[int] | None = None
        if list_path is not None:
            files, times = _read_timestamp_file(folder, list_path)
        else:
            files = _image_files(folder)
            stem_times, stem_ns = _stem_times([f.stem for f in files])
            if stem_times is not None:
                order = np.argsort(stem_times, kind="stable")
                files, times = [files[k] for k in order], stem_times[order]
                ns = None if stem_ns is None else [stem_ns[k] for k in order]
                if np.any(np.diff(times) <= 0):
                    k = int(np.flatnonzero(np.diff(times) <= 0)[0])
                    raise DatasetError(f"two images have the same time in their names: {files[k].name}, {files[k + 1].name}", folder)
            else:
                times = np.arange(len(files), dtype=np.float64) / float(fps or DEFAULT_FPS)
        records = [
            FrameRecord(index=i, timestamp=float(t), stem=f.stem, image=f, timestamp_ns=None if ns is None else ns[i])
            for i, (t, f) in enumerate(zip(times, files))
        ]
        width, height, grey = probe_image(files[0])

        def fallback() -> Camera:
            fx, cx, cy = float(width), (width - 1) / 2.0, (height - 1) / 2.0
            warnings.warn(
                f"{folder}: no {CAMERA_FILE} and no intrinsics option; assuming fx=fy={fx:g} px (the image width, "
                f"about 53 deg horizontal field of view), cx={cx:g} cy={cy:g} px, no distortion. Pass "
                f"intrinsics=(fx, fy, cx, cy) or add {CAMERA_FILE} to override.",
                DatasetWarning,
                stacklevel=4,
            )
            return Camera(fx=fx, fy=fx, cx=cx, cy=cy, width=width, height=height)

        camera = replace(select_camera(folder, width, height, intrinsics, distortion, fallback), depth_scale=None)
        gt_path = folder / "groundtruth.txt"
        return Sequence(
            kind=self.name,
            name=f"folder/{folder.name}",
            camera=camera,
            sensor="mono",
            fps=float(fps) if fps is not None else fps_from_timestamps(times, DEFAULT_FPS),
            records=records,
            groundtruth=Trajectory.read_tum(gt_path) if gt_path.is_file() else None,
            grayscale=grey,
            source=folder,
        )

    def write(self, sequence: Sequence, out_dir: Path, frames: Iterable[Frame]) -> Path:
        """Write ``<stem>.png`` per frame, ``timestamps.txt`` (``timestamp filename``),
        ``camera.yaml`` and ``groundtruth.txt`` (when known) into ``out_dir``; return it.
        Right images and depth maps are not written (warned)."""
        out_dir = Path(out_dir)
        if sequence.sensor != "mono":
            warnings.warn(
                f"{sequence.name}: the folder layout holds one camera; the {sequence.sensor} sequence's "
                f"{'right images' if sequence.sensor == 'stereo' else 'depth maps'} are not written",
                DatasetWarning,
                stacklevel=3,
            )
        lines: list[str] = []
        used: set[str] = set()
        for position, frame in enumerate(frames):
            stem = frame_file_stem(frame.record.stem, position, used)
            image = checked_image(frame, sequence.camera, sequence.name)
            write_image(out_dir / f"{stem}.png", image, grey=sequence.grayscale)
            lines.append(f"{format_float(frame.timestamp)} {stem}.png\n")
        if not lines:
            raise DatasetError(f"{sequence.name}: no frames to write")
        atomic_write_text(out_dir / TIMESTAMP_FILES[0], "# timestamp filename\n" + "".join(lines))
        write_camera_yaml(out_dir / CAMERA_FILE, sequence.camera)
        if sequence.groundtruth is not None:
            sequence.groundtruth.write_tum(out_dir / "groundtruth.txt")
        return out_dir


def _timestamp_file(folder: Path, option: str | Path | None) -> Path | None:
    if option is None:
        return next((folder / n for n in TIMESTAMP_FILES if (folder / n).is_file()), None)
    path = Path(option).expanduser()
    if not path.is_absolute() and not path.exists() and (folder / path).exists():
        path = folder / path
    if not path.is_file():
        raise DatasetError("timestamps file not found (option timestamps)", path)
    return path


def _read_timestamp_file(folder: Path, path: Path) -> tuple[list[Path], np.ndarray]:
    """Image files and times (s) from a one-column or ``timestamp filename`` file."""
    rows = read_rows(path)
    columns = len(rows[0][1]) if rows else 1
    if columns == 2:
        listed = read_list(path, "tf", "timestamp filename")
        files = []
        for number, (_, name) in listed:
            file = folder / str(name)
            if not _exists(file):
                raise DatasetError(f"listed image {one_line(str(name), 80)} not found in {folder}", path, number)
            files.append(file)
        return files, np.array([row[1][0] for row in listed], dtype=np.float64)
    if columns != 1:
        raise DatasetError(f"expected 'timestamp' or 'timestamp filename' per line, got {columns} fields", path, rows[0][0])
    times = np.array([row[1][0] for row in read_list(path, "t", "timestamp")], dtype=np.float64)
    files = _image_files(folder)
    if len(times) != len(files):
        raise DatasetError(f"{len(times)} timestamps for {len(files)} images in {folder} (one time per image, in name order)", path)
    return files, times


def _exists(file: Path) -> bool:
    """``file.is_file()``, false for a name the file system refuses (too long)."""
    try:
        return file.is_file()
    except OSError:
        return False


def _image_files(folder: Path) -> list[Path]:
    """Image files of ``folder`` (hidden ones skipped) in natural order; at least one."""
    files = sorted(
        (f for f in folder.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES and not f.name.startswith(".") and f.is_file()),
        key=lambda f: natural_key(f.name),
    )
    if not files:
        raise DatasetError(f"no images found (looked for {', '.join(IMAGE_SUFFIXES)})", folder)
    return files


def _stem_times(stems: list[str]) -> tuple[np.ndarray | None, list[int] | None]:
    """``(times (s), times (ns) or None)`` when every stem is a time: ``1341847980.722988``
    (s) or 16+ digits (ns); ``(None, None)`` otherwise."""
    if all(re.fullmatch(r"\d+\.\d+", s) for s in stems):
        return np.array([float(s) for s in stems], dtype=np.float64), None
    if all(re.fullmatch(r"\d{16,}", s) for s in stems):
        ns = [int(s) for s in stems]
        return np.array(ns, dtype=np.float64) * 1e-9, ns
    return None, None


FOLDER = FolderDataset()
