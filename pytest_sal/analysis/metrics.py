"""Metrics of SLAM runs: ``evaluate`` scores one ``RunResult`` against the ground truth
(ATE, RPE, scale error from ``pytest_sal.analysis.trajectory_errors``, KITTI's ``t_rel`` /
``r_rel`` from ``pytest_sal.analysis.kitti_metrics``, tracking figures from the run itself)
into a ``RunMetrics``; ``aggregate`` (``pytest_sal.analysis.aggregation``, exported here too)
summarises many runs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from pytest_sal.analysis.aggregation import AGGREGATED, aggregate
from pytest_sal.analysis.kitti_metrics import kitti_from_ate
from pytest_sal.analysis.kitti_segments import KITTI_SEGMENTS_M, segment_lengths
from pytest_sal.analysis.trajectory_errors import MIN_POSES, Align, AteResult, RpeResult, RpeUnit, ate, rpe, scale_error
from sal_adapters.common.errors import SalError
from sal_adapters.trajectory import Trajectory
from sal_wrappers.base import WRITTEN_BEFORE_FAILURE, RunResult

__all__ = ["AGGREGATED", "MAX_POSITION_M", "RunMetrics", "aggregate", "evaluate"]


@dataclass(frozen=True, eq=False)
class RunMetrics:
    """Metrics of one ``RunResult``; ``None`` where a value could not be computed.

    ``ate_rmse`` (m), ``rpe_trans`` / ``rpe_rot`` (RMSE of ``RpeResult`` ratios, per
    ``rpe_delta`` ``rpe_unit``), ``scale`` (Sim(3) scale, when aligned with ``sim3``) and
    ``scale_error`` (``|1 - s|``, monocular runs only: how far the map's arbitrary initial
    scale is from metric, see ``scale_error``) need ground truth and at least
    ``MIN_POSES`` tracked poses. ``failure`` says why a run failed (the system's own reason,
    too few poses, nothing associated); a run that wrote its trajectory before it crashed has
    both its accuracy values and its ``failure``. ``ate`` keeps the full ATE for plots.

    ``t_rel`` (%) and ``r_rel`` (deg/100 m) are KITTI's odometry errors
    (``pytest_sal.analysis.kitti_metrics``) over ``kitti_segments`` segments of the lengths
    ``kitti_segments_m`` (m), on the estimate aligned as for the ATE; ``kitti_missing`` says
    why they are ``None`` when the run was scored (path shorter than the shortest segment,
    no segment with an estimate at both ends).
    """

    system: str
    sequence: str
    sensor: str
    scored: str
    align: str
    frames: int
    tracked: int
    tracking_rate: float
    first_tracked: int | None
    maps: int
    matched: int = 0
    ate_rmse: float | None = None
    rpe_trans: float | None = None
    rpe_rot: float | None = None
    t_rel: float | None = None
    r_rel: float | None = None
    kitti_segments_m: tuple[float, ...] = ()
    kitti_segments: int = 0
    kitti_missing: str | None = None
    rpe_delta: float = 1.0
    rpe_unit: str = "m"
    scale: float | None = None
    scale_error: float | None = None
    has_groundtruth: bool = False
    failure: str | None = None
    ate: AteResult | None = field(default=None, repr=False)

    @property
    def ok(self) -> bool:
        return self.failure is None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (without ``ate``)."""
        return {name: getattr(self, name) for name in self.__dataclass_fields__ if name != "ate"}


#: a pose farther than this from the origin (m) is no SLAM estimate of a recorded drive: the run is not scored
MAX_POSITION_M = 1e6


