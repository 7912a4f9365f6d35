"""Outcomes the run history tests save and compare (test_history_runs.py,
test_history_regression.py, test_history_command.py): a fog boundary search and a frame-drop
metric test, and the run files they are saved in."""

from __future__ import annotations

from pathlib import Path

from pytest_sal.engine.outcomes.outcome import Boundary, Outcome, Trial
from pytest_sal.history.run_history import History

__all__ = ["DROP", "FOG", "drop", "fog", "save"]


FOG = "tests/test_fog.py::test_fog_visibility"
DROP = "tests/test_transport.py::test_frame_drop"


def fog(
    pass_value: float | None, fail_value: float | None, *, edge: float = 25.0, ate: float | None = 0.3, verdict: str = "passed", **kw
) -> Outcome:
    """fog.visibility_m gets more severe when lower; the system passed down to ``pass_value``."""
    trials = [Trial(edge, verdict == "passed", {"ate_rmse": ate, "tracking_rate": 0.97})]
    trials += [Trial(v, ok, {"ate_rmse": 0.5}) for v, ok in ((pass_value, True), (fail_value, False)) if v is not None]
    fields: dict = {
        "test_id": FOG,
        "system": "orbslam3",
        "dataset": "kitti-07",
        "parameter": "fog.visibility_m",
        "worse": "lower",
        "edge": edge,
        "requirement": "ate_rmse < 1.5 m wherever fog.visibility_m >= 25 m",
        "verdict": verdict,
        "criteria": [("ate_rmse", "<", 1.5)],
        "envelope": ">= 25 m",
        "boundary": Boundary(pass_value, fail_value, "m"),
        "termination": "tolerance",
        "trials": trials,
    }
    return Outcome(**(fields | kw))


def drop(pass_value: float | None, fail_value: float | None, *, edge: float = 10.0, rate: float = 0.95) -> Outcome:
    """frame_drop.drop_rate gets more severe when higher; passed up to ``pass_value`` %."""
    return Outcome(
        test_id=DROP,
        system="orbslam3",
        dataset="kitti-07",
        parameter="frame_drop.drop_rate",
        worse="higher",
        edge=edge,
        requirement="tracking_rate >= 0.9 wherever frame_drop.drop_rate <= 10 %",
        verdict="passed",
        criteria=[("tracking_rate", ">=", 0.9)],
        envelope="<= 10 %",
        boundary=Boundary(pass_value, fail_value, "%"),
        termination="tolerance",
        trials=[Trial(edge, True, {"ate_rmse": 0.4, "tracking_rate": rate})],
    )


def save(history: History, outcomes: list[Outcome], commit: str = "1a2b3c4", name: str | None = None, dirty: bool = False) -> Path:
    return history.append_run(outcomes, name=name, commit=commit, dirty=dirty, machine={"hostname": "box"})
