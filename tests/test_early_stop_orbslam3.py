"""Early stop of real ORB-SLAM3 runs: the child process applies the rule itself after every
frame, ends cleanly and the parent reads the stop back.

Measured on the 2-core machine (load about 1.5), KITTI 07 mono at 0.05 lx (night): the full
run never initialises (0/140) and takes 16-18 s; stopped by ``tracking_rate >= 0.9`` it ends
after 15 frames, in 2.4 s. The EuRoC excerpt in stereo tracks 95/95 with or without the rule.

``pyorbslam3`` must be installed (the ``orbslam3`` extra); the module is skipped without it.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pyorbslam3")

from pytest_sal import tracking_rate
from pytest_sal.engine.execution.early_stop import StopRule
from pytest_sal.engine.requirements import Requirement
from sal_adapters import Sequence, open_dataset
from sal_modules import create, perturb
from sal_wrappers import TrackState
from sal_wrappers import create as create_system
from sal_wrappers.base import SlamSystemError

RULE = StopRule.of(Requirement.build([tracking_rate >= 0.9]))


def test_a_run_that_never_initialises_stops_in_the_child_with_the_full_runs_verdict(
    shared_data: Path, orb_vocabulary: Path, tmp_path: Path
) -> None:
    kitti = open_dataset("kitti", shared_data / "kitti" / "sequences" / "07")
    dark = perturb(kitti, create("night", illuminance_lux=0.05), seed=0)
    system = create_system("orbslam3", vocabulary=orb_vocabulary)
    full = system.run(dark, tmp_path / "full", timeout=300)
    stopped = system.run(dark, tmp_path / "stopped", timeout=300, stop=RULE)
    assert full.stopped is None and full.tracked == 0 and full.failure is not None and "never initialised" in full.failure
    assert stopped.stopped == "tracking_rate >= 0.9 can no longer hold: not initialised by frame 15 of 140 (0.8929 at best)"
    assert stopped.failure is None and stopped.exit_status == 0 and stopped.info["phase"] == "done"  # not a crash
    assert stopped.info["frames_reported"] == 15 and stopped.load["frames"] == 15 and stopped.final_trajectory is None
    assert stopped.frames == 140 and (stopped.states == TrackState.NOT_INITIALISED).all()  # frames not run: not tracked
    verdict = Requirement.build([tracking_rate >= 0.9]).holds
    assert verdict({"tracking_rate": stopped.tracking_rate}) is verdict({"tracking_rate": full.tracking_rate}) is False


def test_a_run_that_holds_is_not_stopped(shared_data: Path, orb_vocabulary: Path, tmp_path: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # cam1/data.csv lists 4 missing files (test_euroc_read.py checks the warning)
        euroc: Sequence = open_dataset("euroc", shared_data / "euroc" / "V1_01_easy_micro", stereo=True)
    system = create_system("orbslam3", vocabulary=orb_vocabulary)
    full = system.run(euroc, tmp_path / "full", timeout=300)
    watched = system.run(euroc, tmp_path / "watched", timeout=300, stop=RULE)
    assert watched.stopped is None and watched.failure is None and watched.final_trajectory is not None
    assert watched.tracked == full.tracked == 95 and np.array_equal(watched.states, full.states)


def test_a_stop_that_does_not_pickle_is_refused_before_the_child_starts(tmp_path: Path) -> None:
    sequence = open_dataset("synthetic", scene="indoor", frames=4, sensor="rgbd")
    with pytest.raises(
        SlamSystemError, match=r"orbslam3: stop=.* cannot be sent to the child process .*a StopRule or a module-level function"
    ):
        create_system("orbslam3").run(sequence, tmp_path, stop=lambda states, frames: None)
    assert not (tmp_path / "orbslam3.log").exists()
