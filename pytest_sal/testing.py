"""Test doubles for testing pytest-sal itself and plug-ins: a deterministic fake SLAM system
whose tracking degrades with the severity of the perturbation it is given, and one that loses
the worker it runs on (for an executor's retries and time limit).

``FakeSlam`` never looks at pixels: it reads the applied chain from the perturbed sequence
(``sequence.meta["perturbation"]``), takes the value of one parameter and tracks the first
``round(n * tracked(value))`` frames exactly (the ground-truth pose), the rest LOST. So a test
of the plugin knows the exact boundary: with ``tracked = lambda v: min(1, v / 40)`` on
``fog.visibility_m`` and the criterion ``tracking_rate >= 0.5``, the boundary is 20 m.
The product never uses it: real tests run ORB-SLAM3 or the reference VO.
"""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pytest_sal.engine.execution.executor import Executor
from pytest_sal.engine.execution.run_job import RunJob, run_job
from pytest_sal.engine.outcomes.run_record import RunRecord
from sal_adapters import Sequence
from sal_wrappers.base import RunResult, SlamSystem, StopCheck, TrackState

__all__ = ["BernoulliSlam", "FakeSlam", "InProcessSlots", "LostWorkerSlam", "SleepySlam", "applied_value"]


def applied_value(sequence: Sequence, address: str) -> float | None:
    """The value of ``module.parameter`` (e.g. ``fog.visibility_m``) in the chain applied to
    ``sequence``, or ``None`` for a clean sequence or a chain without that module."""
    module, _, name = address.partition(".")
    chain = sequence.meta.get("perturbation")
    if chain is None:
        return None
    steps = chain.get("steps", [chain])
    for step in steps:
        if step.get("module") == module and name in step.get("params", {}):
            return float(step["params"][name])
    return None


def _share_function(tracked: str) -> Callable[[float], float]:
    """The expression ``tracked`` in ``v`` as a function (``min``, ``max`` and ``abs`` allowed)."""
    share: Callable[[float], float] = eval(f"lambda v: {tracked}", {"min": min, "max": max, "abs": abs})
    return share


class FakeSlam(SlamSystem):
    """Tracks a share ``tracked(value)`` (0..1) of the frames, ``value`` being the applied
    value of ``parameter``; the clean sequence tracks fully. ``crash_below`` / ``crash_above``
    make the run fail (as a crashed child would) beyond a value; ``flaky`` alternates the
    share between ``tracked(value)`` and ``tracked(value) + flaky`` from run to run (a noisy
    system near its threshold). ``calls_file`` gets a line per run: the value, and the process
    that ran it and its parent. Options are JSON values (``tracked`` as a small expression in
    ``v``, e.g. ``"min(1, v / 40)"``) so that they are part of cache keys."""

    name = "fake"
    sensors = ("mono", "stereo", "rgbd")
    description = "deterministic fake SLAM for testing the plugin (tracking falls with severity)"

    def __init__(
        self, parameter: str = "fog.visibility_m", tracked: str = "min(1, v / 40)", flaky: float = 0.0, calls_file: str | None = None
    ):
        self.parameter = parameter
        self.tracked = tracked
        self.flaky = float(flaky)
        self.calls_file = calls_file
        self.deterministic = not self.flaky  # type: ignore[misc]  # one run per trial unless flaky
        self._share = _share_function(tracked)
        self._runs = 0

    def __getstate__(self) -> dict[str, Any]:
        """Pickled without the compiled ``tracked`` (made again from its text when unpickled):
        plain pickle can send it to a worker, and cloudpickle (Ray) need not copy a lambda's
        code, which took 11 ms a run."""
        return {name: value for name, value in self.__dict__.items() if name != "_share"}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._share = _share_function(self.tracked)

    def options(self) -> dict[str, Any]:
        return {"parameter": self.parameter, "tracked": self.tracked, "flaky": self.flaky}

    def run(self, sequence: Sequence, workdir: Path, timeout: float | None = None, stop: StopCheck | None = None) -> RunResult:
        """Track the share of the frames (see the class text); ``stop`` is ignored (not ``stoppable``)."""
        start = time.perf_counter()
        value = applied_value(sequence, self.parameter)
        share = 1.0 if value is None else float(np.clip(self._share(value), 0.0, 1.0))
        if self.flaky and self._runs % 2:
            share = min(1.0, share + self.flaky)
        self._runs += 1
        self._record(value)
        n = len(sequence)
        tracked = int(round(n * share))
        states = np.full(n, TrackState.LOST, dtype=np.int8)
        states[:tracked] = TrackState.OK
        return self._result(sequence, states, range(tracked), time.perf_counter() - start, {"value": value, "share": share})

    def _record(self, value: float | None) -> None:
        """A line in ``calls_file``: the value run and the process that ran it and its parent."""
        if self.calls_file:
            with open(self.calls_file, "a", encoding="utf-8") as handle:
                handle.write(json.dumps({"value": value, "pid": os.getpid(), "parent": os.getppid()}) + "\n")

    def _result(self, sequence: Sequence, states: np.ndarray, tracked: range, seconds: float, info: dict[str, Any]) -> RunResult:
        """The run's result: ``states`` per frame, the ground-truth poses of the ``tracked``
        frames as the trajectory (none when nothing was tracked), one map when any was."""
        trajectory = None
        if len(tracked) and sequence.groundtruth is not None and sequence.groundtruth_is_per_frame:
            trajectory = sequence.groundtruth.select(list(tracked))
        return RunResult(
            system=self.name,
            sequence=sequence.name,
            sensor=sequence.sensor,
            timestamps=sequence.timestamps,
            states=states,
            trajectory=trajectory,
            maps=1 if len(tracked) else 0,
            wall_time_s=seconds,
            track_time_s=0.0,
            info=info,
        )


