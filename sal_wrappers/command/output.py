"""What an external SLAM program wrote: finding its trajectory file, reading the output formats
(tum, kitti with or without times, euroc, json; see ``sal_wrappers.command.system``) and matching the
poses to the frames given (a pose within half a frame period of a frame's time tracks it)."""

from __future__ import annotations

import glob
import json
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from sal_adapters import Trajectory
from sal_adapters.common.errors import DatasetError
from sal_adapters.common.textfiles import check_size, iter_rows, read_numeric_table
from sal_adapters.trajectory import read_times
from sal_wrappers.base import TrackState

__all__ = [
    "OUTPUT_FORMATS",
    "TIME_UNITS",
    "Stamp",
    "find_output",
    "frame_states",
    "no_match_message",
    "read_output",
    "snapshot",
    "written_since",
]

OUTPUT_FORMATS = ("tum", "kitti", "euroc", "json")
#: seconds per unit of the times in the output
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
#: one file's (mtime ns, size), or None when it is gone
Stamp = tuple[int, int] | None


def read_output(path: Path, output_format: str, time_unit: str, frame_times: np.ndarray, times_path: Path | None) -> Trajectory:
    """The trajectory in ``path`` (times in s); an empty trajectory when it holds no pose.
    Raises ``DatasetError`` (file and line) or ``ValueError`` when it cannot be parsed."""
    scale = TIME_UNITS[time_unit]
    empty = Trajectory(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 4)))
    if output_format == "json":
        return _read_json(path, scale)
    if next(iter_rows(path, delimiter="," if output_format == "euroc" else None), None) is None:
        return empty
    if output_format == "tum":
        return _rescaled(Trajectory.read_tum(path), scale)
    if output_format == "euroc":
        return Trajectory.read_euroc(path)
    table, _ = read_numeric_table(path, (12, 13), what="values (3x4 pose row-major, optionally preceded by a timestamp)")
    if table.shape[1] == 13:
        return _rescaled(Trajectory.read_kitti(path), scale)
    if times_path is not None:
        stamps = read_times(times_path) * scale
        if len(stamps) != len(table):
            raise DatasetError(f"{len(table)} poses in {path.name} but {len(stamps)} times", times_path)
    elif len(table) == len(frame_times):
        stamps = frame_times
    else:
        raise DatasetError(
            f"{len(table)} poses of 12 values (no timestamps) for {len(frame_times)} frames: without times a KITTI "
            f"file must hold one pose per frame given, in order; write 13 values per line (timestamp first) or the "
            f"times to {{output_times}}",
            path,
        )
    return Trajectory.read_kitti(path, np.asarray(stamps, dtype=np.float64))


def _matches(output: Path, pattern: bool) -> list[Path]:
    if pattern:
        return [Path(p) for p in glob.glob(str(output), recursive=True) if Path(p).is_file()]
    return [output] if output.is_file() else []


def _stat(path: Path) -> Stamp:
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_mtime_ns, st.st_size


def snapshot(output: Path, pattern: bool, workdir: Path) -> dict[Path, Stamp]:
    """Files that already match ``output``: those inside ``workdir`` are removed (left from an
    earlier run there), the others remembered so that an untouched one is not taken for output."""
    before: dict[Path, Stamp] = {}
    for path in _matches(output, pattern):
        if path.resolve().is_relative_to(workdir):
            path.unlink(missing_ok=True)
        else:
            before[path] = _stat(path)
    return before


def written_since(path: Path, before: dict[Path, Stamp]) -> bool:
    return path.is_file() and (path not in before or _stat(path) != before[path])


def find_output(output: Path, pattern: bool, before: dict[Path, Stamp]) -> tuple[Path | None, str | None]:
    found = [p for p in _matches(output, pattern) if written_since(p, before)]
    if found:
        return max(found, key=lambda p: (_stat(p) or (0, 0))[0]), None
    stale = [p for p in _matches(output, pattern) if p in before]
    if stale:
        return None, f"no trajectory written: {stale[0]} is left from before this run (not modified by it)"
    what = f"no file matches {output}" if pattern else f"{output} not found"
    return None, f"no trajectory written: {what} (the program must write its trajectory there; see the output option)"


def _rescaled(trajectory: Trajectory, scale: float) -> Trajectory:
    if scale == 1.0:
        return trajectory
    return Trajectory(trajectory.timestamps * scale, trajectory.positions, trajectory.quaternions)