def evaluate(
    result: RunResult,
    groundtruth: Trajectory | None,
    *,
    align: Align | None = None,
    rpe_delta: float = 1.0,
    rpe_unit: RpeUnit = "m",
    max_diff: float | None = None,
    kitti_segments: Sequence[float] | None = None,
) -> RunMetrics:
    """Score ``result.trajectory`` against ``groundtruth``; never raises for a failed run.

    ``align`` defaults to ``sim3`` for a ``mono`` run and ``se3`` otherwise; the association
    tolerance follows the frame rate of ``result.timestamps``. A run that failed, whose
    scored trajectory has fewer than ``MIN_POSES`` poses or that does not associate with the
    ground truth gets ``failure`` set and no accuracy values; RPE is ``None`` (and ATE kept)
    when the trajectory is shorter than ``rpe_delta``. A run whose system wrote its trajectory
    before it failed (``info["written_before_failure"]``: a program that crashed at shutdown) is
    scored all the same and keeps ``failure``: the requirement judges its metrics.
    ``kitti_segments`` (m, default the devkit's 100 .. 800) are the segment lengths of
    ``t_rel`` / ``r_rel``, computed on the ATE's aligned estimate (see ``RunMetrics``).
    """
    lengths = segment_lengths(KITTI_SEGMENTS_M if kitti_segments is None else kitti_segments)
    align = align or ("sim3" if result.sensor == "mono" else "se3")
    unscored = _unscored(result, align, float(rpe_delta), rpe_unit, lengths, groundtruth is not None)
    trajectory = result.trajectory
    poses = 0 if trajectory is None else len(trajectory)
    if result.failure is not None and not (result.info.get(WRITTEN_BEFORE_FAILURE) and poses >= MIN_POSES):
        return replace(unscored, failure=result.failure)
    if trajectory is None or poses < MIN_POSES:
        return replace(unscored, failure=f"{poses} pose(s) in the scored trajectory: too few to score (need {MIN_POSES})")
    if groundtruth is None:
        return replace(unscored, failure=result.failure)
    far = int((~(np.abs(trajectory.positions) <= MAX_POSITION_M).all(axis=1)).sum())  # nan and inf too, without overflow
    if far:
        return replace(
            unscored, failure=f"not scored: {far} of {poses} poses lie beyond {MAX_POSITION_M:g} m from the origin or are not finite"
        )
    fps = _frame_rate(result.timestamps)
    try:
        absolute = ate(trajectory, groundtruth, align=align, max_diff=max_diff, fps=fps)
    except (SalError, np.linalg.LinAlgError) as exc:  # an alignment whose SVD does not converge, too
        return replace(unscored, failure=f"not scored: {exc}")
    relative: RpeResult | None
    try:
        relative = rpe(trajectory, groundtruth, delta=rpe_delta, unit=rpe_unit, align=align, max_diff=max_diff, fps=fps)
    except SalError:
        relative = None  # too short for rpe_delta: ATE still stands
    scale = absolute.scale if align == "sim3" else None
    mono_scale_error = None
    if result.sensor == "mono":
        mono_scale_error = abs(1.0 - scale) if scale is not None else scale_error(trajectory, groundtruth, max_diff=absolute.max_diff)
    kitti = kitti_from_ate(absolute, groundtruth, segments_m=lengths)
    return replace(
        unscored,
        matched=absolute.matched,
        ate_rmse=absolute.rmse,
        rpe_trans=None if relative is None else relative.trans.rmse,
        rpe_rot=None if relative is None else relative.rot.rmse,
        t_rel=kitti.t_rel,
        r_rel=kitti.r_rel,
        kitti_segments=kitti.count,
        kitti_missing=kitti.reason,
        scale=scale,
        scale_error=mono_scale_error,
        failure=result.failure,
        ate=absolute,
    )


def _unscored(
    result: RunResult, align: Align, rpe_delta: float, rpe_unit: RpeUnit, lengths: tuple[float, ...], has_groundtruth: bool
) -> RunMetrics:
    """The metrics of ``result`` that need no scoring: what it ran and tracked, and how it will be scored."""
    return RunMetrics(
        system=result.system,
        sequence=result.sequence,
        sensor=result.sensor,
        scored=result.scored,
        align=align,
        frames=result.frames,
        tracked=result.tracked,
        tracking_rate=result.tracking_rate,
        first_tracked=result.first_tracked,
        maps=result.maps,
        rpe_delta=rpe_delta,
        rpe_unit=rpe_unit,
        kitti_segments_m=lengths,
        has_groundtruth=has_groundtruth,
    )


def _frame_rate(stamps: np.ndarray) -> float | None:
    """Frames per second from the median time step of the frames given (``None`` if unknown)."""
    step = float(np.median(np.diff(stamps))) if len(stamps) > 1 else 0.0
    return 1.0 / step if step > 0 else None
