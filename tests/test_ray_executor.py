"""RayExecutor on a real local Ray with 2 CPUs (started once for the module): the same trials and
boundary as the local executor, lost workers retried or failed with the reason and never cached,
a task that never answers cancelled, a cached suite that starts no Ray, the dataset check on the
worker, loopback only, and nothing left running afterwards.

Ray is imported only through pytest_sal.engine.execution.ray_executor (inside the tests), which keeps a
local Ray on 127.0.0.1; the tests' token is RAY_AUTH_TOKEN, not a file in the home folder.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from kitti_excerpt import kitti_copy
from ray_clusters import listening_addresses, ray_environment, session_processes, wait_until_gone

import pytest_sal.testing
from pytest_sal import tracking_rate
from pytest_sal.engine.execution import ray_executor
from pytest_sal.engine.execution.executor import Executor, ExecutorError, LocalExecutor
from pytest_sal.engine.execution.ray_executor import RayExecutor
from pytest_sal.engine.execution.run_job import RunJob
from pytest_sal.engine.execution.trial_runner import TrialRunner
from pytest_sal.engine.outcomes.outcome import Outcome
from pytest_sal.engine.requirements import Requirement
from pytest_sal.engine.search.requirement_search import SearchSettings, search_outcome
from pytest_sal.store.content_cache import ContentCache
from pytest_sal.testing import FakeSlam, LostWorkerSlam
from sal_adapters import Sequence, open_dataset
from sal_adapters.common.errors import DatasetError
from sal_modules import fog
from sal_wrappers import SlamSystem, create

HOME_TOKEN = Path.home() / ".ray" / "auth_token"


@pytest.fixture(scope="module")
def home_token_existed() -> bool:
    """Whether ~/.ray/auth_token existed before this module's Ray started."""
    return HOME_TOKEN.exists()


@pytest.fixture(scope="module")
def executor(home_token_existed: bool) -> Iterator[RayExecutor]:
    """A local Ray with 2 CPUs for the module, connected before the first test."""
    with ray_environment():
        local_ray = RayExecutor(num_cpus=2)
        local_ray.connect()
        yield local_ray
        local_ray.close()


def foggy_street() -> Sequence:
    """10 mono frames of the synthetic street: reference_vo tracks them in fog of 64 m, not of 32 m."""
    return open_dataset("synthetic", scene="urban", frames=10, sensor="mono")


def search(executor: Executor, cache: Path) -> Outcome:
    """reference_vo's boundary of tracking_rate >= 0.9 in fog, up to 6 trials."""
    requirement = Requirement.build([tracking_rate >= 0.9, fog.visibility_m >= 200])
    runner = TrialRunner(
        foggy_street(),
        fog.visibility_m.ref(),
        create("reference_vo"),
        requirement,
        cache=ContentCache(cache),
        workdir=cache / "work",
        timeout=120.0,
        executor=executor,
    )
    return search_outcome(runner, requirement, SearchSettings(tolerance_pct=25.0, max_trials=6), "test_fog")


def trials(outcome: Outcome) -> list[tuple[Any, ...]]:
    """Each trial's value, verdict, metrics and runs, without wall times, loads and cache flags."""

    def run(record: dict[str, Any]) -> dict[str, Any]:
        return {k: v for k, v in record.items() if k not in ("wall_time_s", "load", "cached")}

    return [(t.value, t.passed, dict(t.metrics), [run(r) for r in t.runs]) for t in outcome.trials]


@dataclass
class Searched:
    local: Outcome
    ray: Outcome
    ray_cache: Path


@pytest.fixture(scope="module")
def searched(executor: RayExecutor, tmp_path_factory: pytest.TempPathFactory) -> Searched:
    """The same search with the local executor and with Ray, each into its own cache."""
    local = search(LocalExecutor(), tmp_path_factory.mktemp("local-cache"))
    ray_cache = tmp_path_factory.mktemp("ray-cache")
    return Searched(local, search(executor, ray_cache), ray_cache)


def runner(tmp_path: Path, system: SlamSystem, executor: Executor, timeout: float = 60.0) -> TrialRunner:
    requirement = Requirement.build([tracking_rate >= 0.5, fog.visibility_m >= 25])
    dataset = open_dataset("synthetic", scene="indoor", frames=4, sensor="rgbd")
    cache = ContentCache(tmp_path / "cache")
    return TrialRunner(
        dataset, fog.visibility_m.ref(), system, requirement, cache=cache, workdir=tmp_path / "work", timeout=timeout, executor=executor
    )


def cache_files(tmp_path: Path) -> list[str]:
    """Every file in the cache folder, its .gitignore and lock files aside."""
    files = (tmp_path / "cache").rglob("*")
    return sorted(str(p.relative_to(tmp_path)) for p in files if p.is_file() and p.name != ".gitignore" and not p.name.endswith(".lock"))