class BernoulliSlam(FakeSlam):
    """A noisy fake with a known chance of holding: each run tracks every frame with
    probability ``held(value)`` (an expression in ``v``, 0..1), else only ``late`` of them (it
    initialised late, as ORB-SLAM3 does). The draw of run number ``k`` of this instance is
    seeded by ``(seed, k, value)``, so a test knows the truth ``p(v)`` and the runs repeat."""

    name = "bernoulli"
    description = "noisy fake SLAM: every run holds with a known probability p(severity)"

    def __init__(
        self,
        parameter: str = "fog.visibility_m",
        held: str = "1 if v >= 20 else 0.5",
        late: float = 0.5,
        seed: int = 0,
        calls_file: str | None = None,
    ):
        super().__init__(parameter, held, calls_file=calls_file)
        self.late, self.seed = float(late), int(seed)
        self.deterministic = False  # type: ignore[misc]

    def options(self) -> dict[str, Any]:
        return {"parameter": self.parameter, "held": self.tracked, "late": self.late, "seed": self.seed}

    def run(self, sequence: Sequence, workdir: Path, timeout: float | None = None, stop: StopCheck | None = None) -> RunResult:
        """Track every frame, or from ``(1 - late) * n`` on (see the class text)."""
        value = applied_value(sequence, self.parameter)
        p = 1.0 if value is None else float(np.clip(self._share(value), 0.0, 1.0))
        draw = np.random.default_rng([self.seed, self._runs, int(round(1000 * abs(value or 0)))]).random()
        self._runs += 1
        self._record(value)
        n = len(sequence)
        start = 0 if draw < p else int(round(n * (1 - self.late)))
        states = np.full(n, TrackState.OK, dtype=np.int8)
        states[:start] = TrackState.NOT_INITIALISED
        return self._result(sequence, states, range(start, n), 0.0, {"value": value, "held_p": p})


class SleepySlam(FakeSlam):
    """``FakeSlam`` whose every run first sleeps ``sleep_s`` seconds, using no CPU: a system whose
    runs take a fixed time, so a benchmark measures the scheduling (a parallel search, an
    executor's slots) beyond the machine's cores. By default it tracks every frame on the mild
    side of 20 m fog visibility and a quarter of them beyond (``tracking_rate >= 0.5`` fails
    below 20 m); the trajectory it returns is scored like any system's. It pickles with plain
    pickle (its options rebuild it), so it can travel to a Ray worker."""

    name = "sleepy"
    description = "deterministic fake SLAM whose runs sleep a fixed time (for scheduling benchmarks)"

    def __init__(self, parameter: str = "fog.visibility_m", tracked: str = "1 if v >= 20 else 0.25", sleep_s: float = 0.3):
        super().__init__(parameter, tracked)
        self.sleep_s = float(sleep_s)

    def options(self) -> dict[str, Any]:
        return {**super().options(), "sleep_s": self.sleep_s}

    def run(self, sequence: Sequence, workdir: Path, timeout: float | None = None, stop: StopCheck | None = None) -> RunResult:
        start = time.perf_counter()
        time.sleep(self.sleep_s)
        result = super().run(sequence, workdir, timeout)
        return dataclasses.replace(result, wall_time_s=time.perf_counter() - start)

    def __reduce__(self) -> tuple[type, tuple[str, str, float]]:
        return SleepySlam, (self.parameter, self.tracked, self.sleep_s)


class LostWorkerSlam(FakeSlam):
    """A ``FakeSlam`` that loses the process it runs in, as its ``switch`` file says when a run
    starts: ``kill`` (SIGKILL, every run), ``kill-once`` (SIGKILL after writing ``never`` into
    the file, so the retry runs normally) or ``hang`` (sleeps an hour, ignoring the timeout);
    anything else, or no file, runs as ``FakeSlam``. ``calls_file`` gets ``{"lost": ...}`` for
    each run lost. Only for an executor that runs it in a worker process (Ray): here it would
    kill or block the test session itself. ``info["code"]`` of a result is this module's file,
    to show which code the worker imported. The switch's path is an option (a cache key part);
    what the file says is not, so a run lost before can be stored once it runs."""

    name = "lost_worker_fake"

    def __init__(self, switch: str, **options: Any):
        super().__init__(**options)
        self.switch = switch

    def options(self) -> dict[str, Any]:
        return {**super().options(), "switch": self.switch}

    def run(self, sequence: Sequence, workdir: Path, timeout: float | None = None, stop: StopCheck | None = None) -> RunResult:
        switch = Path(self.switch)
        says = switch.read_text(encoding="utf-8").strip() if switch.is_file() else ""
        if says in ("kill", "kill-once", "hang") and self.calls_file:
            with open(self.calls_file, "a", encoding="utf-8") as handle:
                handle.write(json.dumps({"lost": says}) + "\n")
        if says == "kill-once":
            switch.write_text("never", encoding="utf-8")
        if says in ("kill", "kill-once"):
            os.kill(os.getpid(), signal.SIGKILL)
        if says == "hang":
            time.sleep(3600)
        result = super().run(sequence, workdir, timeout)
        return dataclasses.replace(result, info={**result.info, "code": __file__})


class InProcessSlots(Executor):
    """An executor that runs each job in the thread that hands it over and says ``k`` runs fit
    at once: the trial runner and the search bring the threads. For tests and benchmarks of the
    parallel search without Ray (with a system whose runs sleep, the scheduling is measured
    beyond the machine's cores)."""

    name = "in-process"

    def __init__(self, k: int):
        super().__init__()
        self.k = k

    def slots(self, system: SlamSystem) -> int:
        return self.k

    def _run(self, job: RunJob) -> RunRecord:
        return run_job(job)
