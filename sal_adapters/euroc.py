"""EuRoC MAV layout: ``<sequence>/mav0/cam0|cam1/{data.csv, data/<ns>.png, sensor.yaml}``,
``imu0/``, ``body.yaml`` and ``state_groundtruth_estimate0/data.csv``.

Frames are named by their capture time in integer nanoseconds. Each camera's ``sensor.yaml``
holds its intrinsics ``[fu, fv, cu, cv]`` (px), radial-tangential distortion ``[k1, k2, p1, p2]``,
resolution, rate (Hz) and ``T_BS``, its pose in the body (IMU) frame. The right camera sits at
``T_left_right = inv(T_BS_cam0) @ T_BS_cam1`` in the left camera frame. The standard ground truth
gives body poses ``T_WB``; the camera-0 poses are ``T_WC = T_WB @ T_BS_cam0``. The camera
files themselves are read and written by ``sal_adapters.euroc_files``.
"""

from __future__ import annotations

import re
import shutil
import warnings
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from sal_adapters.camera import Camera
from sal_adapters.common.atomic import copy_tree
from sal_adapters.common.errors import DatasetError, DatasetWarning
from sal_adapters.common.textfiles import atomic_write_text
from sal_adapters.datasets import DatasetKind
from sal_adapters.euroc_files import (
    FRAME_CSV_HEADER,
    GT_SENSOR_YAML,
    CameraSensor,
    FrameRow,
    read_camera_sensor,
    read_frame_csv,
    read_sensor_yaml,
    read_transform,
    sensor_yaml,
)
from sal_adapters.images import probe_image, write_image
from sal_adapters.sequence import Frame, FrameRecord, Sequence
from sal_adapters.trajectory import Trajectory

__all__ = ["EUROC", "GROUNDTRUTH_FRAMES", "EurocDataset"]

GROUNDTRUTH_FRAMES = ("body", "camera")