def test_a_local_ray_is_on_loopback_only_and_says_so(executor: RayExecutor, home_token_existed: bool) -> None:
    ray = ray_executor.ray
    assert {node["NodeManagerAddress"] for node in ray.nodes() if node["Alive"]} == {"127.0.0.1"}
    folder = executor.session_folder
    assert folder is not None and folder.parent == Path("/tmp") and folder.name.startswith("sal-ray-")
    listening = listening_addresses(session_processes(folder))
    assert listening == {"127.0.0.1"}  # GCS, raylet, agents and workers: no port on another address
    assert executor.address.startswith("127.0.0.1:")
    assert executor.describe() == f"ray at {executor.address}: 1 node, 2 CPUs, 0 GPUs"
    # no run in flight: both CPUs are this executor's
    assert executor.slots(create("reference_vo")) == 2 and executor.slots(create("command", argv=["true"], num_cpus=2)) == 1
    assert HOME_TOKEN.exists() == home_token_existed  # the token came from RAY_AUTH_TOKEN, not a new file


def test_slots_count_the_share_of_the_cluster_less_the_runs_in_flight(executor: RayExecutor, tmp_path: Path) -> None:
    """Slots follow the cluster's size and this executor's own runs, not Ray's free-resource
    report, which lags the runs that just ended: a search's width does not depend on timing."""
    import threading
    import time

    from pytest_sal.testing import SleepySlam

    assert RayExecutor(num_cpus=4, share=2).slots(create("reference_vo")) == 2  # two xdist workers share 4 CPUs
    sleepy = SleepySlam(sleep_s=1.5)
    job = runner(tmp_path, sleepy, executor)
    running = threading.Thread(target=job.run_trial, args=(30.0,))
    running.start()
    deadline = time.monotonic() + 5
    while executor.slots(sleepy) == 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    during = executor.slots(sleepy)
    running.join()
    assert during == 1 and executor.slots(sleepy) == 2  # free again the moment the run is back


def test_the_deterministic_search_gives_the_same_trials_and_boundary_on_ray(searched: Searched, executor: RayExecutor) -> None:
    # 2 CPUs: a bisection round holds two trials; the walk along the verdicts is the local search
    path = [t for t, point in zip(trials(searched.ray), searched.ray.trials) if not point.speculative]
    assert path == trials(searched.local) and any(point.speculative for point in searched.ray.trials)
    assert searched.ray.boundary == searched.local.boundary and searched.ray.verdict == searched.local.verdict
    boundary = searched.ray.boundary
    assert boundary.fail_value is not None and boundary.pass_value is not None
    assert (
        boundary.pass_value > 64 and boundary.fail_value < 128
    )  # fog of 64 m loses it, 128 m does not (reference_vo, the street of issue 25)
    assert len(searched.ray.trials) >= 4 and executor.submitted >= len(searched.ray.trials)


def test_a_cached_suite_sends_nothing_and_starts_no_ray(searched: Searched, tmp_path: Path) -> None:
    fresh = RayExecutor(temp_dir=tmp_path)
    again = search(fresh, searched.ray_cache)
    assert fresh.submitted == 0 and all(t.cached for t in again.trials)
    assert fresh.describe() == "ray (local, starts on the first run)" and fresh.session_folder is None
    assert not list(tmp_path.glob("sal-ray-*"))  # no session folder was made
    # the cached path is walked trial by trial: the speculative trials beside it are not asked for again
    assert trials(again) == [t for t, point in zip(trials(searched.ray), searched.ray.trials) if not point.speculative]
    assert again.boundary == searched.ray.boundary


def test_a_worker_killed_once_is_retried_and_its_run_stored(executor: RayExecutor, tmp_path: Path) -> None:
    switch, calls = tmp_path / "switch", tmp_path / "calls.jsonl"
    switch.write_text("kill-once")
    trial = runner(tmp_path, LostWorkerSlam(str(switch), calls_file=str(calls)), executor).run_trial(40.0)
    assert switch.read_text() == "never" and calls.read_text().count('"lost"') == 1  # the first attempt died
    assert trial.passed and trial.metrics["tracking_rate"] == 1.0 and "not_cached" not in trial.runs[0]
    assert runner(tmp_path, LostWorkerSlam(str(switch)), executor).run_trial(40.0).cached


def test_a_worker_lost_every_time_fails_with_the_reason_and_leaves_the_cache_sound(executor: RayExecutor, tmp_path: Path) -> None:
    switch, calls = tmp_path / "switch", tmp_path / "calls.jsonl"
    switch.write_text("kill")
    system = LostWorkerSlam(str(switch), calls_file=str(calls))
    trial = runner(tmp_path, system, executor).run_trial(40.0)
    (run,) = trial.runs
    assert run["failure"].startswith("Ray worker lost 3 times: WorkerCrashedError: The worker died unexpectedly")
    assert run["not_cached"] == run["failure"] and not trial.passed and run["tracking_rate"] == 0.0
    assert [json.loads(line) for line in calls.read_text().splitlines()] == [{"lost": "kill"}] * 3  # max_retries=2: 3 attempts
    assert cache_files(tmp_path) == []  # no entry, no temporary or partial file
    switch.write_text("run")  # the machine is fine again: the next session runs it and stores it
    good = runner(tmp_path, system, executor).run_trial(40.0)
    assert good.passed and not good.cached and len(cache_files(tmp_path)) == 1
    assert runner(tmp_path, system, executor).run_trial(40.0).cached


