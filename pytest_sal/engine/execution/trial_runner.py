"""One trial: perturb the dataset at one severity, run the system, score each run with evo,
and judge the requirement by its runs. Runs are cached content-addressed, one by one.

A deterministic system (``reference_vo``) gets one run per trial (``run_trial``), and the
boundary search bisects on its verdicts. A noisy one (ORB-SLAM3 is multi-threaded and uses
RANSAC: about one run in six splits its map on a clean 51-frame KITTI sequence) is searched by
``pytest_sal.engine.search.reliability_search``, which places its runs with ``add_runs``
(``RunPolicy``: whether a system is noisy). A trial's metrics are the median over its runs; its
verdict is the majority of the runs that did not abstain.

The cache key of a run holds everything that changes its result: the dataset fingerprint, the
configured module (name, version, every parameter), the seed, the system's identity (name,
version, options, the content of the files it runs), the run's number and the runner version.
An identical run in a later session, or in the other xdist worker, is read back instead of
run again; a trial that needs more runs than were cached runs only the missing ones. A stored
run whose entry lacks what the judge reads (``RunRecord.entry_problem``) is discarded and run again.
A run whose failure the machine decided (``run_job.machine_failure``: a timeout on a starved or
oversubscribed machine, out of memory) counts in this session and is not stored, so the next
session runs it again; its run says why under ``not_cached``.

Early stop (``early_stop``, on by default): a ``stoppable`` system is given the requirement's
``StopRule`` and stops a run once a criterion can no longer hold; the run's metrics say why
under ``stopped`` and its verdict is the full run's (failed). A stopped record is valid only
for requirements whose rule stops it, so the cache keeps it apart: a run looks up its full key
(a run that finished serves every requirement), then the key with the rule's criteria
(``key(value, number, stop=rule)``); a run that finishes is stored under the full key, a
stopped one under the rule's. Keys of full runs are those without early stop.
"""

from __future__ import annotations

import functools
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from pytest_sal.analysis.kitti_metrics import KITTI_SEGMENTS_M
from pytest_sal.engine.execution.early_stop import StopRule
from pytest_sal.engine.execution.executor import Executor, LocalExecutor
from pytest_sal.engine.execution.run_job import RunJob, store_artifacts
from pytest_sal.engine.outcomes.outcome import Trial, TrialMetrics
from pytest_sal.engine.outcomes.run_record import RunRecord
from pytest_sal.engine.requirements import Requirement
from pytest_sal.store.cache_keys import cache_key
from pytest_sal.store.content_cache import ContentCache
from sal_adapters import Sequence
from sal_modules import Perturbation, perturb
from sal_modules.params import ParamRef
from sal_wrappers import SlamSystem

__all__ = [
    "NOISY_RUNS",
    "RUNNER_VERSION",
    "RunPolicy",
    "TrialRunner",
]

#: Bumped when a change here changes cached results (2: one cache entry per run; 3: entries
#: carry a checksum, so entries of 2 are left to eviction and ``sal cache clear``; 4: records
#: carry t_rel / r_rel and keys the KITTI segment lengths they were scored with; 5: entries name
#: their key (issue 23), so entries of 4, which would each be refused with a warning, are left
#: to eviction and ``sal cache clear``).
RUNNER_VERSION = 5


@dataclass(frozen=True)
class RunPolicy:
    """Whether a system is noisy, and the most runs per trial it is given.

    Attributes:
        max_runs: the most runs per trial (1: a deterministic system, one run a trial; above
            1: a noisy one, searched by ``pytest_sal.engine.search.reliability_search``).
    """

    max_runs: int = 1

    @classmethod
    def for_system(cls, system: SlamSystem, runs: int | None) -> RunPolicy:
        """``runs`` when given (the most runs per trial), else 1 for a deterministic system
        and ``NOISY_RUNS`` for a noisy one."""
        if runs is None:
            runs = 1 if getattr(system, "deterministic", False) else NOISY_RUNS
        return cls(max_runs=int(runs))

    @property
    def noisy(self) -> bool:
        """More than one run per trial: ``runs`` given above 1, or a system that is not
        ``deterministic`` with ``runs`` not given."""
        return self.max_runs > 1


#: Most runs per trial of a noisy system when ``sal_runs`` is not set.
NOISY_RUNS = 5


