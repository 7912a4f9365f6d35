"""KITTI odometry layout: ``sequences/SS/image_0..3``, ``calib.txt``, ``times.txt``,
``poses/SS.txt``.

Grey images live in ``image_0`` (left) / ``image_1`` (right), colour in ``image_2`` / ``image_3``.
``calib.txt`` holds rectified projection matrices ``P_i = K [I | t_i]`` relative to camera 0, so
camera ``i`` sits at ``-t_i = -K^-1 P_i[:, 3]`` in the camera-0 frame and the stereo baseline is
``|t_left - t_right|`` (0.54 m). ``poses/SS.txt`` gives camera-0 poses, one row per frame; for
the colour camera they are moved to camera 2 (``T_w_c2 = T_w_c0 @ T_c0_c2``).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from sal_adapters.camera import MAX_FOCAL_PX, Camera
from sal_adapters.common.errors import DatasetError, DatasetWarning
from sal_adapters.common.textfiles import atomic_write_text, iter_rows, read_rows
from sal_adapters.datasets import DatasetKind
from sal_adapters.images import IMAGE_SUFFIXES, read_image, write_image
from sal_adapters.layout_io import fps_from_timestamps
from sal_adapters.sequence import Frame, FrameRecord, Sequence
from sal_adapters.trajectory import Trajectory, read_times, write_times

__all__ = ["KITTI", "KittiDataset", "read_calib"]

#: Rate assumed for a one-frame sequence (Hz); KITTI's cameras run at about 10 Hz.
KITTI_FPS = 10.0

#: (left, right) image folders for grey and colour pairs, and their calib.txt keys.
CAMERA_DIRS = {False: ("image_0", "image_1", "P0", "P1"), True: ("image_2", "image_3", "P2", "P3")}


class KittiDataset(DatasetKind):
    """KITTI odometry sequences (grey or colour, mono or stereo)."""

    name = "kitti"
    description = "KITTI odometry: sequences/SS/image_0..3, calib.txt, times.txt, poses/SS.txt"

    def open(
        self,
        path: Path | None,
        *,
        sequence: str | int | None = None,
        stereo: bool = False,
        color: bool | None = None,
    ) -> Sequence:
        """Open a KITTI sequence.

        Args:
            path: the sequence folder (``.../sequences/07``) or the dataset root holding
                ``sequences/`` (then ``sequence`` picks one).
            sequence: sequence id, ``7`` or ``"07"``.
            stereo: also load the right camera.
            color: ``True`` for image_2/3, ``False`` for image_0/1; default grey when present.
        """
        seq_dir = _sequence_dir(path, sequence)
        if color is None:
            color = not (seq_dir / "image_0").is_dir() and (seq_dir / "image_2").is_dir()
        left_name, right_name, left_key, right_key = CAMERA_DIRS[bool(color)]
        calib = read_calib(seq_dir / "calib.txt", [left_key, right_key] if stereo else [left_key])
        left_files = _image_files(seq_dir / left_name)
        times_path = seq_dir / "times.txt"
        times = read_times(times_path)
        if len(times) != len(left_files):
            raise DatasetError(f"{len(times)} timestamps for {len(left_files)} images in {left_name}/", times_path)
        right_files: list[Path | None] = list(_right_files(seq_dir / right_name, left_files)) if stereo else [None] * len(left_files)
        camera, T_c0_left = _camera(calib, left_key, right_key if stereo else None, read_image(left_files[0]).shape)
        records = [
            FrameRecord(index=i, timestamp=float(t), stem=f.stem, image=f, right=r)
            for i, (t, f, r) in enumerate(zip(times, left_files, right_files))
        ]
        name = seq_dir.name
        poses_path = seq_dir.parent.parent / "poses" / f"{name}.txt"
        groundtruth = None
        if poses_path.is_file():
            groundtruth = Trajectory.read_kitti(poses_path, times=_times_for_poses(poses_path, times))
            groundtruth = groundtruth.transformed(right=T_c0_left)
        fps = fps_from_timestamps(times, KITTI_FPS)
        meta: dict[str, Any] = {
            "sequence": name,
            "calib": {key: value.ravel().tolist() for key, value in calib.items()},
            "T_c0_left": T_c0_left.ravel().tolist(),
        }
        return Sequence(
            kind=self.name,
            name=f"kitti/{name}",
            camera=camera,
            sensor="stereo" if stereo else "mono",
            fps=fps,
            records=records,
            groundtruth=groundtruth,
            grayscale=not color,
            source=seq_dir,
            meta=meta,
        )

    def write(self, sequence: Sequence, out_dir: Path, frames: Iterable[Frame]) -> Path:
        """Write ``sequences/SS/...`` and ``poses/SS.txt`` under ``out_dir``; frames are renumbered
        ``000000..`` in order (KITTI tools derive file names from the line number of times.txt)."""
        seq_id = str(sequence.meta.get("sequence", "00")) if sequence.kind == self.name else "00"
        seq_dir = out_dir / "sequences" / seq_id
        color = not sequence.grayscale
        left_name, right_name, left_key, right_key = CAMERA_DIRS[color]
        stereo = sequence.sensor == "stereo"
        for position, frame in enumerate(frames):
            stem = f"{position:06d}"
            write_image(seq_dir / left_name / f"{stem}.png", frame.image, grey=not color)
            if stereo:
                write_image(seq_dir / right_name / f"{stem}.png", frame.require("right"), grey=not color)
        write_times(seq_dir / "times.txt", sequence.timestamps)
        calib, T_c0_left = _calib_for(sequence, left_key, right_key)
        lines = [f"{key}: " + " ".join(f"{v:.12e}" for v in np.ravel(value)) for key, value in calib.items()]
        atomic_write_text(seq_dir / "calib.txt", "\n".join(lines) + "\n")
        if sequence.groundtruth is not None:
            if sequence.groundtruth_is_per_frame:
                gt = sequence.groundtruth.transformed(right=np.linalg.inv(T_c0_left))
                gt.write_kitti(out_dir / "poses" / f"{seq_id}.txt")
            else:
                warnings.warn(
                    f"{sequence.name}: ground truth is not one pose per frame; KITTI poses/{seq_id}.txt not written",
                    DatasetWarning,
                    stacklevel=2,
                )
        return seq_dir


def read_calib(path: Path, required: list[str]) -> dict[str, np.ndarray]:
    """Parse ``calib.txt`` (``KEY: 12 values`` per line) into 3x4 matrices; ``required`` keys
    must be present."""
    calib: dict[str, np.ndarray] = {}
    for number, fields in read_rows(path):
        key = fields[0].rstrip(":")
        if len(fields) != 13:
            raise DatasetError(f"expected '{key}:' followed by 12 numbers, got {len(fields) - 1}", path, number)
        try:
            calib[key] = np.array([float(v) for v in fields[1:]]).reshape(3, 4)
        except ValueError:
            raise DatasetError(f"expected 12 numbers after '{key}:'", path, number) from None
        _check_projection(calib[key], key, path, number)
    missing = [key for key in required if key not in calib]
    if missing:
        raise DatasetError(f"missing projection matrix {', '.join(missing)} (found: {', '.join(calib) or 'none'})", path)
    return calib


#: focal lengths (px) a camera can have: a 1 px lens to a 10^6 px telescope
_FOCAL_RANGE_PX = (1.0, MAX_FOCAL_PX)


def _check_projection(P: np.ndarray, key: str, path: Path, line: int) -> None:
    """``DatasetError`` naming file, line and key unless ``P`` is a camera: finite numbers,
    focal lengths ``fx = P[0, 0]`` and ``fy = P[1, 1]`` within ``_FOCAL_RANGE_PX``, and an
    invertible left 3x3 block (``_camera0_to_camera`` solves with it)."""
    low, high = _FOCAL_RANGE_PX
    for name, value in (("fx", P[0, 0]), ("fy", P[1, 1])):
        if not low <= value <= high:  # also false for nan
            raise DatasetError(
                f"{key}: the focal length {name} = {value:g} px is not a camera's: expected a finite number between {low:g} and {high:g} px",
                path,
                line,
            )
    if not np.isfinite(P).all():
        raise DatasetError(f"{key}: expected 12 finite numbers, got {' '.join(f'{v:g}' for v in P.ravel())}", path, line)
    if abs(np.linalg.det(P[:, :3])) < 1e-12 * high**2:
        raise DatasetError(f"{key}: the left 3x3 block of the projection matrix is singular", path, line)


def _camera0_to_camera(P: np.ndarray) -> np.ndarray:
    """``t = K^-1 P[:, 3]``: translation from camera 0 to the rectified camera of ``P`` (m)."""
    return np.linalg.solve(P[:, :3], P[:, 3])


def _right_files(folder: Path, left_files: list[Path]) -> list[Path]:
    """The right image of every left image (same name in ``folder``); all must exist."""
    right_files = [folder / f.name for f in left_files]
    missing = [f for f in right_files if not f.is_file()]
    if missing:
        raise DatasetError(
            f"stereo needs a right image for every left image: {len(missing)} of {len(right_files)} missing (first: {missing[0].name})",
            folder,
        )
    return right_files


def _camera(calib: dict[str, np.ndarray], left_key: str, right_key: str | None, shape: tuple[int, ...]) -> tuple[Camera, np.ndarray]:
    """The left camera of images of ``shape`` from its ``calib.txt`` matrix (with the right
    camera's offset when ``right_key`` is given), and ``T_c0_left``, its pose in camera 0."""
    P_left = calib[left_key]
    camera = Camera(fx=P_left[0, 0], fy=P_left[1, 1], cx=P_left[0, 2], cy=P_left[1, 2], width=shape[1], height=shape[0])
    t_left = _camera0_to_camera(P_left)
    if right_key is not None:
        T_lr = np.eye(4)
        T_lr[:3, 3] = t_left - _camera0_to_camera(calib[right_key])
        camera = camera.with_stereo(T_lr)
    T_c0_left = np.eye(4)
    T_c0_left[:3, 3] = -t_left
    return camera, T_c0_left


def _sequence_dir(path: Path | None, sequence: str | int | None) -> Path:
    if path is None:
        raise DatasetError("the kitti dataset needs a path (the sequence folder or the dataset root)")
    if sequence is not None:
        seq_id = f"{int(sequence):02d}" if str(sequence).isdigit() else str(sequence)
        for candidate in (path / "sequences" / seq_id, path / seq_id):
            if candidate.is_dir():
                return candidate
        if path.name == seq_id:
            return path
        raise DatasetError(f"sequence {seq_id!r} not found (looked for sequences/{seq_id}/)", path)
    if (path / "times.txt").is_file() or any((path / d).is_dir() for d in ("image_0", "image_2")):
        return path
    if (path / "sequences").is_dir():
        found = sorted(p.name for p in (path / "sequences").iterdir() if p.is_dir())
        if len(found) == 1:
            return path / "sequences" / found[0]
        raise DatasetError(f"several sequences found ({', '.join(found)}); pass sequence=", path / "sequences")
    raise DatasetError("not a KITTI sequence folder (no times.txt, image_0/ or image_2/, nor sequences/)", path)


def _image_files(folder: Path) -> list[Path]:
    if not folder.is_dir():
        raise DatasetError("image folder not found", folder)
    files = sorted(f for f in folder.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise DatasetError("no images found", folder)
    return files


def _times_for_poses(poses_path: Path, times: np.ndarray) -> np.ndarray:
    """One timestamp per pose row: the frame times (the file must have a row per frame)."""
    rows = sum(1 for _ in iter_rows(poses_path))
    if rows != len(times):
        raise DatasetError(f"{rows} poses for {len(times)} frames (one 3x4 pose per frame expected)", poses_path)
    return times


def _calib_for(sequence: Sequence, left_key: str, right_key: str) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Projection matrices to write and the left camera's pose in the camera-0 frame.

    A KITTI source keeps its own ``calib.txt``; anything else gets ``P = K [I | t]`` with the
    left camera as camera 0 (and 2) and the right one at the baseline.
    """
    if sequence.kind == "kitti" and "calib" in sequence.meta:
        calib = {key: np.asarray(v).reshape(3, 4) for key, v in sequence.meta["calib"].items()}
        return calib, np.asarray(sequence.meta["T_c0_left"]).reshape(4, 4)
    cam = sequence.camera
    if any(cam.distortion) or cam.right is not None:
        warnings.warn(
            f"{sequence.name}: the KITTI layout assumes rectified, undistorted images; distortion and a "
            "separate right camera are not written",
            DatasetWarning,
            stacklevel=3,
        )
    K = cam.K
    left = K @ np.hstack([np.eye(3), np.zeros((3, 1))])
    right = K @ np.hstack([np.eye(3), [[-(cam.baseline_m or 0.0)], [0.0], [0.0]]])
    calib = {"P0": left, "P1": right, "P2": left, "P3": right}
    return calib, np.eye(4)


KITTI = KittiDataset()
