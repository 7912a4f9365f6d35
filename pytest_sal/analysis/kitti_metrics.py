"""KITTI's own odometry metric: ``t_rel`` (%) and ``r_rel`` (deg/100 m) over sub-sequences of a
fixed path length, as the KITTI odometry devkit (``evaluate_odometry.cpp``) defines them.

* ``dist[i]`` (m): the reference's path length up to frame ``i``, ``dist[0] = 0``
  (``trajectoryDistances``);
* a segment starts at every ``step``-th frame ``f`` (10: one second at KITTI's 10 Hz) and, for
  each length ``L`` (m), ends at the first frame ``l`` with ``dist[l] > dist[f] + L``; a start
  with no such frame has no segment of that length (``lastFrameFromSegmentLength``);
* ``E = (P_f^-1 P_l)^-1 (Q_f^-1 Q_l)`` (``Q`` reference, ``P`` estimate), ``t_err = |t(E)| / L``
  (m/m) and ``r_err = angle(R(E)) / L`` (rad/m), the angle being
  ``acos(clamp((trace R(E) - 1) / 2, -1, 1))`` (``calcSequenceErrors``, ``translationError``,
  ``rotationError``; computed here with scipy's rotation magnitude, the same angle without
  acos's loss of precision near 0);
* ``t_rel = 100 * mean(t_err)`` (%) and ``r_rel = mean(r_err) * 180 / pi * 100`` (deg/100 m),
  the means over every segment of every length.

Where pytest-sal has to go beyond the devkit:

* **frames** are the reference's poses, in its order (KITTI's ground truth has one per frame);
  the estimate is paired with them by timestamp (``trajectory_errors.associate``);
* **tracking lost**: the devkit needs a pose in every frame. A segment whose first or last
  frame has no estimated pose is skipped; when none is left the metric is ``None`` with a reason;
* **short sequences**: the devkit's 100 .. 800 m give no segment on a short excerpt (KITTI 07's
  first 140 frames are 78 m). The lengths are an option (``segments_m``); a reference shorter
  than the shortest length gives ``None`` with a reason, never 0;
* **scale**: the devkit assumes a metric estimate. The estimate is first aligned like the ATE's
  (``align``): ``sim3`` (monocular, whose scale is unobservable) also corrects its scale with
  the Umeyama ``s``; a rigid ``se3`` alignment changes no relative pose, so stereo and RGB-D
  estimates are scored as the devkit scores them.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from pytest_sal.analysis.kitti_segments import KITTI_SEGMENTS_M, KITTI_STEP, parse_segments, segment_lengths
from pytest_sal.analysis.trajectory_errors import Align, AteResult, ate, relative_errors
from sal_adapters.common.errors import SalError
from sal_adapters.trajectory import Trajectory

__all__ = [
    "KITTI_SEGMENTS_M",
    "KITTI_STEP",
    "KittiResult",
    "kitti_errors",
    "kitti_from_ate",
    "kitti_odometry",
    "parse_segments",
    "segment_lengths",
    "segments",
    "trajectory_distances",
]


@dataclass(frozen=True, eq=False)
class KittiResult:
    """Errors of the KITTI segments; ``t_rel`` / ``r_rel`` are ``None`` (``reason`` says why)
    when no segment could be scored.

    ``t_rel`` (%) ``= 100 * mean(t_errors)``, ``r_rel`` (deg/100 m) ``= 18000 / pi *
    mean(r_errors)``; ``count`` segments of the lengths ``segments_m`` (m). Per segment:
    ``first`` / ``last`` frame (index into the reference), ``length`` (m), ``t_errors`` (m/m)
    and ``r_errors`` (rad/m). ``skipped``: segments left out because an end had no estimate.
    """

    t_rel: float | None
    r_rel: float | None
    count: int
    skipped: int
    segments_m: tuple[float, ...]
    reason: str | None = None
    first: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int), repr=False)
    last: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int), repr=False)
    length: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    t_errors: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    r_errors: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)


def trajectory_distances(positions: np.ndarray) -> np.ndarray:
    """``dist[i] = sum_{k<=i} |p_k - p_(k-1)|`` (m), ``dist[0] = 0`` (the devkit's ``trajectoryDistances``)."""
    steps = np.linalg.norm(np.diff(np.asarray(positions, dtype=np.float64), axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)])


