"""Machine load of paced runs (``sal_wrappers.pacing``): the fell-behind rule, re-pacing, the
oversubscription warning, and the ``RunResult`` fields that carry them. Synthetic hand-over
times only; the real ORB-SLAM3 runs are in test_orbslam3.py."""

from __future__ import annotations

import numpy as np
import pytest

from sal_wrappers import RunResult, TrackState, oversubscribed_warning
from sal_wrappers.pacing import LATE_PERIODS, MAX_LATE_SHARE, MAX_OVERRUN, MIN_PACE, fell_behind_reason, load_figures, machine_load, repace

FPS = 10.0
N = 100


def handed_over(extra: np.ndarray, pace: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Sensor times at 10 Hz and hand-over times with ``extra[i]`` s of lateness on frame i."""
    t = np.arange(N) / FPS
    lateness = np.r_[0.0, np.asarray(extra, dtype=np.float64)[1:]]
    given = np.r_[0.0, np.cumsum(np.diff(t) / pace + lateness[1:])]
    return t, given


def late_frames(count: int, seconds: float) -> np.ndarray:
    extra = np.zeros(N)
    extra[1 : 1 + count] = seconds
    return extra


def test_on_time_run_keeps_up() -> None:
    t, given = handed_over(np.full(N, 0.004))  # a few ms of sleep overshoot
    figures = load_figures(t, given, np.full(N, 0.04), 1.0, {"cpu_s": 8.0, "loop_wall_s": 10.0})
    assert not figures["fell_behind"] and figures["fell_behind_reason"] is None
    assert figures["late_frames"] == 0 and figures["lateness_ms_max"] == pytest.approx(4.0)
    assert figures["period_ms"] == pytest.approx(100.0) and figures["late_threshold_ms"] == pytest.approx(50.0)
    assert figures["sensor_s"] == pytest.approx(9.9) and figures["overrun"] == pytest.approx(0.396 / 9.9, abs=1e-4)
    assert figures["track_over_period_median"] == pytest.approx(0.4) and figures["frames_track_over_period"] == 0
    assert figures["cpu_per_wall"] == pytest.approx(0.8) and figures["cpu_s"] == 8.0


def test_lateness_is_against_each_frames_due_time() -> None:
    t = np.array([0.0, 0.1, 0.2, 0.4])  # a dropped frame: 200 ms gap
    given = np.array([5.0, 5.1, 5.33, 5.6])  # origin does not matter
    figures = load_figures(t, given, np.full(4, 0.03), 1.0)
    # due: -, 5.1, 5.2, 5.53 -> lateness 0, 0, 130, 70 ms; late past half of its own period: 130 > 50, 70 < 100
    assert figures["lateness_ms_max"] == pytest.approx(130.0)
    assert figures["late_frames"] == 1
    assert figures["loop_s"] == pytest.approx(0.6) and figures["sensor_s"] == pytest.approx(0.4)


def test_late_share_rule_boundary() -> None:
    """More than 10 % of frames later than half a period: fell behind; 10 % or fewer: kept up."""
    at_limit = int(MAX_LATE_SHARE * N)
    t, given = handed_over(late_frames(at_limit, 0.06))
    below = load_figures(t, given, np.full(N, 0.05), 1.0)
    assert below["late_frames"] == at_limit and below["overrun"] < MAX_OVERRUN and not below["fell_behind"]
    t, given = handed_over(late_frames(at_limit + 1, 0.06))
    above = load_figures(t, given, np.full(N, 0.05), 1.0)
    assert above["fell_behind"]
    assert above["fell_behind_reason"] == f"{at_limit + 1} of {N} frames late by > 50 ms"
    # just under half a period is not late
    t, given = handed_over(late_frames(N - 1, 0.999 * LATE_PERIODS / FPS))
    small = load_figures(t, given, np.full(N, 0.05), 1.0)
    assert small["late_frames"] == 0


def test_overrun_rule_catches_many_small_delays() -> None:
    """Every frame 30 ms late (under half a period) adds up to 30 % behind the sensor clock."""
    t, given = handed_over(np.full(N, 0.03))
    figures = load_figures(t, given, np.full(N, 0.12), 1.0)
    assert figures["late_frames"] == 0
    assert figures["overrun"] == pytest.approx(0.3) and figures["fell_behind"]
    assert figures["fell_behind_reason"].endswith("s of sensor time")
    assert figures["frames_track_over_period"] == N - 1 and figures["track_over_period_median"] == pytest.approx(1.2)
    t, given = handed_over(np.full(N, 0.02))
    assert not load_figures(t, given, np.full(N, 0.12), 1.0)["fell_behind"]  # 20 % < 25 %


def test_pace_scales_the_frame_period() -> None:
    """At pace 0.5 a 10 Hz frame is due 200 ms after the previous: 180 ms per frame keeps up."""
    t = np.arange(N) / FPS
    given = np.r_[0.0, np.cumsum(np.full(N - 1, 0.18))]
    assert load_figures(t, given, np.full(N, 0.17), 1.0)["fell_behind"]
    slow = load_figures(t, given, np.full(N, 0.17), 0.5)
    assert slow["period_ms"] == pytest.approx(200.0) and slow["pace"] == 0.5
    assert slow["late_frames"] == 0 and not slow["fell_behind"]


def test_unpaced_run_never_falls_behind() -> None:
    t = np.arange(N) / FPS
    given = np.arange(N) * 0.5
    figures = load_figures(t, given, np.full(N, 0.5), None)
    assert not figures["paced"] and not figures["fell_behind"] and figures["late_frames"] == 0
    assert fell_behind_reason({}) is None


def test_repace_is_just_below_the_achieved_rate() -> None:
    assert repace(1.0, 14.4, 30.0, margin=1.0) == 0.48
    assert repace(1.0, 14.4, 30.0) == 0.43  # 0.9 x 0.48
    assert repace(1.0, 14.4, 14.5, margin=1.0) == 0.99
    assert repace(0.5, 28.8, 40.0, margin=1.0) == 0.36  # 0.5 * 0.72
    assert repace(1.0, 14.4, 1000.0) == MIN_PACE
    assert repace(1.0, 14.4, 10.0) == 1.0  # never faster
    assert repace(1.0, 14.4, 0.0) == 1.0


def test_repace_keeps_the_synthetic_run_up() -> None:
    """Re-paced at the achieved rate, the same per-frame cost is on time."""
    t = np.arange(N) / FPS
    given = np.r_[0.0, np.cumsum(np.full(N - 1, 0.19))]
    first = load_figures(t, given, np.full(N, 0.19), 1.0)
    pace = repace(1.0, first["sensor_s"], first["loop_s"])
    assert first["fell_behind"] and pace == 0.47  # 0.9 x 0.526
    given = np.r_[0.0, np.cumsum(np.maximum(0.19, np.diff(t) / pace))]
    assert not load_figures(t, given, np.full(N, 0.19), pace)["fell_behind"]


def test_oversubscribed_warning() -> None:
    quiet = {"loadavg": [0.3, 0.2, 0.1], "cpus": 2, "usable_cpus": 2}
    assert oversubscribed_warning(1, load=quiet) is None
    text = oversubscribed_warning(2, load={**quiet, "loadavg": [9.3, 5.0, 2.0]})
    assert text == (
        "pytest-sal: 2 worker(s) x ORB-SLAM3 (about 1.5 cores each) on 2 cores with load average 9.3: "
        "runs may fall behind the sensor clock; they are re-paced and marked"
    )
    assert oversubscribed_warning(2, load=quiet) is not None  # 3 cores needed
    assert oversubscribed_warning(1, load={**quiet, "loadavg": [2.5, 1.0, 1.0]}) is not None  # already busy
    assert oversubscribed_warning(8, cpus_per_run=1.0, load={"loadavg": [0.0, 0, 0], "cpus": 16, "usable_cpus": 8}) is None
    load = machine_load()
    assert len(load["loadavg"]) == 3 and load["cpus"] >= 1 and 1 <= load["usable_cpus"] <= load["cpus"]


def _result(**fields: object) -> RunResult:
    return RunResult("orbslam3", "kitti-07", "mono", np.arange(4) / 10, np.full(4, TrackState.OK), **fields)


def test_run_result_keeps_load_and_reads_old_entries() -> None:
    t, given = handed_over(np.full(N, 0.09))
    load = load_figures(t, given, np.full(N, 0.18), 1.0)
    result = _result(load=load, fell_behind=True, info={"attempts": [{"pace": 1.0, "load": load}]})
    back = RunResult.from_json(result.to_json())
    assert back.fell_behind and back.load == load and back.info["attempts"][0]["load"]["late_frames"] == N - 1
    old = result.to_dict()
    del old["load"], old["fell_behind"]
    restored = RunResult.from_dict(old)
    assert restored.load == {} and restored.fell_behind is False
    assert "sensor clock" not in restored.summary()


def test_summary_says_re_paced_or_starved() -> None:
    t, given = handed_over(np.full(N, 0.09))
    late = load_figures(t, given, np.full(N, 0.18), 1.0)
    t, given = handed_over(np.zeros(N), pace=0.52)
    on_time = load_figures(t, given, np.full(N, 0.18), 0.52)
    repaced = _result(load=on_time, info={"attempts": [{"pace": 1.0, "load": late}, {"pace": 0.52, "load": on_time}]})
    assert repaced.summary().endswith(
        "; fell behind the sensor clock (99 of 100 frames late by > 50 ms; 18.8 s for 9.9 s of sensor time); re-paced at 0.52x"
    )
    starved = _result(load=late, fell_behind=True, info={"attempts": [{"pace": 1.0, "load": late}]})
    assert "; STARVED: fell behind the sensor clock (99 of 100 frames late by > 50 ms" in starved.summary()
    assert "sensor clock" not in _result(load=on_time).summary()
