"""What ORB-SLAM3 reports, read back: its tracking states, map segments and saved trajectory.

Tracking states (ORB-SLAM3 ``TrackingState`` -> ``TrackState``):

* every state before the first ``OK`` frame -> ``NOT_INITIALISED``;
* ``OK`` (and ``OK_KLT``) -> ``OK``;
* after the first ``OK``: ``RECENTLY_LOST`` and ``LOST`` -> ``LOST``, and ``NOT_INITIALIZED``,
  ``NO_IMAGES_YET``, ``SYSTEM_NOT_READY`` -> ``LOST`` too: ORB-SLAM3 reports them after it
  reset the map it lost, so the system had a map and lost it. Frames the child never reported
  on (it crashed or timed out first) follow the same rule.

Map segments: a new segment starts at the first ``OK`` frame after a frame whose ORB-SLAM3
state was ``LOST``, ``NOT_INITIALIZED``, ``NO_IMAGES_YET`` or ``SYSTEM_NOT_READY`` (a new or
reset map, with its own origin and, in monocular, its own scale). ``RECENTLY_LOST`` frames
that come back to ``OK`` (relocalised in the same map) stay in their segment.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sal_adapters import Trajectory
from sal_adapters.common.textfiles import iter_rows, read_numeric_table
from sal_wrappers.base import TrackState

__all__ = ["ORB_STATES", "TRACKED", "map_states", "read_final_trajectory", "segment_ids", "state_name", "track_state"]

#: ORB-SLAM3 ``TrackingState`` values by name (pyorbslam3 0.1.1).
ORB_STATES: dict[str, int] = {
    "SYSTEM_NOT_READY": -1,
    "NO_IMAGES_YET": 0,
    "NOT_INITIALIZED": 1,
    "OK": 2,
    "RECENTLY_LOST": 3,
    "LOST": 4,
    "OK_KLT": 5,
}
#: The states of a tracked frame: ``OK`` and ``OK_KLT``.
TRACKED = frozenset({ORB_STATES["OK"], ORB_STATES["OK_KLT"]})
_RECENTLY_LOST = ORB_STATES["RECENTLY_LOST"]
_NAMES = {v: k for k, v in ORB_STATES.items()}


def state_name(state: int) -> str:
    """``"OK"`` for 2; the number as text for a value ORB-SLAM3 does not define."""
    return _NAMES.get(state, str(state))


def track_state(state: int | None, tracked_before: bool) -> TrackState:
    """``TrackState`` of one frame from its ORB-SLAM3 state (``None``: not reported) and
    whether an earlier frame was tracked; see the module text for the rule."""
    if state in TRACKED:
        return TrackState.OK
    return TrackState.LOST if tracked_before else TrackState.NOT_INITIALISED


def map_states(raw: list[int | None]) -> np.ndarray:
    """``TrackState`` per frame (int8) from ORB-SLAM3 states (``None``: not reported)."""
    out = np.empty(len(raw), dtype=np.int8)
    tracked = False
    for i, state in enumerate(raw):
        out[i] = track_state(state, tracked)
        tracked = tracked or out[i] == TrackState.OK
    return out


def segment_ids(raw: list[int | None]) -> np.ndarray:
    """Map segment (0, 1, ...) of every ``OK`` frame, -1 for the others; see the module text."""
    ids = np.full(len(raw), -1, dtype=np.int64)
    segment, broken = -1, True
    for i, state in enumerate(raw):
        if state in TRACKED:
            if broken:
                segment, broken = segment + 1, False
            ids[i] = segment
        elif state != _RECENTLY_LOST:
            broken = True
    return ids


def read_final_trajectory(path: Path, frame_times: np.ndarray, tolerance_s: float = 1e-3) -> Trajectory:
    """Read ORB-SLAM3's ``save_trajectory_euroc`` file and put its times on the frames' times.

    The file has one line per frame, space-separated: ``1e9 * t`` (ns, printed with 6
    decimals; a float64, so absolute EuRoC times are off by up to 256 ns), ``tx ty tz`` (m) and
    ``qx qy qz qw`` (Hamilton, x y z w: TUM order, not EuRoC's w-first). Each time is replaced
    by the nearest frame time when that is within ``tolerance_s`` (s). It is read line by line
    within the limits of ``sal_adapters.common.textfiles.iter_rows``; a bad line raises ``DatasetError``.
    """
    if next(iter_rows(path), None) is None:
        raise ValueError(f"{path}: no poses")
    table, _ = read_numeric_table(path, 8, what="values (t [ns], tx ty tz, qx qy qz qw)")
    times = table[:, 0] * 1e-9
    frame_times = np.sort(np.asarray(frame_times, dtype=np.float64))
    if len(frame_times):
        pos = np.clip(np.searchsorted(frame_times, times), 1, max(1, len(frame_times) - 1))
        lo = frame_times[np.maximum(pos - 1, 0)]
        hi = frame_times[np.minimum(pos, len(frame_times) - 1)]
        nearest = np.where(np.abs(times - lo) <= np.abs(hi - times), lo, hi)
        times = np.where(np.abs(nearest - times) <= tolerance_s, nearest, times)
    return Trajectory(times, table[:, 1:4], table[:, 4:8])
