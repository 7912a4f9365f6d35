"""Timestamped 6-DoF trajectories and their file formats (TUM, KITTI, EuRoC CSV).

Poses are camera-to-world (``T_wc``): ``p_world = R @ p_cam + t``. Quaternions are stored
``x y z w`` as in TUM files; evo uses ``w x y z``, which ``to_evo``/``from_evo`` convert.
Trajectories are immutable: every operation returns a new one, arrays are read-only.
"""

from __future__ import annotations

from array import array
from collections.abc import Sequence as SequenceABC
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from sal_adapters.common.errors import DatasetError
from sal_adapters.common.textfiles import (
    atomic_write_text,
    check_times,
    format_float,
    iter_rows,
    read_numeric_table,
)

if TYPE_CHECKING:
    from evo.core.trajectory import PoseTrajectory3D

__all__ = ["Trajectory"]

EUROC_HEADER = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []"


@dataclass(frozen=True, eq=False)
class Trajectory:
    """``N`` poses: timestamps (s, float64), positions (m, Nx3), quaternions (Nx4, x y z w)."""

    timestamps: np.ndarray
    positions: np.ndarray
    quaternions: np.ndarray

    def __post_init__(self) -> None:
        t = np.array(self.timestamps, dtype=np.float64).reshape(-1)
        p = np.array(self.positions, dtype=np.float64).reshape(-1, 3)
        q = np.array(self.quaternions, dtype=np.float64).reshape(-1, 4)
        if not len(t) == len(p) == len(q):
            raise ValueError(f"trajectory arrays differ in length: {len(t)} timestamps, {len(p)} positions, {len(q)} quaternions")
        with np.errstate(over="ignore"):  # a norm too large for a float is refused below
            norms = np.linalg.norm(q, axis=1, keepdims=True)
        if np.any(norms < 1e-9) or not np.all(np.isfinite(norms)) or not np.all(np.isfinite(q)) or not np.all(np.isfinite(p)):
            raise ValueError("trajectory holds a zero-length or non-finite quaternion or position")
        q = q / norms
        for name, arr in (("timestamps", t), ("positions", p), ("quaternions", q)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    def __len__(self) -> int:
        return len(self.timestamps)

    def __repr__(self) -> str:
        span = f"{self.timestamps[0]:.3f}..{self.timestamps[-1]:.3f} s" if len(self) else "empty"
        return f"Trajectory({len(self)} poses, {span}, path {self.path_length():.2f} m)"

    # -- construction and conversion -------------------------------------------------------
    @classmethod
    def from_matrices(cls, timestamps: np.ndarray, poses: np.ndarray) -> Trajectory:
        """Build from ``N`` homogeneous 4x4 (or 3x4) camera-to-world matrices."""
        poses = np.asarray(poses, dtype=np.float64)
        if poses.ndim != 3 or poses.shape[1:] not in ((4, 4), (3, 4)):
            raise ValueError(f"poses must be Nx4x4 or Nx3x4, got shape {poses.shape}")
        rotations = _orthonormalize(poses[:, :3, :3])
        quats = Rotation.from_matrix(rotations).as_quat() if len(poses) else np.zeros((0, 4))
        return cls(timestamps, poses[:, :3, 3], quats)

    @property
    def matrices(self) -> np.ndarray:
        """``N`` camera-to-world 4x4 matrices."""
        out = np.tile(np.eye(4), (len(self), 1, 1))
        if len(self):
            out[:, :3, :3] = Rotation.from_quat(self.quaternions).as_matrix()
        out[:, :3, 3] = self.positions
        return out

    def to_evo(self) -> PoseTrajectory3D:
        """A new evo ``PoseTrajectory3D`` (evo aligns in place: this one is never shared)."""
        from evo.core.trajectory import PoseTrajectory3D

        return PoseTrajectory3D(
            positions_xyz=self.positions.copy(),
            orientations_quat_wxyz=self.quaternions[:, [3, 0, 1, 2]].copy(),
            timestamps=self.timestamps.copy(),
        )

    @classmethod
    def from_evo(cls, traj: PoseTrajectory3D) -> Trajectory:
        """Convert an evo ``PoseTrajectory3D``."""
        return cls(traj.timestamps, traj.positions_xyz, traj.orientations_quat_wxyz[:, [1, 2, 3, 0]])

    # -- operations --------------------------------------------------------------------------
    def select(self, indices: SequenceABC[int] | np.ndarray) -> Trajectory:
        """Poses at ``indices`` (integer positions or a boolean mask)."""
        return Trajectory(self.timestamps[indices], self.positions[indices], self.quaternions[indices])

    def crop(self, t_start: float, t_end: float) -> Trajectory:
        """Poses with ``t_start <= t <= t_end`` (s)."""
        return self.select((self.timestamps >= t_start) & (self.timestamps <= t_end))

    def transformed(self, left: np.ndarray | None = None, right: np.ndarray | None = None) -> Trajectory:
        """Every pose ``T`` replaced by ``left @ T @ right`` (change of world or of body frame)."""
        poses = self.matrices
        if left is not None:
            poses = np.asarray(left, dtype=np.float64) @ poses
        if right is not None:
            poses = poses @ np.asarray(right, dtype=np.float64)
        return Trajectory.from_matrices(self.timestamps, poses)

    def path_length(self) -> float:
        """Length of the path through the positions (m)."""
        if len(self) < 2:
            return 0.0
        return float(np.linalg.norm(np.diff(self.positions, axis=0), axis=1).sum())

    def allclose(self, other: Trajectory, atol: float = 1e-9) -> bool:
        """Same length, timestamps, positions and rotations (``q`` and ``-q`` are equal)."""
        if len(self) != len(other):
            return False
        same_sign = np.abs(np.sum(self.quaternions * other.quaternions, axis=1))
        return (
            np.allclose(self.timestamps, other.timestamps, rtol=0, atol=max(atol, 1e-6))
            and np.allclose(self.positions, other.positions, rtol=0, atol=atol)
            and np.allclose(same_sign, 1.0, rtol=0, atol=max(atol, 1e-12) * 10)
        )

    # -- TUM -----------------------------------------------------------------------------------
    @classmethod
    def read_tum(cls, path: str | Path) -> Trajectory:
        """Read ``timestamp tx ty tz qx qy qz qw`` lines (comments ``#`` skipped)."""
        table, _ = read_numeric_table(Path(path), 8, what="values (timestamp tx ty tz qx qy qz qw)")
        return _checked(cls, table[:, 0], table[:, 1:4], table[:, 4:8], path)

    def write_tum(self, path: str | Path) -> None:
        """Write in TUM format, with timestamps that read back exactly."""
        lines = ["# timestamp tx ty tz qx qy qz qw"]
        for t, p, q in zip(self.timestamps, self.positions, self.quaternions):
            lines.append(" ".join([format_float(t), *(format_float(v) for v in p), *(format_float(v) for v in q)]))
        atomic_write_text(Path(path), "\n".join(lines) + "\n")

    # -- KITTI ---------------------------------------------------------------------------------
    @classmethod
    def read_kitti(cls, path: str | Path, times: str | Path | np.ndarray | None = None) -> Trajectory:
        """Read KITTI poses: 12 values per line (3x4 row-major), or 13 with a leading timestamp.

        ``times`` is a ``times.txt`` path or an array (s); without it, 12-column files get
        the frame index as timestamp.
        """
        path = Path(path)
        table, _ = read_numeric_table(path, (12, 13), what="values (3x4 pose row-major, optionally preceded by a timestamp)")
        if table.shape[1] == 13:
            stamps, table = table[:, 0], table[:, 1:]
        elif times is None:
            stamps = np.arange(len(table), dtype=np.float64)
        else:
            stamps = read_times(times) if not isinstance(times, np.ndarray) else np.asarray(times, dtype=np.float64)
        if len(stamps) != len(table):
            raise DatasetError(f"{len(table)} poses but {len(stamps)} timestamps", path)
        poses = table.reshape(-1, 3, 4)
        return _checked_matrices(cls, stamps, poses, path)

    def write_kitti(self, path: str | Path, times_path: str | Path | None = None) -> None:
        """Write 12 values per line; with ``times_path``, also a ``times.txt`` beside it."""
        rows = self.matrices[:, :3, :].reshape(len(self), 12)
        atomic_write_text(Path(path), "".join(" ".join(f"{v:.12e}" for v in row) + "\n" for row in rows))
        if times_path is not None:
            write_times(times_path, self.timestamps)

    # -- EuRoC ---------------------------------------------------------------------------------
    @classmethod
    def read_euroc(cls, path: str | Path) -> Trajectory:
        """Read an EuRoC ground-truth CSV: ``ns, px, py, pz, qw, qx, qy, qz[, ...]``."""
        path = Path(path)
        stamps, values = array("d"), array("d")
        width = None
        for number, fields in iter_rows(path, delimiter=","):
            if len(fields) < 8 or (width is not None and len(fields) != width):
                raise DatasetError(
                    f"expected {width or 'at least 8'} comma-separated values (timestamp [ns], p_x p_y p_z [m], q_w q_x q_y q_z), got {len(fields)}",
                    path,
                    number,
                )
            width = len(fields)
            try:
                stamps.append(parse_ns(fields[0]) * 1e-9)
                values.extend([float(v) for v in fields[1:8]])
            except ValueError as exc:
                raise DatasetError(f"expected numbers ({exc})", path, number) from None
        if not values:
            raise DatasetError("no poses found", path)
        table = np.frombuffer(values, dtype=np.float64).reshape(-1, 7)
        return _checked(cls, np.frombuffer(stamps, dtype=np.float64), table[:, 0:3], table[:, [4, 5, 6, 3]], path)

    def write_euroc(self, path: str | Path) -> None:
        """Write an EuRoC CSV with integer nanosecond timestamps."""
        lines = [EUROC_HEADER]
        for t, p, q in zip(self.timestamps, self.positions, self.quaternions):
            values = [*p, q[3], q[0], q[1], q[2]]
            lines.append(",".join([str(seconds_to_ns(t)), *(format_float(v) for v in values)]))
        atomic_write_text(Path(path), "\n".join(lines) + "\n")


def parse_ns(text: str) -> int:
    """Integer nanoseconds from ``"1403715274312143104"`` or ``"1403715274312143104.000"``."""
    whole, _, fraction = text.strip().partition(".")
    if not whole.lstrip("-").isdigit() or (fraction and not fraction.isdigit()):
        raise ValueError(f"{text!r} is not a timestamp in ns")
    return int(whole)


def seconds_to_ns(seconds: float) -> int:
    """Nearest integer nanosecond of a float64 time in seconds."""
    return int(round(float(seconds) * 1e9))


def read_times(source: str | Path) -> np.ndarray:
    """Read a KITTI-style ``times.txt``: one time in seconds per line, finite and increasing
    (``check_times``)."""
    table, lines = read_numeric_table(Path(source), 1, what="number (time in seconds)")
    check_times(zip(lines, table[:, 0].tolist()), Path(source))
    return table[:, 0]


def write_times(path: str | Path, stamps: np.ndarray) -> None:
    """Write one time in seconds per line, reading back exactly."""
    atomic_write_text(Path(path), "".join(format_float(t) + "\n" for t in stamps))


def _orthonormalize(rotations: np.ndarray) -> np.ndarray:
    """Nearest rotation matrices (SVD), for slightly non-orthogonal file values."""
    u, _, vt = np.linalg.svd(rotations)
    r = u @ vt
    flip = np.linalg.det(r) < 0
    if np.any(flip):
        u[flip, :, -1] *= -1
        r = u @ vt
    return r


def _checked(cls: type[Trajectory], t: np.ndarray, p: np.ndarray, q: np.ndarray, path: str | Path) -> Trajectory:
    try:
        return cls(t, p, q)
    except ValueError as exc:
        raise DatasetError(str(exc), path) from None


def _checked_matrices(cls: type[Trajectory], t: np.ndarray, poses: np.ndarray, path: str | Path) -> Trajectory:
    if not np.all(np.isfinite(poses)):
        raise DatasetError("pose holds a non-finite value", path)
    det = np.linalg.det(poses[:, :3, :3])
    bad = np.flatnonzero(np.abs(det - 1.0) > 1e-2)
    if len(bad):
        raise DatasetError(f"pose {bad[0]} has a rotation with determinant {det[bad[0]]:.4f}, not 1", path)
    return cls.from_matrices(t, poses)
