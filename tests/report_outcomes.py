"""The outcomes the report tests (test_report.py) render: one per verdict and kind of search, as
the plugin writes them (real modules, parameters, units, systems, dataset names, requirement
and reproduction lines; test_report_fixtures.py checks them against the real code)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from pytest_sal.engine.outcomes.outcome import Boundary, Outcome, Trial, TrialMetrics

__all__ = ["FOG_REQ", "XSS_ID", "flaky", "fog", "m", "never_passed", "png", "rain", "regressed", "sweep_point"]

FOG_REQ = "ate_rmse < 1.5 m and tracking_rate >= 0.9 wherever fog.visibility_m >= 25 m"
XSS_ID = "tests/robustness/test_weather.py::test_rain[<script>alert(1)</script>]"


def m(ate: float | None, rate: float | None) -> TrialMetrics:
    """A trial's metrics: ATE (m) and tracking rate; the other metrics not available."""
    return TrialMetrics({"ate_rmse": ate, "tracking_rate": rate, "rpe_trans": None, "rpe_rot": None, "scale_error": None})


def fog(artifacts_dir: Path | None = None) -> Outcome:
    """Passed: edge 25 m passes, geometric bisection towards 1 m, boundary 13.7-15.1 m, all cached."""
    trials = [
        Trial(25.0, True, m(0.21, 0.99), cached=True, wall_time_s=0.01),
        Trial(5.0, False, m(4.8, 0.41), cached=True, failed=["ate_rmse < 1.5 m", "tracking_rate >= 0.9"]),
        Trial(11.18, False, m(2.1, 0.84), cached=True, failed=["ate_rmse < 1.5 m", "tracking_rate >= 0.9"]),
        Trial(16.72, True, m(0.44, 0.97), cached=True),
        Trial(13.67, False, m(1.7, 0.93), cached=True, failed=["ate_rmse < 1.5 m"]),
        Trial(15.12, True, m(0.83, 0.95), cached=True),
    ]
    if artifacts_dir is not None:
        for i, t in enumerate(trials):
            t.artifacts["frame"] = str(png(artifacts_dir / f"frame{i}.png", (64, 96), 40 * i))
        trials[0].artifacts["trajectory"] = str(png(artifacts_dir / "traj0.png", (60, 80), 200))
    return Outcome(
        test_id="tests/robustness/test_weather.py::test_fog[orbslam3-euroc_mh01]",
        system="orbslam3",
        dataset="euroc/MH_01_easy",
        parameter="fog.visibility_m",
        worse="lower",
        edge=25.0,
        requirement=FOG_REQ,
        criteria=[("ate_rmse", "<", 1.5), ("tracking_rate", ">=", 0.9)],
        envelope=">= 25 m",
        verdict="passed",
        boundary=Boundary(15.12, 13.67, "m"),
        termination="tolerance",
        trials=trials,
        margin=25.0 - 15.12,
        previous=Boundary(17.0, 15.0, "m"),
        reproduction="@sal.at(fog.visibility_m, 25)  # m; seed 0, up to 5 run(s), system orbslam3, dataset euroc/MH_01_easy",
    )


def rain() -> Outcome:
    """Failed at the edge (tracking lost there), boundary 12.5-15 mm/h, a contradiction; id with <script>."""
    return Outcome(
        test_id=XSS_ID,
        system="reference_vo",
        dataset="kitti/07",
        parameter="rain.intensity_mm_h",
        worse="higher",
        edge=20.0,
        requirement="ate_rmse < 1 m wherever rain.intensity_mm_h <= 20 mm/h",
        criteria=[("ate_rmse", "<", 1.0)],
        envelope="<= 20 mm/h",
        verdict="failed",
        boundary=Boundary(12.5, 15.0, "mm/h"),
        termination="tolerance",
        trials=[
            Trial(20.0, False, m(None, 0.0), failed=["ate_rmse < 1 m"], wall_time_s=41.0),
            Trial(10.0, True, m(0.31, 1.0), wall_time_s=38.0),
            Trial(15.0, False, m(2.9, 0.7), failed=["ate_rmse < 1 m"], wall_time_s=40.0),
            Trial(12.5, True, m(0.52, 1.0), wall_time_s=39.0),
            Trial(17.5, True, m(0.9, 0.99), wall_time_s=39.0),
        ],
        contradictions=["17.5 mm/h passed but 15 mm/h (milder) failed"],
        margin=12.5 - 20.0,
        reproduction="@sal.at(rain.intensity_mm_h, 20)  # mm/h; seed 0, up to 1 run(s), system reference_vo, dataset kitti/07",
    )


