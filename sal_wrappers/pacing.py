"""Did a paced run keep up with the sensor clock? Load figures, the fell-behind rule, re-pacing.

ORB-SLAM3 is fed at the sensor rate: frame ``i`` is due ``(t_i - t_{i-1}) / pace`` s after
frame ``i-1`` was handed over. On a machine that cannot feed its threads, hand-overs come late
and LocalMapping falls behind, and monocular tracking degrades for reasons that are the
machine's, not the system's. ``load_figures`` measures this per run from the hand-over times;
``fell_behind_reason`` applies the rule; ``repace`` gives the slower pace of a re-run (0.9 x
the rate the machine achieved);
``oversubscribed_warning`` tells at session start that more runs are started than the cores
can feed.

The rule (thresholds from KITTI 07 mono, 140 frames, 2000 features, on a 2-core machine; see
benchmarks/load_kitti07.md): a paced run **fell behind** when more than ``MAX_LATE_SHARE``
(10 %) of its frames were handed over more than ``LATE_PERIODS`` (half) of their frame period
after they were due, or when its hand-overs took more than ``MAX_OVERRUN`` (25 %) longer than
the sensor clock (first to last frame, at the pace). An unpaced run never falls behind.

>>> import numpy as np
>>> given = np.r_[0.0, np.cumsum(np.full(99, 0.18))]   # 10 Hz frames handed over every 180 ms
>>> figures = load_figures(np.arange(100) / 10, given, np.full(100, 0.17), 1.0)
>>> figures["fell_behind"], figures["late_frames"], figures["lateness_ms_max"]
(True, 99, 80.0)
>>> repace(1.0, figures["sensor_s"], figures["loop_s"])  # 0.9 x the achieved 0.556x
0.5
"""

from __future__ import annotations

import math
import os
import resource
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # numpy loads with load_figures: the session-start warning stays light
    import numpy as np

__all__ = [
    "LATE_PERIODS",
    "MAX_LATE_SHARE",
    "MAX_OVERRUN",
    "MIN_PACE",
    "REPACE_MARGIN",
    "fell_behind_reason",
    "load_figures",
    "machine_load",
    "oversubscribed_warning",
    "process_usage",
    "repace",
]

#: A frame is late when handed over more than this many of its frame periods after it was due.
LATE_PERIODS = 0.5
#: A run fell behind when more than this share of its frames was late.
MAX_LATE_SHARE = 0.10
#: ... or when its hand-overs (first to last) took this much longer than the sensor clock.
MAX_OVERRUN = 0.25
#: The slowest pace a re-run is given (speed factor against the sensor rate).
MIN_PACE = 0.05
#: A re-run is paced this much below the rate the machine achieved: at exactly that rate about
#: one in ten re-runs beside 7 other ORB-SLAM3 runs on 2 cores fell behind again (load jitter).
REPACE_MARGIN = 0.9


def machine_load() -> dict[str, Any]:
    """``loadavg`` (1, 5, 15 min; runnable threads), ``cpus`` (``os.cpu_count()``) and
    ``usable_cpus`` (this process's CPU affinity)."""
    try:
        usable = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        usable = os.cpu_count() or 1
    return {"loadavg": [round(v, 2) for v in os.getloadavg()], "cpus": os.cpu_count() or 1, "usable_cpus": usable}


def oversubscribed_warning(workers: int, cpus_per_run: float = 1.5, load: dict[str, Any] | None = None) -> str | None:
    """A warning when ``workers`` concurrent ORB-SLAM3 runs (about ``cpus_per_run`` cores each)
    need more cores than this machine has, or the machine is already busier than its cores
    (1-min load average above the usable cores); ``None`` when they fit.

    ``load``: a ``machine_load()`` result (default: measured now)."""
    load = machine_load() if load is None else load
    cpus = int(load.get("usable_cpus") or load["cpus"])
    average = float(load["loadavg"][0])
    need = workers * cpus_per_run
    if need <= cpus and average <= cpus:
        return None
    return (
        f"pytest-sal: {workers} worker(s) x ORB-SLAM3 (about {cpus_per_run:g} cores each) on {cpus} cores "
        f"with load average {average:.1f}: runs may fall behind the sensor clock; they are re-paced and marked"
    )