class EurocDataset(DatasetKind):
    """EuRoC MAV sequences (grey, mono or unrectified stereo, ns timestamps)."""

    name = "euroc"
    description = "EuRoC MAV: <seq>/mav0/cam0|cam1/{data.csv,data/<ns>.png,sensor.yaml}, state_groundtruth_estimate0/"

    def open(
        self,
        path: Path | None,
        *,
        sequence: str | None = None,
        stereo: bool = False,
        groundtruth: str | Path | None = None,
        groundtruth_frame: str | None = None,
    ) -> Sequence:
        """Open a EuRoC sequence.

        Args:
            path: the sequence folder (holding ``mav0/``), ``mav0/`` itself, or a parent folder
                (then ``sequence`` names the sub-folder, e.g. ``"V1_01_easy"``).
            sequence: sub-folder of ``path`` holding the sequence.
            stereo: also load ``cam1``; frames are the cam0/cam1 rows with the same ns time.
            groundtruth: an EuRoC CSV (``ns, p xyz [m], q wxyz``) to use as ground truth instead of
                the one found in the folder.
            groundtruth_frame: ``"body"`` (poses of the IMU/body frame, moved to cam0 with
                ``T_BS``) or ``"camera"`` (poses of cam0 already). Default: ``body`` for
                ``groundtruth=`` and ``state_groundtruth_estimate0/data.csv``, ``camera`` for a
                ``groundtruth*.csv`` / ``*_GT*.csv`` file in the sequence folder (ORB-SLAM3
                evaluation files).

        Raises:
            DatasetError: a folder, file, line or option is wrong (the message names it).
        """
        if groundtruth_frame is not None and groundtruth_frame not in GROUNDTRUTH_FRAMES:
            raise DatasetError(f"groundtruth_frame must be 'body' or 'camera', got {groundtruth_frame!r}")
        seq_dir = _sequence_dir(path, sequence)
        mav0 = seq_dir / "mav0"
        left = read_camera_sensor(mav0 / "cam0" / "sensor.yaml")
        rows0 = read_frame_csv(mav0 / "cam0" / "data.csv")
        rows1: list[FrameRow] = []
        right: CameraSensor | None = None
        if stereo:
            csv1 = mav0 / "cam1" / "data.csv"
            if not csv1.is_file():
                raise DatasetError("stereo=True needs the right camera, but its frame list is missing", csv1)
            right = read_camera_sensor(mav0 / "cam1" / "sensor.yaml")
            rows1 = read_frame_csv(csv1)
        pairs = _usable_frames(rows0, rows1, stereo, mav0)
        if not pairs:
            raise DatasetError("no frame has its image file" + (" in both cameras" if stereo else ""), mav0 / "cam0" / "data.csv")

        camera = left.camera
        meta: dict[str, Any] = {"sequence": seq_dir.name, "T_BS_cam0": _flat(left.T_BS)}
        if right is not None:
            T_lr = np.linalg.inv(left.T_BS) @ right.T_BS
            same = _same_intrinsics(left.camera, right.camera)
            camera = camera.with_stereo(T_lr, right=None if same else right.camera)
            meta["T_BS_cam1"] = _flat(right.T_BS)
        records = [
            FrameRecord(
                index=position,
                timestamp=row.ns * 1e-9,
                stem=row.file.stem,
                image=row.file,
                right=None if partner is None else partner.file,
                timestamp_ns=row.ns,
            )
            for position, row, partner in pairs
        ]
        return Sequence(
            kind=self.name,
            name=f"euroc/{seq_dir.name}",
            camera=camera,
            sensor="stereo" if stereo else "mono",
            fps=left.rate_hz,
            records=records,
            groundtruth=_groundtruth(seq_dir, left.T_BS, groundtruth, groundtruth_frame),
            grayscale=_is_single_channel(records[0].image),
            source=seq_dir,
            meta=meta,
        )

    def write(self, sequence: Sequence, out_dir: Path, frames: Iterable[Frame]) -> Path:
        """Write ``out_dir/<name>/mav0/...`` and return ``out_dir/<name>``.

        Images are PNG files named by their ns time (``FrameRecord.timestamp_ns``, else the
        rounded time in s); ``data.csv`` lists exactly the frames written. A EuRoC source keeps
        its ``T_BS`` (and ``imu0/``, ``body.yaml``); any other source gets cam0 as body frame.
        Ground truth is written as body poses in ``state_groundtruth_estimate0/data.csv``.
        """
        from_euroc = sequence.kind == self.name and "T_BS_cam0" in sequence.meta
        seq_dir = out_dir / _folder_name(sequence, from_euroc)
        mav0 = seq_dir / "mav0"
        stereo = sequence.sensor == "stereo"
        if sequence.sensor == "rgbd":
            warnings.warn(
                f"{sequence.name}: the EuRoC layout has no depth maps; writing the images only (mono)",
                DatasetWarning,
                stacklevel=3,
            )
        T_BS0, T_BS1 = _extrinsics_for(sequence, from_euroc)
        grey = sequence.grayscale
        stamps: list[int] = []
        for frame in frames:
            record = frame.record
            ns = record.time_ns
            if stamps and ns <= stamps[-1]:
                raise DatasetError(
                    f"EuRoC names frames by their time in ns, which must increase: frame {record.index} at {ns} ns follows {stamps[-1]} ns",
                    sequence.source,
                )
            stamps.append(ns)
            write_image(mav0 / "cam0" / "data" / f"{ns}.png", _sized(frame.image, sequence.camera, sequence, record), grey=grey)
            if stereo:
                right = _sized(frame.require("right"), sequence.camera.right or sequence.camera, sequence, record)
                write_image(mav0 / "cam1" / "data" / f"{ns}.png", right, grey=grey)

        cameras = [("cam0", sequence.camera, T_BS0)]
        if T_BS1 is not None:  # stereo
            cameras.append(("cam1", sequence.camera.right or sequence.camera, T_BS1))
        for cam_name, camera, T_BS in cameras:
            csv = "".join(f"{ns},{ns}.png\n" for ns in stamps)
            atomic_write_text(mav0 / cam_name / "data.csv", FRAME_CSV_HEADER + "\n" + csv)
            text = sensor_yaml(camera, T_BS, sequence.fps, f"{cam_name} of {sequence.name}, written by pytest-sal")
            atomic_write_text(mav0 / cam_name / "sensor.yaml", text)

        if sequence.groundtruth is not None:
            body = sequence.groundtruth.transformed(right=np.linalg.inv(T_BS0))
            body.write_euroc(mav0 / "state_groundtruth_estimate0" / "data.csv")
            atomic_write_text(mav0 / "state_groundtruth_estimate0" / "sensor.yaml", GT_SENSOR_YAML)
        source_mav0 = None if sequence.source is None else sequence.source / "mav0"
        if from_euroc and source_mav0 is not None:
            if (source_mav0 / "imu0").is_dir():
                copy_tree(source_mav0 / "imu0", mav0 / "imu0")  # with the umask's modes, not the source's
            if (source_mav0 / "body.yaml").is_file():
                shutil.copyfile(source_mav0 / "body.yaml", mav0 / "body.yaml")
        return seq_dir