def segments(dist: np.ndarray, lengths_m: Iterable[float], step: int = KITTI_STEP) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every devkit segment ``(first, last, length)``: ``first`` every ``step`` frames, ``last``
    the first frame with ``dist[last] > dist[first] + length``; starts without one are dropped."""
    lengths = np.asarray(segment_lengths(lengths_m))
    starts = np.arange(0, len(dist), int(step))
    ends = np.searchsorted(dist, dist[starts, None] + lengths[None, :], side="right")
    first, which = np.nonzero(ends < len(dist))
    return starts[first], ends[first, which], lengths[which]


def kitti_errors(
    reference: np.ndarray,
    estimate: np.ndarray,
    tracked: np.ndarray | None = None,
    *,
    segments_m: Iterable[float] = KITTI_SEGMENTS_M,
    step: int = KITTI_STEP,
) -> KittiResult:
    """The devkit's errors of ``estimate`` (``N`` 4x4 poses, in the reference's world and scale)
    against ``reference`` (``N`` 4x4 poses, one per frame); ``tracked`` (``N`` booleans, default
    all) marks the frames that have an estimate. See the module docstring."""
    lengths = segment_lengths(segments_m)
    reference, estimate = np.asarray(reference, dtype=np.float64), np.asarray(estimate, dtype=np.float64)
    if estimate.shape != reference.shape or reference.ndim != 3 or reference.shape[1:] != (4, 4):
        raise SalError(f"KITTI errors need two stacks of N 4x4 poses, got shapes {reference.shape} and {estimate.shape}")
    tracked = np.ones(len(reference), dtype=bool) if tracked is None else np.asarray(tracked, dtype=bool)
    dist = trajectory_distances(reference[:, :3, 3])
    first, last, length = segments(dist, lengths, step)
    if not len(first):
        reason = (
            f"the reference path is {dist[-1] if len(dist) else 0.0:.1f} m, too short for a segment of {lengths[0]:g} m "
            f"(KITTI segment lengths {', '.join(f'{v:g}' for v in lengths)} m)"
        )
        return KittiResult(None, None, 0, 0, lengths, reason)
    keep = tracked[first] & tracked[last]
    skipped = int(np.count_nonzero(~keep))
    first, last, length = first[keep], last[keep], length[keep]
    if not len(first):
        reason = f"none of the {skipped} KITTI segment(s) has an estimated pose at both ends (tracking lost)"
        return KittiResult(None, None, 0, skipped, lengths, reason)
    trans, rot_deg = relative_errors(reference, estimate, np.column_stack([first, last]))
    t_err, r_err = trans / length, np.radians(rot_deg) / length
    return KittiResult(
        t_rel=float(100.0 * t_err.mean()),
        r_rel=float(np.degrees(r_err.mean()) * 100.0),
        count=len(first),
        skipped=skipped,
        segments_m=lengths,
        first=first,
        last=last,
        length=length,
        t_errors=t_err,
        r_errors=r_err,
    )


def kitti_from_ate(
    absolute: AteResult, reference: Trajectory, *, segments_m: Iterable[float] = KITTI_SEGMENTS_M, step: int = KITTI_STEP
) -> KittiResult:
    """KITTI errors of an ATE's aligned estimate (``absolute.estimate``, paired by timestamp with
    ``absolute.reference``) on the frames of the whole ``reference``; frames the estimate has no
    pose for are untracked (see ``kitti_errors``)."""
    order = np.argsort(reference.timestamps, kind="stable")
    at = np.clip(np.searchsorted(reference.timestamps[order], absolute.reference.timestamps), 0, len(order) - 1)
    frames = order[at]
    if not np.array_equal(reference.timestamps[frames], absolute.reference.timestamps):
        raise SalError("KITTI errors: the ATE was computed against another reference trajectory")
    poses = reference.matrices
    estimate = poses.copy()  # untracked frames keep the reference pose; they are never scored
    estimate[frames] = absolute.estimate.matrices
    tracked = np.zeros(len(reference), dtype=bool)
    tracked[frames] = True
    return kitti_errors(poses, estimate, tracked, segments_m=segments_m, step=step)


def kitti_odometry(
    estimate: Trajectory,
    reference: Trajectory,
    *,
    segments_m: Iterable[float] = KITTI_SEGMENTS_M,
    align: Align = "se3",
    max_diff: float | None = None,
    fps: float | None = None,
    step: int = KITTI_STEP,
) -> KittiResult:
    """``t_rel`` (%) and ``r_rel`` (deg/100 m) of ``estimate`` against ``reference``: paired and
    aligned as ``trajectory_errors.ate`` does (``sim3`` for a monocular estimate), then ``kitti_from_ate``."""
    return kitti_from_ate(ate(estimate, reference, align=align, max_diff=max_diff, fps=fps), reference, segments_m=segments_m, step=step)