def flaky() -> Outcome:
    return Outcome(
        test_id="tests/test_motion.py::test_blur",
        system="orbslam3",
        dataset="tum/rgbd_dataset_freiburg1_desk",
        parameter="motion_blur.speed_kmh",
        worse="higher",
        edge=50.0,
        requirement="ate_rmse < 0.1 m wherever motion_blur.speed_kmh <= 50 km/h",
        criteria=[("ate_rmse", "<", 0.1)],
        envelope="<= 50 km/h",
        verdict="flaky",
        boundary=Boundary(50.0, 100.0, "km/h"),
        termination="max_trials",
        trials=[
            Trial(50.0, False, m(0.12, 0.97), runs=[{"passed": p} for p in (True, False, False, True, False)], failed=["ate_rmse < 0.1 m"]),
            Trial(100.0, False, m(0.4, 0.9), failed=["ate_rmse < 0.1 m"]),
        ],
        margin=0.0,
        reproduction="@sal.at(motion_blur.speed_kmh, 50)  # km/h; seed 0, up to 5 run(s), system orbslam3, dataset tum/rgbd_dataset_freiburg1_desk",
    )


def regressed() -> Outcome:
    return Outcome(
        test_id="tests/test_transport.py::test_drop",
        system="orbslam3",
        dataset="euroc/V1_01_easy",
        parameter="frame_drop.drop_rate",
        worse="higher",
        edge=0.1,
        requirement="tracking_rate >= 0.8 wherever frame_drop.drop_rate <= 0.1",
        criteria=[("tracking_rate", ">=", 0.8)],
        envelope="<= 0.1",
        verdict="passed",
        boundary=Boundary(0.19, 0.2, ""),
        termination="tolerance",
        trials=[
            Trial(0.1, True, m(0.1, 0.95)),
            Trial(0.19, True, m(0.2, 0.82)),
            Trial(0.2, False, m(0.3, 0.7)),
            Trial(0.18, True, m(0.2, 0.85)),
        ],
        margin=0.09,
        previous=Boundary(0.3, 0.35, ""),
        regression="frame_drop.drop_rate boundary moved toward the requirement: passed up to 0.3 before, now only up to 0.19 (-37 %, limit 10 %)",
        reproduction="@sal.at(frame_drop.drop_rate, 0.1)  # no unit; seed 0, up to 5 run(s), system orbslam3, dataset euroc/V1_01_easy",
    )


def never_passed() -> Outcome:
    return Outcome(
        test_id="tests/test_weather.py::test_fog_night",
        system="orbslam3",
        dataset="kitti/07",
        parameter="(night>>fog).visibility_m",
        worse="lower",
        edge=25.0,
        requirement="ate_rmse < 1.5 m wherever (night>>fog).visibility_m >= 25 m",
        criteria=[("ate_rmse", "<", 1.5)],
        envelope=">= 25 m",
        verdict="failed",
        boundary=Boundary(None, 100000.0, "m"),
        termination="not_bracketed",
        trials=[Trial(25.0, False, m(None, 0.05)), Trial(100000.0, False, m(None, 0.1))],
        margin=None,
        reproduction="@sal.at((night>>fog).visibility_m, 25)  # m; seed 0, up to 5 run(s), system orbslam3, dataset kitti/07",
    )


def sweep_point() -> Outcome:
    """A ``sal.sweep`` level: no envelope, no trials yet, no metrics."""
    return Outcome(
        test_id="test_sweep.py::test_levels[3]",
        system="reference_vo",
        dataset="synthetic/urban-seed0",
        parameter="sensor_noise.iso",
        worse="higher",
        edge=None,
        requirement="ate_rmse < 0.5 m",
        criteria=[("ate_rmse", "<", 0.5)],
        verdict="failed",
        boundary=Boundary(None, None, ""),
        termination="single",
    )


def png(path: Path, size: tuple[int, int], level: int) -> Path:
    image = np.full((*size, 3), level % 256, np.uint8)
    cv2.circle(image, (size[1] // 2, size[0] // 2), 10, (0, 0, 255), -1)
    assert cv2.imwrite(str(path), image)
    return path