def _usable_frames(rows0: list[FrameRow], rows1: list[FrameRow], stereo: bool, mav0: Path) -> list[tuple[int, FrameRow, FrameRow | None]]:
    """``(cam0 row position, cam0 row, cam1 row)`` of the frames whose images exist (and pair up);
    one ``DatasetWarning`` per ``data.csv`` that loses rows."""
    present0 = _present(rows0)
    if not stereo:
        _warn_dropped(mav0 / "cam0" / "data.csv", len(rows0), len(rows0) - len(present0), 0, "")
        return [(i, row, None) for i, row in enumerate(rows0) if row.ns in present0]
    present1 = _present(rows1)
    paired = present0.keys() & present1.keys()
    _warn_dropped(mav0 / "cam0" / "data.csv", len(rows0), len(rows0) - len(present0), len(present0) - len(paired), "cam1")
    _warn_dropped(mav0 / "cam1" / "data.csv", len(rows1), len(rows1) - len(present1), len(present1) - len(paired), "cam0")
    return [(i, row, present1[row.ns]) for i, row in enumerate(rows0) if row.ns in paired]


def _present(rows: list[FrameRow]) -> dict[int, FrameRow]:
    """Rows whose image file exists, by ns (one directory listing per folder)."""
    listings: dict[Path, set[str]] = {}
    out = {}
    for row in rows:
        folder = row.file.parent
        if folder not in listings:
            listings[folder] = {p.name for p in folder.iterdir()} if folder.is_dir() else set()
        if row.file.name in listings[folder]:
            out[row.ns] = row
    return out


def _warn_dropped(csv: Path, total: int, missing: int, unpaired: int, other: str) -> None:
    if not missing and not unpaired:
        return
    reasons = []
    if missing:
        reasons.append(f"{missing} name image files that do not exist")
    if unpaired:
        reasons.append(f"{unpaired} have no {other} image at the same ns timestamp")
    warnings.warn(
        f"{csv}: {missing + unpaired} of {total} rows skipped: {'; '.join(reasons)}",
        DatasetWarning,
        stacklevel=4,
    )


def _groundtruth(seq_dir: Path, T_BS0: np.ndarray, explicit: str | Path | None, frame: str | None) -> Trajectory | None:
    """Camera-0 poses from ``explicit``, ``state_groundtruth_estimate0/data.csv`` or a single
    ``groundtruth*.csv`` / ``*_GT*.csv`` in the sequence folder; ``None`` when there is none."""
    T_gt_body = np.eye(4)
    if explicit is not None:
        path = Path(explicit).expanduser()
        if not path.is_file() and not path.is_absolute() and (seq_dir / path).is_file():
            path = seq_dir / path
        if not path.is_file():
            raise DatasetError("ground-truth file not found", path)
        default = "body"
    elif (seq_dir / "mav0" / "state_groundtruth_estimate0" / "data.csv").is_file():
        gt_dir = seq_dir / "mav0" / "state_groundtruth_estimate0"
        path, default = gt_dir / "data.csv", "body"
        if (gt_dir / "sensor.yaml").is_file():
            data = read_sensor_yaml(gt_dir / "sensor.yaml")
            if "T_BS" in data:  # pose of the estimated frame in the body frame
                T_gt_body = np.linalg.inv(read_transform(data["T_BS"], gt_dir / "sensor.yaml"))
    else:
        found = sorted(p for p in seq_dir.glob("*.csv") if p.is_file() and (p.name.lower().startswith("groundtruth") or "_GT" in p.name))
        if not found:
            return None
        if len(found) > 1:
            warnings.warn(
                f"{seq_dir}: several ground-truth files ({', '.join(p.name for p in found)}); "
                "opening without ground truth (pass groundtruth=...)",
                DatasetWarning,
                stacklevel=3,
            )
            return None
        path, default = found[0], "camera"
    trajectory = Trajectory.read_euroc(path)
    if (frame or default) == "camera":
        return trajectory
    return trajectory.transformed(right=T_gt_body @ T_BS0)