@dataclass
class TrialRunner:
    """Runs trials of one robustness test.

    Args:
        dataset: the clean sequence.
        ref: the searched parameter (``fog.visibility_m``); values are in its unit.
        system: the SLAM system under test.
        requirement: judges each run's metrics.
        runs: the most runs per trial (``None``: 1 for a deterministic system, else
            ``NOISY_RUNS``); above 1 the system is noisy (``RunPolicy``).
        seed: perturbation seed (the same random pattern at every severity).
        cache: the run cache, or ``None`` to always run.
        workdir: where runs write their logs and files.
        timeout: seconds per run.
        artifacts: also store an example frame and a trajectory plot with each computed trial
            (for the HTML report; runs read from the cache keep what they were stored with).
        cache_frames: write each perturbed sequence once into the cache, in its dataset's
            layout, and give systems the copy read back from there: the same severity is then
            perturbed once for every system and session (worth it for several systems or an
            external ``command`` system; writing costs about 25-45 ms a frame).
        progress: called with the trial each time runs are added to it (from one thread at
            a time).
        kitti_segments: segment lengths (m) of ``t_rel`` / ``r_rel`` (ini ``sal_kitti_segments``).
        executor: where runs that are not cached happen (``LocalExecutor``: here, one at a
            time); the runs of one ``add_runs`` go to it together.
        early_stop: stop a run of a ``stoppable`` system once the requirement can no longer
            hold (``StopRule``; see the module text); ``False``: every run runs every frame.
    """

    dataset: Sequence
    ref: ParamRef
    system: SlamSystem
    requirement: Requirement
    runs: int | None = None
    seed: int = 0
    cache: ContentCache | None = None
    workdir: Path = Path(".")
    timeout: float | None = 600.0
    artifacts: bool = False
    cache_frames: bool = False
    progress: Callable[[Trial], None] | None = None
    kitti_segments: tuple[float, ...] = KITTI_SEGMENTS_M
    executor: Executor = field(default_factory=LocalExecutor)
    early_stop: bool = True

    def __post_init__(self) -> None:
        self.policy = RunPolicy.for_system(self.system, self.runs)
        self._progress_lock = threading.Lock()
        self._modules: dict[float, Perturbation] = {}
        self._modules_lock = threading.Lock()
        stoppable = self.early_stop and self.system.stoppable
        #: what stops this requirement's runs early (``None``: they run every frame)
        self.stop_rule = StopRule.of(self.requirement) if stoppable else None

    def module(self, value: float) -> Perturbation:
        """The module (or chain) at ``value``, built and validated once per value: the cache
        keys, the run jobs and ``unchanged_frames`` share it."""
        with self._modules_lock:
            if value not in self._modules:
                self._modules[value] = self.ref.module(value)
            return self._modules[value]

    def key(self, value: float, number: int = 0, stop: StopRule | None = None) -> str:
        """Cache key of run ``number`` at ``value``; with ``stop``, of the run stopped by that rule."""
        parts: dict[str, Any] = {} if stop is None else {"stop": stop.key()}
        return cache_key(
            runner=RUNNER_VERSION,
            dataset=self.dataset.fingerprint,
            module=self.module(value).to_dict(),
            seed=self.seed,
            system=self.system.identity(),
            run=number,
            kitti_segments_m=self.kitti_segments,
            **parts,
        )

    def unchanged_frames(self, value: float) -> list[int] | None:
        """The positions checked when the module at ``value`` leaves the first, middle and last
        frame as they were (both cameras), else ``None``. "As they were" allows rounding: no
        pixel moves by more than 1 grey level and fewer than 1 % of them move at all (fog at
        100 km in a 5 m room: 0.1 % by 1 level). Modules that work on the whole sequence at
        once (video coding) are not checked: it would cost a full encode."""
        module = self.module(value)
        steps = getattr(module, "steps", (module,))
        if any(step.whole_sequence for step in steps):
            return None
        perturbed = perturb(self.dataset, module, seed=self.seed)
        if len(perturbed) != len(self.dataset):
            return None
        positions = sorted({0, len(self.dataset) // 2, len(self.dataset) - 1})
        for i in positions:
            clean, changed = self.dataset[i], perturbed[i]
            if not _same(clean.image, changed.image) or not _same(clean.right, changed.right):
                return None
        return positions

    def cached(self, value: float) -> bool:
        """The first run at ``value`` is in the cache: a trial there costs no run (``run_cached``)."""
        return self.run_cached(value, 0)

    def run_trial(self, value: float) -> Trial:
        """The trial at ``value`` of a deterministic system: one run."""
        trial = Trial(value=float(value), passed=False)
        self._extend(trial)
        return trial

    def _extend(self, trial: Trial) -> None:
        """The first run of ``trial`` when it has none (a trial read back without its runs)."""
        if not trial.runs:
            start = time.perf_counter()
            self._append_runs(trial, 1)
            self._summarise(trial, time.perf_counter() - start)

    def add_runs(self, trial: Trial, count: int) -> tuple[RunRecord, ...]:
        """``count`` more runs of ``trial`` (numbered on from its runs), together; the new runs,
        judged. A noisy system's search
        (``pytest_sal.engine.search.reliability_search``) places its runs with this."""
        start = time.perf_counter()
        first = len(trial.runs)
        self._append_runs(trial, count)
        self._summarise(trial, time.perf_counter() - start)
        return trial.runs[first:]

    def run_cached(self, value: float, number: int) -> bool:
        """Run ``number`` at ``value`` is in the cache (finished, or stopped by this runner's
        rule): it costs no run. Only looks for the entry's file."""
        if self.cache is None:
            return False
        keys = [self.key(value, number)] + ([] if self.stop_rule is None else [self.key(value, number, stop=self.stop_rule)])
        return any(self.cache.path(key).is_file() for key in keys)

    def _append_runs(self, trial: Trial, count: int) -> None:
        """Run (or read back) the next ``count`` runs of ``trial`` at once, judge them and append them."""
        numbers = range(len(trial.runs), len(trial.runs) + count)
        if count == 1:
            results = [self._cached_run(trial.value, numbers[0])]
        else:
            with ThreadPoolExecutor(max_workers=count, thread_name_prefix="sal-run") as pool:
                results = list(pool.map(functools.partial(self._cached_run, trial.value), numbers))
        runs = [record.judged(self.requirement.holds(record.metrics), cached) for record, cached in results]
        trial.runs = (*trial.runs, *runs)
        for run in runs:
            trial.artifacts.update({k: v for k, v in run.artifacts.items() if k not in trial.artifacts})

    def _summarise(self, trial: Trial, seconds: float) -> None:
        """The trial's metrics, verdict and time from its runs; reported to ``progress``."""
        trial.metrics = TrialMetrics.of(trial.runs)
        trial.passed = trial.passes > trial.fails
        trial.cached = all(r.cached for r in trial.runs)
        trial.failed = [str(c) for c in self.requirement.failed(trial.metrics)]
        trial.wall_time_s += seconds
        if self.progress is not None:
            with self._progress_lock:
                self.progress(trial)

    def _cached_run(self, value: float, number: int) -> tuple[RunRecord, bool]:
        """``(record, was_cached)`` of run ``number`` at ``value``: read from the cache, or run by
        the executor and stored (unless the machine decided its failure)."""
        key, rule = self.key(value, number), self.stop_rule
        if self.cache is None:
            return self._execute(value, key if rule is None else self.key(value, number, rule), number, rule), False
        if rule is None:
            compute = functools.partial(self._entry, value, key, number, None)
            data, cached = self.cache.compute(key, compute, check=RunRecord.entry_problem, transient=_not_cached)
            return RunRecord.from_entry(data), cached
        full = self.cache.get(key, check=RunRecord.entry_problem)
        if full is not None:
            return RunRecord.from_entry(full), True
        return self._stoppable_run(value, number, key, rule)

    def _stoppable_run(self, value: float, number: int, key: str, rule: StopRule) -> tuple[RunRecord, bool]:
        """``(record, was_cached)`` of a run ``rule`` may stop, under the lock of its stop key: read
        back (stopped, or finished while this waited for the lock), or run; a finished run is
        stored under the full ``key``, a stopped one under the stop key (see the module text)."""
        cache = self.cache
        assert cache is not None  # only called with a cache
        read_back: list[bool] = []

        def run() -> dict[str, Any]:
            full = cache.get(key, check=RunRecord.entry_problem)
            if full is not None:
                read_back.append(True)
                return full
            data = self._entry(value, stop_key, number, rule)
            if "stopped" not in data["metrics"] and _not_cached(data) is None:
                cache.put(key, data)
            return data

        def kept_apart(data: dict[str, Any]) -> str | None:
            return _not_cached(data) or (None if "stopped" in data["metrics"] else "it finished: stored under its full key")

        stop_key = self.key(value, number, rule)
        data, cached = cache.compute(stop_key, run, check=RunRecord.entry_problem, transient=kept_apart)
        return RunRecord.from_entry(data), cached or bool(read_back)

    def _entry(self, value: float, key: str, number: int, stop: StopRule | None) -> dict[str, Any]:
        """The cache entry of run ``number`` at ``value`` (``_execute``)."""
        return self._execute(value, key, number, stop).entry()

    def _execute(self, value: float, key: str, number: int, stop: StopRule | None) -> RunRecord:
        """Run ``number`` at ``value`` on the executor (stopped early by ``stop``); its report
        images (first run of a trial) are written here, on the controller, under the cache's
        ``artifacts`` folder, named by ``key``."""
        job = RunJob(
            key=key,
            number=number,
            value=value,
            label=f"{self.ref.label} = {value:g} {self.ref.unit}".rstrip(),
            dataset=self.dataset,
            module=self.module(value),
            system=self.system,
            seed=self.seed,
            workdir=self.workdir,
            timeout=self.timeout,
            kitti_segments=self.kitti_segments,
            artifacts=self.artifacts and self.cache is not None and number == 0,
            frames_cache=self.cache.root if self.cache_frames and self.cache is not None else None,
            stop=stop,
        )
        return store_artifacts(self.executor.run(job), self.cache if job.artifacts else None, key)


def _not_cached(entry: dict[str, Any]) -> str | None:
    """Why a run's cache entry must not be stored (``pytest_sal.engine.execution.run_job.failed_output``
    sets it): the machine decided it."""
    return entry.get("not_cached")


def _same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    """Equal up to rounding: at most 1 grey level apart, and on fewer than 1 % of the values."""
    if a is None or b is None:
        return a is None and b is None
    if a.shape != b.shape:
        return False
    change = cv2.absdiff(a, b)
    return int(change.max(initial=0)) <= 1 and bool(np.count_nonzero(change) < 0.01 * change.size)