def process_usage() -> dict[str, float]:
    """CPU time (s, user + sys, all threads of this process) and involuntary context switches
    so far; call it in the child, before and after the tracking loop."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return {"cpu_s": usage.ru_utime + usage.ru_stime, "involuntary_switches": float(usage.ru_nivcsw)}


def repace(pace: float, sensor_s: float, loop_s: float, margin: float = REPACE_MARGIN) -> float:
    """The pace (speed factor) of a re-run: ``margin * pace * sensor_s / loop_s``, a little
    below the rate the machine achieved (``sensor_s``: the sequence's duration at ``pace``;
    ``loop_s``: how long the hand-overs took, both in s), rounded down to 2 significant
    digits, at most ``pace``, at least ``MIN_PACE``."""
    if loop_s <= 0 or sensor_s <= 0:
        return pace
    factor = margin * pace * sensor_s / loop_s
    digits = 1 - math.floor(math.log10(factor)) if factor > 0 else 2
    factor = math.floor(factor * 10**digits) / 10**digits
    return float(min(pace, max(MIN_PACE, factor)))


def fell_behind_reason(figures: dict[str, Any]) -> str | None:
    """Why a run fell behind the sensor clock, in words (``None``: it kept up); ``figures``
    from ``load_figures``."""
    if not figures.get("paced") or not figures.get("frames"):
        return None
    reasons = []
    late, n = int(figures["late_frames"]), int(figures["frames"])
    if late > MAX_LATE_SHARE * n:
        reasons.append(f"{late} of {n} frames late by > {figures['late_threshold_ms']:.0f} ms")
    if figures["overrun"] > MAX_OVERRUN:
        reasons.append(f"{figures['loop_s']:.1f} s for {figures['sensor_s']:.1f} s of sensor time")
    return "; ".join(reasons) or None


def load_figures(
    timestamps: np.ndarray,
    given: np.ndarray,
    track_times: np.ndarray,
    pace: float | None,
    child: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Whether a run kept up with the sensor clock, as a JSON-ready dict.

    Args:
        timestamps: sensor times (s) of the frames handed over, in order.
        given: when each was handed over (s, any origin; same length).
        track_times: seconds in each tracking call.
        pace: speed factor of the pacing, ``None`` when unpaced.
        child: what the child measured, copied in: ``cpu_s`` (CPU time of the tracking loop,
            all threads), ``child_cpu_s`` (whole child so far), ``loop_wall_s``,
            ``involuntary_switches``, ``loadavg_start`` / ``loadavg_end``, ``cpus``.

    Keys: ``paced``, ``pace``, ``frames``; ``period_ms`` (median frame period at the pace);
    ``lateness_ms_median`` / ``_p90`` / ``_max`` (hand-over minus due time); ``late_frames``
    (later than ``late_threshold_ms`` = ``LATE_PERIODS`` x median period) and ``late_share``;
    ``sensor_s`` / ``loop_s`` (first to last frame: sensor clock at the pace / hand-overs) and
    ``overrun`` (``loop_s / sensor_s - 1``); ``track_ms_median``, ``track_over_period_median``
    and ``frames_track_over_period`` (tracking calls longer than their frame period);
    ``cpu_per_wall`` (cores used on average in the loop); the ``child`` figures; and
    ``fell_behind`` with ``fell_behind_reason`` (``fell_behind_reason()``'s words).
    """
    import numpy as np

    t = np.asarray(timestamps, dtype=np.float64).reshape(-1)
    g = np.asarray(given, dtype=np.float64).reshape(-1)
    track = np.asarray(track_times, dtype=np.float64).reshape(-1)
    n = min(len(t), len(g))
    t, g = t[:n], g[:n]
    rate = pace if pace else 1.0
    periods = np.diff(t) / rate  # s, frame i-1 -> i at the pace
    lateness = np.r_[0.0, g[1:] - (g[:-1] + periods)] if n else np.zeros(0)
    period = float(np.median(periods)) if len(periods) else 0.0
    late = lateness[1:] > LATE_PERIODS * periods if pace else np.zeros(max(0, n - 1), dtype=bool)
    sensor_s = float(t[-1] - t[0]) / rate if n else 0.0
    loop_s = float(g[-1] - g[0]) if n else 0.0
    k = min(len(track), len(periods) + 1)
    ratio = track[: k - 1] / np.maximum(periods[: k - 1], 1e-9) if k > 1 else np.zeros(0)  # call i against period to i+1

    def ms(values: np.ndarray, q: float) -> float:
        return round(float(np.percentile(values, q)) * 1e3, 2) if len(values) else 0.0

    figures: dict[str, Any] = {
        "paced": bool(pace),
        "pace": pace,
        "frames": int(n),
        "period_ms": round(period * 1e3, 2),
        "lateness_ms_median": ms(lateness, 50) if pace else 0.0,
        "lateness_ms_p90": ms(lateness, 90) if pace else 0.0,
        "lateness_ms_max": ms(lateness, 100) if pace else 0.0,
        "late_threshold_ms": round(LATE_PERIODS * period * 1e3, 2),
        "late_frames": int(np.count_nonzero(late)),
        "late_share": round(float(np.count_nonzero(late)) / n, 4) if n else 0.0,
        "sensor_s": round(sensor_s, 3),
        "loop_s": round(loop_s, 3),
        "overrun": round(loop_s / sensor_s - 1.0, 4) if sensor_s > 0 else 0.0,
        "track_ms_median": ms(track, 50),
        "track_over_period_median": round(float(np.median(ratio)), 3) if len(ratio) else 0.0,
        "frames_track_over_period": int(np.count_nonzero(ratio > 1.0)),
    }
    child = dict(child or {})
    if child.get("cpu_s") is not None and child.get("loop_wall_s"):
        figures["cpu_per_wall"] = round(float(child["cpu_s"]) / float(child["loop_wall_s"]), 3)
    figures.update(child)
    reason = fell_behind_reason(figures)
    figures["fell_behind"] = reason is not None
    figures["fell_behind_reason"] = reason
    return figures
