"""Trajectory errors of an estimate against a reference: association by timestamp, ATE, RPE and
the monocular scale error (the per-run metrics built on them are in ``pytest_sal.analysis.metrics``,
KITTI's ``t_rel`` / ``r_rel`` in ``pytest_sal.analysis.kitti_metrics``).

The numbers are evo's (``evo.main_ape.ape`` / ``evo.main_rpe.rpe``), so they agree with the
``evo_ape`` / ``evo_rpe`` command line. evo aligns its estimate *in place*: every function here
hands evo fresh copies (``Trajectory.to_evo``), so the caller's trajectories never change.

Alignment (Umeyama) of the estimate onto the reference: ``"se3"`` (rotation + translation,
for stereo / RGB-D / inertial), ``"sim3"`` (also a scale ``s``, for monocular, whose scale is
unobservable) or ``"none"``.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any, Literal, NamedTuple, get_args

import numpy as np
from scipy.spatial.transform import Rotation

from sal_adapters.common.errors import SalError
from sal_adapters.trajectory import Trajectory

__all__ = [
    "MIN_POSES",
    "Align",
    "Association",
    "AteResult",
    "ErrorStats",
    "RpeResult",
    "RpeUnit",
    "associate",
    "ate",
    "default_max_diff",
    "relative_errors",
    "rpe",
    "scale_error",
]

Align = Literal["se3", "sim3", "none"]
RpeUnit = Literal["m", "s", "frames"]

#: fewest associated poses a trajectory is scored on (Umeyama needs 3)
MIN_POSES = 3
#: smallest default association tolerance (s), evo's own default
MIN_MAX_DIFF = 0.01


class Association(NamedTuple):
    """Poses of ``estimate`` and ``reference`` paired by timestamp (same length, same order)."""

    estimate: Trajectory
    reference: Trajectory
    max_diff: float  #: tolerance used (s): paired timestamps differ by at most this


@dataclass(frozen=True)
class ErrorStats:
    """Summary of errors ``e_i``: ``rmse = sqrt(mean(e_i^2))``, ``std`` is the population one."""

    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float

    @classmethod
    def of(cls, errors: np.ndarray) -> ErrorStats:
        e = np.asarray(errors, dtype=np.float64)
        return cls(
            rmse=float(np.sqrt(np.mean(e**2))),
            mean=float(np.mean(e)),
            median=float(np.median(e)),
            std=float(np.std(e)),
            min=float(np.min(e)),
            max=float(np.max(e)),
        )


@dataclass(frozen=True, eq=False)
class AteResult:
    """Absolute trajectory error: ``e_i = |p_ref,i - (s R p_est,i + t)|`` (m) after alignment.

    ``scale`` is the Sim(3) ``s`` (estimate -> reference; 1.0 for ``se3`` / ``none``);
    ``timestamps`` (s) and ``errors`` (m) are per associated pose; ``estimate`` is the aligned
    estimate and ``reference`` the reference poses paired with it.
    """

    rmse: float
    mean: float
    median: float
    max: float
    min: float
    std: float
    scale: float
    matched: int
    align: str
    max_diff: float
    timestamps: np.ndarray = field(repr=False)
    errors: np.ndarray = field(repr=False)
    estimate: Trajectory = field(repr=False)
    reference: Trajectory = field(repr=False)


@dataclass(frozen=True, eq=False)
class RpeResult:
    """Relative pose error over consecutive pose pairs ``(i, j)`` about ``delta`` apart.

    For each pair, ``E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)`` (``Q`` reference, ``P`` aligned
    estimate); ``trans_errors = |t(E)| / delta`` and ``rot_errors = angle(R(E)) / delta``
    (degrees). Units: ``m/m`` and ``deg/m`` for ``unit="m"`` (drift per metre travelled),
    ``m/s`` and ``deg/s`` for ``"s"``, per frame for ``"frames"``. ``timestamps`` are those
    of each pair's second pose (s).
    """

    trans: ErrorStats
    rot: ErrorStats
    delta: float
    unit: str
    pairs: int
    align: str
    scale: float
    max_diff: float
    timestamps: np.ndarray = field(repr=False)
    trans_errors: np.ndarray = field(repr=False)
    rot_errors: np.ndarray = field(repr=False)


# -- association ----------------------------------------------------------------------------
def associate(estimate: Trajectory, reference: Trajectory, max_diff: float | None = None, fps: float | None = None) -> Association:
    """Pair poses by nearest timestamp (evo ``sync.associate_trajectories``, nearest time).

    Tolerance ``max_diff`` (s), unless given: half a frame period, never below 0.01 s. The
    period is ``1 / fps`` or, without ``fps``, the smaller median time step of the two
    trajectories. Raises ``SalError`` naming both time ranges when no pose pairs up.
    """
    from evo.core import sync

    max_diff = default_max_diff(estimate, reference, fps) if max_diff is None else float(max_diff)
    if len(estimate) and len(reference):
        try:
            ref, est = sync.associate_trajectories(reference.to_evo(), estimate.to_evo(), max_diff=max_diff)
            return Association(Trajectory.from_evo(est), Trajectory.from_evo(ref), max_diff)
        except sync.SyncException:
            pass
    raise SalError(
        f"no estimate pose is within {max_diff:g} s of a reference pose: estimate {_span(estimate)}, reference {_span(reference)}"
    )


def default_max_diff(estimate: Trajectory, reference: Trajectory, fps: float | None = None) -> float:
    """Half a frame period (s), at least ``MIN_MAX_DIFF``; see ``associate``."""
    if fps is not None:
        if fps <= 0:
            raise SalError(f"frame rate must be positive, got {fps}")
        return max(MIN_MAX_DIFF, 0.5 / fps)
    steps = [np.median(np.diff(t.timestamps)) for t in (estimate, reference) if len(t) > 1]
    steps = [float(s) for s in steps if s > 0]
    return max(MIN_MAX_DIFF, 0.5 * min(steps)) if steps else MIN_MAX_DIFF


# -- ATE, RPE, scale --------------------------------------------------------------------------
def ate(
    estimate: Trajectory,
    reference: Trajectory,
    *,
    align: Align = "se3",
    max_diff: float | None = None,
    fps: float | None = None,
) -> AteResult:
    """Absolute trajectory error (translation part, m) after ``align``; see ``AteResult``.

    Same as ``evo_ape <fmt> ref est -a [-s] --t_max_diff max_diff``.
    """
    from evo.core.metrics import PoseRelation
    from evo.main_ape import ape

    pair = _associated(estimate, reference, align, max_diff, fps)
    est, ref = pair.estimate.to_evo(), pair.reference.to_evo()
    result = _evo_call(ape, ref, est, PoseRelation.translation_part, align=align != "none", correct_scale=align == "sim3")
    errors = np.asarray(result.np_arrays["error_array"], dtype=np.float64)
    stats = ErrorStats.of(errors)
    return AteResult(
        rmse=stats.rmse,
        mean=stats.mean,
        median=stats.median,
        max=stats.max,
        min=stats.min,
        std=stats.std,
        scale=_sim3_scale(result) if align == "sim3" else 1.0,
        matched=len(errors),
        align=align,
        max_diff=pair.max_diff,
        timestamps=pair.reference.timestamps,
        errors=errors,
        estimate=Trajectory.from_evo(est),
        reference=pair.reference,
    )


def rpe(
    estimate: Trajectory,
    reference: Trajectory,
    *,
    delta: float = 1.0,
    unit: RpeUnit = "m",
    align: Align = "se3",
    max_diff: float | None = None,
    fps: float | None = None,
) -> RpeResult:
    """Relative pose error (drift) over consecutive pairs; see ``RpeResult`` for the formulas.

    Pairs: ``"m"`` - the next pose after at least ``delta`` metres of *reference* path
    (``evo_rpe ... -d delta -u m --pairs_from_reference``); ``"frames"`` - every ``delta``-th
    associated pose (``-u f``); ``"s"`` - the first pose at least ``delta`` seconds later
    (evo has no time unit: pairs chosen here, errors by the same formula). ``align``
    matters only for ``sim3`` (the estimate's scale); a rigid alignment leaves RPE unchanged.
    """
    if unit not in get_args(RpeUnit):
        raise SalError(f"RPE unit must be one of {', '.join(get_args(RpeUnit))}, got {unit!r}")
    if not delta > 0 or (unit == "frames" and float(delta) != int(delta)):
        raise SalError(f"RPE delta must be positive (and whole for frames), got {delta}")
    pair = _associated(estimate, reference, align, max_diff, fps)
    est, ref = pair.estimate.to_evo(), pair.reference.to_evo()
    scale = _align(est, ref, align)
    if unit == "s":
        ids = _time_pairs(pair.reference.timestamps, delta)
        if len(ids) == 0:
            raise SalError(f"RPE: the trajectory spans less than delta = {delta} s")
        trans, rot = relative_errors(ref.poses_se3, est.poses_se3, ids)
        stamps = pair.reference.timestamps[ids[:, 1]]
    else:
        trans, rot, stamps = _evo_rpe(ref, est, delta, unit)
    trans, rot = trans / delta, rot / delta
    return RpeResult(
        trans=ErrorStats.of(trans),
        rot=ErrorStats.of(rot),
        delta=float(delta),
        unit=unit,
        pairs=len(trans),
        align=align,
        scale=scale,
        max_diff=pair.max_diff,
        timestamps=stamps,
        trans_errors=trans,
        rot_errors=rot,
    )


def scale_error(estimate: Trajectory, reference: Trajectory, *, max_diff: float | None = None) -> float:
    """``|1 - s|`` with ``s`` the Sim(3) scale that maps the estimate onto the reference.

    0 for a metric estimate; an estimate 3x too large gives ``s = 1/3`` and ``2/3``.
    """
    return abs(1.0 - ate(estimate, reference, align="sim3", max_diff=max_diff).scale)


# -- helpers ------------------------------------------------------------------------------------
def _span(t: Trajectory) -> str:
    if not len(t):
        return "is empty"
    return f"spans {t.timestamps[0]:.3f}..{t.timestamps[-1]:.3f} s ({len(t)} poses)"


def _associated(estimate: Trajectory, reference: Trajectory, align: str, max_diff: float | None, fps: float | None) -> Association:
    if align not in get_args(Align):
        raise SalError(f"alignment must be one of {', '.join(get_args(Align))}, got {align!r}")
    pair = associate(estimate, reference, max_diff=max_diff, fps=fps)
    if align != "none" and len(pair.estimate) < MIN_POSES:
        raise SalError(f"only {len(pair.estimate)} pose(s) associate with the reference: {align} alignment needs {MIN_POSES}")
    return pair


def _evo_call(function: Any, *args: Any, **kwargs: Any) -> Any:
    """Call into evo, turning its exceptions (degenerate alignment, empty pairs) into ``SalError``."""
    from evo import EvoException

    try:
        return function(*args, **kwargs)
    except EvoException as exc:
        raise SalError(f"evo: {exc}") from None


def _align(est: Any, ref: Any, align: str) -> float:
    """Align evo ``est`` onto ``ref`` in place; return the scale (1.0 unless ``sim3``)."""
    if align == "none":
        return 1.0
    _, _, s = _evo_call(est.align, ref, correct_scale=align == "sim3")
    return float(s)


def _sim3_scale(result: Any) -> float:
    """``s`` of evo's ``[[s R, t], [0, 1]]`` alignment matrix: ``det(s R)^(1/3)``."""
    return float(np.cbrt(np.linalg.det(result.np_arrays["alignment_transformation_sim3"][:3, :3])))


def _evo_rpe(ref: Any, est: Any, delta: float, unit: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """evo RPE (translation m, rotation deg) on already aligned copies, consecutive pairs."""
    from evo.core.metrics import PoseRelation, Unit
    from evo.main_rpe import rpe as evo_rpe

    delta_unit = Unit.meters if unit == "m" else Unit.frames
    out = []
    for relation in (PoseRelation.translation_part, PoseRelation.rotation_angle_deg):
        # evo_rpe trims its trajectories to the pair ends: give it copies
        r = _evo_call(
            evo_rpe,
            copy.deepcopy(ref),
            copy.deepcopy(est),
            relation,
            delta=int(delta) if unit == "frames" else float(delta),
            delta_unit=delta_unit,
            all_pairs=False,
            pairs_from_reference=True,
        )
        out.append(np.asarray(r.np_arrays["error_array"], dtype=np.float64))
    return out[0], out[1], np.asarray(r.np_arrays["timestamps"], dtype=np.float64)


def _time_pairs(stamps: np.ndarray, delta: float) -> np.ndarray:
    """Consecutive index pairs ``(i, j)``: ``j`` the first pose with ``t_j >= t_i + delta``."""
    ids = [0]
    while (j := int(np.searchsorted(stamps, stamps[ids[-1]] + delta - 1e-9, side="left"))) < len(stamps):
        ids.append(j)
    return np.column_stack([ids[:-1], ids[1:]]).astype(int) if len(ids) > 1 else np.zeros((0, 2), dtype=int)


def relative_errors(
    ref_poses: list[np.ndarray] | np.ndarray, est_poses: list[np.ndarray] | np.ndarray, ids: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Translation (m) and rotation (deg) of ``E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)`` per index pair
    ``(i, j)`` of ``ids`` (``Q`` reference, ``P`` estimate, 4x4 poses). The KITTI devkit's
    ``pose_error`` is ``E^-1``: the same translation norm and rotation angle."""
    q, p = np.asarray(ref_poses), np.asarray(est_poses)
    i, j = ids[:, 0], ids[:, 1]
    q_rel = np.linalg.inv(q[i]) @ q[j]
    p_rel = np.linalg.inv(p[i]) @ p[j]
    e = np.linalg.inv(q_rel) @ p_rel
    rot = np.degrees(Rotation.from_matrix(e[:, :3, :3]).magnitude())
    return np.linalg.norm(e[:, :3, 3], axis=1), rot