def _read_json(path: Path, scale: float) -> Trajectory:
    try:
        check_size(path, path.stat().st_size)  # read whole: within the limit of the other formats
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise DatasetError(f"not valid JSON ({exc.msg}, column {exc.colno})", path, exc.lineno) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"cannot read ({exc})", path) from None
    if not isinstance(data, list):
        raise DatasetError('expected a JSON list of {"t": time, "pose": 4x4 matrix or [tx, ty, tz, qx, qy, qz, qw]}', path)
    stamps, poses = [], []
    for i, entry in enumerate(data):
        where = f"entry {i}"
        if not isinstance(entry, dict) or "t" not in entry or "pose" not in entry:
            raise DatasetError(f'{where}: expected an object with keys "t" and "pose", got {json.dumps(entry)[:80]}', path)
        t = entry["t"]
        if isinstance(t, bool) or not isinstance(t, (int, float)):
            raise DatasetError(f'{where}: "t" must be a number, got {json.dumps(t)[:40]}', path)
        try:
            pose = np.asarray(entry["pose"], dtype=np.float64)
        except (TypeError, ValueError):
            raise DatasetError(f'{where}: "pose" must be a 4x4 (or 3x4) matrix or [tx, ty, tz, qx, qy, qz, qw]', path) from None
        if not np.all(np.isfinite(pose)):
            raise DatasetError(f'{where}: "pose" holds a non-finite value', path)
        matrix = np.eye(4)
        if pose.shape in ((4, 4), (3, 4)):
            det = np.linalg.det(pose[:3, :3])
            if abs(det - 1.0) > 1e-2:
                raise DatasetError(f"{where}: the rotation has determinant {det:.4f}, not 1", path)
            matrix[:3, :] = pose[:3, :]
        elif pose.shape == (7,):
            if np.linalg.norm(pose[3:]) < 1e-9:
                raise DatasetError(f"{where}: zero-length quaternion", path)
            matrix[:3, :3] = Rotation.from_quat(pose[3:]).as_matrix()
            matrix[:3, 3] = pose[:3]
        else:
            raise DatasetError(f'{where}: "pose" has shape {pose.shape}; expected 4x4, 3x4 or 7 values [tx, ty, tz, qx, qy, qz, qw]', path)
        stamps.append(float(t) * scale)
        poses.append(matrix)
    if not poses:
        return Trajectory(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 4)))
    return Trajectory.from_matrices(np.asarray(stamps), np.asarray(poses))


def frame_states(frame_times: np.ndarray, fps: float, trajectory: Trajectory, keyframes: bool) -> tuple[np.ndarray, Trajectory | None]:
    """Per-frame states and the poses matched to frames (at the frames' times)."""
    n = len(frame_times)
    states = np.full(n, TrackState.NOT_INITIALISED, dtype=np.int8)
    if not len(trajectory) or not n:
        return states, None
    order = np.argsort(trajectory.timestamps, kind="stable")
    pose_t = trajectory.timestamps[order]
    right = np.clip(np.searchsorted(pose_t, frame_times), 0, len(pose_t) - 1)
    left = np.clip(right - 1, 0, len(pose_t) - 1)
    nearest = np.where(np.abs(pose_t[left] - frame_times) <= np.abs(pose_t[right] - frame_times), left, right)
    matched = np.abs(pose_t[nearest] - frame_times) < 0.5 / fps
    if not matched.any():
        return states, None
    tracked = matched.copy()
    if keyframes:
        hits = np.flatnonzero(matched)
        tracked[hits[0] : hits[-1] + 1] = True
    first = int(np.flatnonzero(tracked)[0])
    states[first:] = TrackState.LOST
    states[tracked] = TrackState.OK
    idx = order[nearest[matched]]
    scored = Trajectory(frame_times[matched], trajectory.positions[idx], trajectory.quaternions[idx])
    return states, scored


def no_match_message(path: Path | None, frame_times: np.ndarray, fps: float, trajectory: Trajectory, unit: str) -> str:
    if not len(trajectory):
        return f"no pose in the trajectory: {path} holds none (nothing tracked)"
    t = trajectory.timestamps
    return (
        f"none of the {len(t)} poses in {path} is within half a frame period ({500.0 / fps:.3g} ms) of a frame time: "
        f"poses at {t.min():.6f}..{t.max():.6f} s, frames at {frame_times.min():.6f}..{frame_times.max():.6f} s "
        f"(output read with time_unit={unit!r}; is it right?)"
    )