def test_a_task_that_never_answers_is_cancelled_and_not_cached(
    executor: RayExecutor, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(ray_executor, "RESULT_GRACE_S", 0.5)
    monkeypatch.setattr(executor, "max_retries", 0)
    switch = tmp_path / "switch"
    switch.write_text("hang")  # sleeps an hour whatever the timeout
    trial = runner(tmp_path, LostWorkerSlam(str(switch)), executor, timeout=1.0).run_trial(40.0)
    (run,) = trial.runs
    assert run["failure"] == (
        "no result from the Ray worker within 3 s (1 attempt(s) of timeout 1 s + 0.5 s, and as long again to wait for a worker): cancelled"
    )
    assert run["not_cached"] == run["failure"] and cache_files(tmp_path) == []


def test_the_worker_runs_the_controllers_code(executor: RayExecutor, tmp_path: Path) -> None:
    output = executor.run(fake_job(LostWorkerSlam(str(tmp_path / "no-switch")), tmp_path))
    assert output.result["info"]["code"] == pytest_sal.testing.__file__  # this checkout's, not an installed copy
    assert output.worker.split(":")[0] and " on Ray node " in output.worker and output.worker.endswith("(127.0.0.1)")
    assert output.metrics["tracking_rate"] == 0.5


def fake_job(system: SlamSystem, workdir: Path) -> RunJob:
    """One run of ``system`` on 4 indoor frames in fog of 20 m."""
    dataset = open_dataset("synthetic", scene="indoor", frames=4, sensor="rgbd")
    return RunJob(
        key="0" * 64,
        number=0,
        value=20.0,
        label="fog.visibility_m = 20 m",
        dataset=dataset,
        module=fog(visibility_m=20.0),
        system=system,
        seed=0,
        workdir=workdir,
        timeout=60.0,
        kitti_segments=(100.0,),
    )


def test_a_dataset_the_worker_cannot_read_is_one_error_naming_the_worker(executor: RayExecutor, shared_data: Path, tmp_path: Path) -> None:
    folder = kitti_copy(shared_data, tmp_path / "kitti")
    trial_runner = runner(tmp_path, FakeSlam(), executor)
    trial_runner.dataset = open_dataset("kitti", folder)
    trial_runner.key(30.0)  # the controller read it (its fingerprint) before it went away
    shutil.rmtree(folder)
    with pytest.raises(DatasetError) as error:
        trial_runner.run_trial(30.0)
    assert error.value.path == str(folder) and str(error.value).startswith(f"{folder}: the dataset kitti")
    assert " on Ray node " in str(error.value) and "(127.0.0.1): every worker must see the dataset at the same path" in str(error.value)


def test_a_system_no_node_can_fit_is_a_usage_error(executor: RayExecutor, tmp_path: Path) -> None:
    droid = create("command", argv=["true"], name="droid_slam", num_gpus=1)
    with pytest.raises(
        ExecutorError, match=r"droid_slam asks for CPU 1, GPU 1 per run, but no node of the Ray cluster at 127\.0\.0\.1:\d+ has"
    ):
        runner(tmp_path, droid, executor).run_trial(40.0)


def test_another_process_submits_to_the_same_ray_by_its_address(executor: RayExecutor, tmp_path: Path) -> None:
    # a pytest-xdist worker started before Ray: it has the token but not RAY_AUTH_MODE=token
    script = textwrap.dedent(
        """
        import sys
        from pytest_sal.engine.execution.ray_executor import RayExecutor
        from pytest_sal.engine.execution.run_job import RunJob
        from pytest_sal.testing import FakeSlam
        from sal_adapters import open_dataset
        from sal_modules import fog
        shared = RayExecutor(sys.argv[1])
        job = RunJob(key="0" * 64, number=0, value=20.0, label="fog", dataset=open_dataset("synthetic", scene="indoor", frames=4),
                     module=fog(visibility_m=20.0), system=FakeSlam(), seed=0, workdir=__import__("pathlib").Path(sys.argv[2]),
                     timeout=60.0, kitti_segments=(100.0,))
        output = shared.run(job)
        print(shared.describe(), output.metrics["tracking_rate"], output.worker)
        shared.close()
        """
    )
    env = {k: v for k, v in os.environ.items() if k != "RAY_AUTH_MODE"}
    done = subprocess.run(
        [sys.executable, "-c", script, executor.address, str(tmp_path)], env=env, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.startswith(f"ray at {executor.address}: 1 node, 2 CPUs, 0 GPUs 0.5 ")
    assert executor.address and session_processes(executor.session_folder or Path("/nonexistent"))  # still running


def test_closing_stops_every_process_and_removes_the_folder(executor: RayExecutor) -> None:
    folder = executor.session_folder
    assert folder is not None and session_processes(folder)
    executor.close()
    assert wait_until_gone(folder) == set() and not folder.exists()
    assert executor.session_folder is None and not ray_executor.ray.is_initialized()
    executor.close()  # again: nothing to do