def _sequence_dir(path: Path | None, sequence: str | None) -> Path:
    if path is None:
        raise DatasetError("the euroc dataset needs a path (the sequence folder holding mav0/)")
    path = Path(path)
    if not path.is_dir():
        raise DatasetError("EuRoC folder not found", path)
    if sequence is not None:
        candidate = path / str(sequence)
        if (candidate / "mav0").is_dir():
            return candidate
        if path.name == str(sequence) and (path / "mav0").is_dir():
            return path
        raise DatasetError(f"sequence {str(sequence)!r} not found (looked for {sequence}/mav0/)", path)
    if (path / "mav0").is_dir():
        return path
    if path.name == "mav0" and (path / "cam0").is_dir():
        return path.parent
    found = sorted(p.name for p in path.iterdir() if (p / "mav0").is_dir())
    if len(found) == 1:
        return path / found[0]
    if found:
        raise DatasetError(f"several EuRoC sequences found ({', '.join(found)}); pass sequence=", path)
    raise DatasetError("not a EuRoC sequence folder (no mav0/ in it or in a sub-folder)", path)


def _is_single_channel(source: Any) -> bool:
    """True when the image file stores one channel (EuRoC cameras are grey)."""
    if not isinstance(source, Path):
        return True
    return probe_image(source)[2]


def _same_intrinsics(a: Camera, b: Camera) -> bool:
    return (a.fx, a.fy, a.cx, a.cy, a.width, a.height, tuple(a.distortion)) == (
        b.fx,
        b.fy,
        b.cx,
        b.cy,
        b.width,
        b.height,
        tuple(b.distortion),
    )


def _flat(T: np.ndarray) -> list[float]:
    return [float(v) for v in np.ravel(T)]


# -- writing ---------------------------------------------------------------------------------------
def _folder_name(sequence: Sequence, from_euroc: bool) -> str:
    name = str(sequence.meta.get("sequence", "")) if from_euroc else ""
    name = name or sequence.name.replace("\\", "/").rstrip("/").rsplit("/", 1)[-1]
    name = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._")
    return name or "sequence"


def _extrinsics_for(sequence: Sequence, from_euroc: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """``T_BS`` of cam0 and cam1: a EuRoC source keeps its own (cam1 follows the camera's
    ``T_left_right``); anything else takes cam0 as the body frame."""
    T_BS0 = np.asarray(sequence.meta["T_BS_cam0"], dtype=np.float64).reshape(4, 4) if from_euroc else np.eye(4)
    T_lr = sequence.camera.T_lr
    if sequence.sensor != "stereo":
        return T_BS0, None
    if T_lr is None:
        raise DatasetError(f"{sequence.name}: a stereo sequence needs the camera's T_left_right or baseline_m to write cam1")
    if from_euroc and "T_BS_cam1" in sequence.meta:
        T_BS1 = np.asarray(sequence.meta["T_BS_cam1"], dtype=np.float64).reshape(4, 4)
        if np.array_equal(np.linalg.inv(T_BS0) @ T_BS1, T_lr):
            return T_BS0, T_BS1  # unchanged extrinsics: keep the source's exact values
    return T_BS0, T_BS0 @ T_lr


def _sized(image: np.ndarray, camera: Camera, sequence: Sequence, record: FrameRecord) -> np.ndarray:
    """``image`` after checking it has the camera's size (sensor.yaml stores one resolution)."""
    if image.shape[:2] != (camera.height, camera.width):
        raise DatasetError(
            f"{sequence.name}: frame {record.index} is {image.shape[1]}x{image.shape[0]} px but the camera "
            f"is {camera.width}x{camera.height} px"
        )
    return image


EUROC = EurocDataset()
