"""run_job's worker-side dataset check and failed_output, the run an executor reports when its
worker gave nothing back: a run that tracked nothing, with its reason, never cached."""

from __future__ import annotations

import shutil
import socket
from pathlib import Path

import pytest
from kitti_excerpt import kitti_copy

from pytest_sal import tracking_rate
from pytest_sal.analysis.metrics import AGGREGATED
from pytest_sal.engine.execution.executor import Executor, LocalExecutor
from pytest_sal.engine.execution.run_job import RunJob, check_readable, failed_output
from pytest_sal.engine.execution.trial_runner import TrialRunner
from pytest_sal.engine.outcomes.run_record import RunRecord
from pytest_sal.engine.requirements import Requirement
from pytest_sal.store.content_cache import ContentCache
from pytest_sal.testing import FakeSlam
from sal_adapters import Sequence, open_dataset
from sal_adapters.common.errors import DatasetError
from sal_modules import fog

LOST = "Ray worker lost 3 times: WorkerCrashedError: The worker died unexpectedly while executing this task"


class WorkerLost(Executor):
    """Every run's worker is lost: the output RayExecutor gives after the retries."""

    name = "lost"

    def _run(self, job: RunJob) -> RunRecord:
        return failed_output(job, LOST, LOST)


def trial_runner(dataset: Sequence, tmp_path: Path, executor: Executor) -> TrialRunner:
    requirement = Requirement.build([tracking_rate >= 0.5, fog.visibility_m >= 25])
    return TrialRunner(
        dataset,
        fog.visibility_m.ref(),
        FakeSlam(),
        requirement,
        cache=ContentCache(tmp_path / "cache"),
        workdir=tmp_path,
        executor=executor,
    )


def test_a_lost_run_fails_with_its_reason_and_is_never_cached(tmp_path: Path) -> None:
    dataset = open_dataset("synthetic", scene="indoor", frames=6, sensor="rgbd")
    runner = trial_runner(dataset, tmp_path, WorkerLost())
    trial = runner.run_trial(40.0)
    (run,) = trial.runs
    assert not trial.passed and run["failure"] == LOST and run["not_cached"] == LOST
    assert run["tracking_rate"] == 0.0 and run["ate_rmse"] is None and not run["cached"]
    assert all(name in run for name in AGGREGATED)
    assert ContentCache(tmp_path / "cache").get(runner.key(40.0)) is None
    again = trial_runner(dataset, tmp_path, LocalExecutor()).run_trial(40.0)  # the next session runs it
    assert again.passed and not again.cached
    assert trial_runner(dataset, tmp_path, WorkerLost()).run_trial(40.0).cached


def test_the_failed_record_is_a_complete_run_record(tmp_path: Path) -> None:
    dataset = open_dataset("synthetic", scene="indoor", frames=5, sensor="rgbd")
    runner = trial_runner(dataset, tmp_path, LocalExecutor())
    job = RunJob(
        key=runner.key(30.0),
        number=0,
        value=30.0,
        label="fog.visibility_m = 30 m",
        dataset=dataset,
        module=fog(visibility_m=30.0),
        system=FakeSlam(),
        seed=0,
        workdir=tmp_path,
        timeout=10.0,
        kitti_segments=(100.0,),
    )
    record = failed_output(job, "no result", None)
    assert RunRecord.entry_problem(record.entry()) is None and "not_cached" not in record.entry()
    assert record.value == 30.0 and record.module == fog(visibility_m=30.0).to_dict()
    assert record.result["states"] == ["not_initialised"] * 5 and record.result["failure"] == "no result"


def test_a_dataset_the_worker_cannot_read_names_the_path_and_the_worker(shared_data: Path, tmp_path: Path) -> None:
    folder = kitti_copy(shared_data, tmp_path / "kitti")
    dataset = open_dataset("kitti", folder)
    runner = trial_runner(dataset, tmp_path, LocalExecutor())
    runner.key(30.0)  # the controller read the dataset (its fingerprint) before it went away
    shutil.rmtree(folder)
    with pytest.raises(DatasetError) as error:
        runner.run_trial(30.0)
    assert error.value.path == str(folder)
    assert f"not readable on worker {socket.gethostname()}:" in str(error.value)
    assert "every worker must see the dataset at the same path as the controller" in str(error.value)


def test_a_missing_frame_file_is_named_too(shared_data: Path, tmp_path: Path) -> None:
    folder = kitti_copy(shared_data, tmp_path / "kitti")
    dataset = open_dataset("kitti", folder)
    runner = trial_runner(dataset, tmp_path, LocalExecutor())
    runner.key(30.0)
    (folder / "image_0" / "000002.png").unlink()  # the last frame
    with pytest.raises(DatasetError, match="000002.png: the dataset .* is not readable on worker"):
        runner.run_trial(30.0)


def test_a_rendered_sequence_reads_no_files_and_is_not_checked(tmp_path: Path) -> None:
    dataset = open_dataset("synthetic", scene="indoor", frames=4, sensor="rgbd", cache_dir=tmp_path / "render")
    moved = dataset.replace(source=tmp_path / "elsewhere")  # a worker without the render cache renders the frames
    check_readable(moved, "worker:1")
    assert moved[0].image.shape == (dataset.camera.height, dataset.camera.width, 3)
