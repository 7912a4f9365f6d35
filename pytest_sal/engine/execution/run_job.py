"""One run of a trial as a self-contained job: what an executor sends to wherever the run
happens (this process, or a Ray worker on another machine), and what comes back.

``RunJob`` holds everything the run needs and nothing of the session: the clean sequence
(pickled as its frame sources: image paths, or the synthetic world's class and seed), the
perturbation configured at the trial's severity, the seed, the system, the timeout, the stop rule. ``run_job`` perturbs the
sequence where it runs, runs the system (which keeps its own crash isolation: a segfault or a
timeout is a failed run, never an exception) and scores the trajectory with evo. It returns the
run's ``RunRecord`` with the whole ``RunResult`` (states, trajectory, log tail) and the report
images as PNG bytes. The controller writes those (``store_artifacts``) and the cache entry, so
nothing a remote worker wrote on its own disk is needed afterwards.

The dataset is read where the run happens: ``check_readable`` first stats its folder and first
and last frames there, so a worker that does not see it at the controller's path is one
``DatasetError`` naming the worker and the path. ``failed_output`` is the record of a run that
gave nothing back (a lost Ray worker): a run that tracked nothing, with its reason.
"""

from __future__ import annotations

import math
import os
import signal
import socket
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from pytest_sal.analysis.aggregation import AGGREGATED
from pytest_sal.analysis.metrics import RunMetrics, evaluate
from pytest_sal.engine.execution.early_stop import StopRule
from pytest_sal.engine.outcomes.run_record import RunRecord
from pytest_sal.store.content_cache import ContentCache
from sal_adapters import Sequence, Trajectory
from sal_adapters.common.errors import DatasetError
from sal_modules import Perturbation, perturb
from sal_wrappers import RunResult, SlamSystem, TrackState, machine_load

__all__ = [
    "RunJob",
    "cached_sequence",
    "check_readable",
    "failed_output",
    "machine_failure",
    "run_job",
    "store_artifacts",
    "worker_name",
]


@dataclass(frozen=True)
class RunJob:
    """One run: the system on the dataset perturbed by ``module``.

    Attributes:
        key: the run's cache key, the stop key when ``stop`` is given (names its work folder and
            its artefacts).
        number: the run's number within its trial (0 for the first).
        value: the severity, in the searched parameter's unit (recorded with the run).
        label: what ``value`` is, for the plot title: ``fog.visibility_m = 30 m``.
        dataset: the clean sequence.
        module: the perturbation (a module or a chain) configured at ``value``, or ``None``
            when ``dataset`` is already the sequence to run on (``sal evaluate``'s cached copies).
        system: the SLAM system.
        seed: the perturbation seed.
        workdir: the folder under which the run writes its logs and files.
        timeout: seconds the system may run (``None``: no limit).
        kitti_segments: segment lengths (m) of ``t_rel`` / ``r_rel``.
        artifacts: make the report images (an example frame, a trajectory plot).
        frames_cache: write the perturbed sequence once into this cache folder and run the
            system on the copy read back (``--sal-cache-frames``), or ``None``.
        stop: stop the run once the requirement can no longer hold (given to a ``stoppable``
            system only), or ``None``: run every frame.
    """

    key: str
    number: int
    value: float
    label: str
    dataset: Sequence
    module: Perturbation | None
    system: SlamSystem
    seed: int
    workdir: Path
    timeout: float | None
    kitti_segments: tuple[float, ...]
    artifacts: bool = False
    frames_cache: Path | None = None
    stop: StopRule | None = None


def worker_name() -> str:
    """``host:pid`` of this process: where a run ran, in messages."""
    return f"{socket.gethostname()}:{os.getpid()}"


def run_job(job: RunJob, worker: str | None = None) -> RunRecord:
    """Perturb, run, score: one run of ``job`` in this process (the system may start its own child).
    ``worker`` names where it runs, in messages and in the record (default ``worker_name()``)."""
    worker = worker or worker_name()
    check_readable(job.dataset, worker)
    perturbed = job.dataset if job.module is None else perturb(job.dataset, job.module, seed=job.seed)
    if job.frames_cache is not None:
        perturbed = cached_sequence(perturbed, ContentCache(job.frames_cache))
    groundtruth = perturbed.groundtruth
    load = machine_load()
    stop = {"stop": job.stop} if job.stop is not None and job.system.stoppable else {}  # others never take one
    try:
        if len(perturbed):
            result = job.system.run(perturbed, job.workdir / f"{job.key[:12]}-run{job.number}", timeout=job.timeout, **stop)
        else:  # every frame dropped: no system can run on it
            result = job.system.no_frames_result(perturbed)
    except MemoryError:
        result = _not_initialised(job.system, perturbed, "out of memory (MemoryError)")
    record, scored = _scored_record(job, result, groundtruth, machine_failure(result, load))
    images: dict[str, bytes] = {}
    if job.artifacts:
        if scored.ate is not None and groundtruth is not None:
            images["trajectory"] = _trajectory_png(job, perturbed.name, groundtruth, scored.ate.estimate)
        if len(perturbed):
            images["frame"] = _example_frame_png(perturbed)
    return replace(record, images=images, worker=worker)


def failed_output(job: RunJob, failure: str, not_cached: str | None, worker: str = "") -> RunRecord:
    """The record of a run of ``job`` that gave no result (its worker was lost, it never
    answered): every frame of the clean sequence NOT_INITIALISED, ``failure`` its reason, scored
    like any run; ``not_cached`` (the machine's failure: the next session runs it again) when given."""
    result = _not_initialised(job.system, job.dataset, failure)
    record, _ = _scored_record(job, result, job.dataset.groundtruth, not_cached)
    return replace(record, worker=worker)


def check_readable(dataset: Sequence, worker: str) -> None:
    """``DatasetError`` unless ``dataset``'s files can be read here: its source folder and the
    first and last frame's files (a few ``stat`` calls; a rendered sequence reads no files and
    is not checked). A run reads the dataset where it runs, so every worker must see it at the
    controller's path."""
    frames = dataset.records[0].files + dataset.records[-1].files if len(dataset) else []
    folder = [dataset.source] if dataset.source is not None and frames else []
    for path in folder + frames:
        if not path.exists():
            raise DatasetError(
                f"the dataset {dataset.name} is not readable on worker {worker}: every worker must see the dataset at the same "
                "path as the controller (mount or copy it there)",
                path,
            )


def _not_initialised(system: SlamSystem, sequence: Sequence, failure: str) -> RunResult:
    """A failed run of ``system`` on ``sequence`` that tracked nothing: every frame NOT_INITIALISED."""
    states = np.full(len(sequence), TrackState.NOT_INITIALISED, dtype=np.int8)
    return RunResult(
        system=system.name, sequence=sequence.name, sensor=sequence.sensor, timestamps=sequence.timestamps, states=states, failure=failure
    )


def _scored_record(job: RunJob, result: RunResult, groundtruth: Trajectory | None, not_cached: str | None) -> tuple[RunRecord, RunMetrics]:
    """The run record of ``result`` scored against ``groundtruth`` (``not_cached`` when given;
    the whole ``result`` for the trip back), and the scores themselves."""
    scored = evaluate(result, groundtruth, kitti_segments=job.kitti_segments)
    metrics = scored.to_dict()
    for name in AGGREGATED:  # NaN judges like null, and a stored record holds no NaN
        if metrics[name] is not None and not math.isfinite(metrics[name]):
            metrics[name] = None
    metrics["wall_time_s"] = result.wall_time_s
    metrics["starved"] = result.fell_behind  # the machine could not feed it even re-paced
    metrics["load"] = result.load
    if result.stopped is not None:
        metrics["stopped"] = result.stopped
    module = None if job.module is None else job.module.to_dict()
    record = RunRecord(metrics, value=job.value, module=module, not_cached=not_cached, result=result.to_dict())
    return record, scored


def store_artifacts(record: RunRecord, cache: ContentCache | None, key: str) -> RunRecord:
    """``record`` with its report images written into ``cache`` (``ContentCache.put_artifact``)
    as ``<key>.png`` (the frame) and ``<key>-trajectory.png``, named in ``artifacts`` (none when
    ``cache`` is ``None``, nor those it cannot write)."""
    artifacts: dict[str, str] = {}
    if cache is not None:
        for name, data in sorted(record.images.items()):
            path = cache.put_artifact(f"{key}.png" if name == "frame" else f"{key}-{name}.png", data)
            if path is not None:
                artifacts[name] = str(path)
    return replace(record, artifacts=artifacts, images={})


#: A timed-out run that had less than this share of one core over its wall time was stalled by
#: the machine (a stopped process, a frozen VM, a throttled container), not too slow: a run
#: too slow to finish uses its time (ORB-SLAM3 paced at the sensor rate: 0.4-1.5 cores).
STALLED_CPU_SHARE = 0.25

#: Words in a failure or log tail that say the run ran out of memory (Python, C++).
_OUT_OF_MEMORY = ("MemoryError", "std::bad_alloc")


def machine_failure(result: RunResult, load: dict[str, Any]) -> str | None:
    """Why the machine, not the system, decided a failed run (it is then not cached), or ``None``.

    The rule: a run that timed out (``failure`` starts with "timed out") is the machine's when
    it fell behind the sensor clock (``RunResult.fell_behind``: starved even re-paced), when it
    got less than ``STALLED_CPU_SHARE`` of a core over its time (``info["cpu_at_timeout_s"]``,
    the CPU its processes had had at the deadline, against its wall time: it was stopped,
    frozen or throttled, whatever the load average said), or when the machine was busier than
    its cores when it started (``load``, a ``machine_load()`` taken before the run: 1-minute
    load average above the usable cores); a timeout that used its time on a quiet machine is
    the system's (it is too slow) and is cached. A system that hangs idle is thus not cached:
    it costs its timeout again next session, never a wrong verdict. A run killed by SIGKILL without a timeout
    (the kernel's out-of-memory killer), or whose failure or log ends in ``MemoryError`` or
    ``std::bad_alloc``, ran out of memory: the machine's.
    """
    failure = result.failure
    if failure is None:
        return None
    if failure.startswith("timed out"):
        if result.fell_behind:
            return f"timed out while starved: it fell behind the sensor clock ({result.load.get('fell_behind_reason')})"
        cpu = result.info.get("cpu_at_timeout_s")
        if cpu is not None and result.wall_time_s > 0 and cpu < STALLED_CPU_SHARE * result.wall_time_s:
            return (
                f"timed out while stalled: it had {cpu:.1f} s of CPU in its {result.wall_time_s:.1f} s "
                f"(less than {STALLED_CPU_SHARE:g} of a core: stopped, frozen or throttled)"
            )
        cores = int(load.get("usable_cpus") or load["cpus"])
        if float(load["loadavg"][0]) > cores:
            return f"timed out on a busy machine: load average {float(load['loadavg'][0]):.1f} on {cores} cores when it started"
        return None
    if result.exit_status == -signal.SIGKILL:
        return "killed by SIGKILL without a timeout: the out-of-memory killer, most likely"
    if any(word in failure or word in result.log_tail for word in _OUT_OF_MEMORY):
        return "ran out of memory"
    return None


def cached_sequence(sequence: Sequence, cache: ContentCache, *, progress: bool = False) -> Sequence:
    """``sequence`` written once into ``cache`` (keyed by its fingerprint, which for a
    perturbed sequence covers source, chain, seed and depth provider) and opened from there;
    ``progress`` shows a bar while it is written."""
    from pytest_sal.store.cache_keys import cache_key
    from sal_adapters import DATASETS, open_dataset, write_sequence

    def fill(target: Path) -> None:
        write_sequence(sequence, target, progress=progress)

    folder, _ = cache.compute_dir(cache_key(frames=sequence.fingerprint), fill)
    options = {"stereo": True} if sequence.sensor == "stereo" and "stereo" in DATASETS.get(sequence.kind).option_names() else {}
    reopened = open_dataset(sequence.kind, folder, **options)
    return reopened.replace(name=sequence.name, meta=dict(reopened.meta, perturbation=sequence.meta.get("perturbation")))


def _trajectory_png(job: RunJob, sequence_name: str, groundtruth: Any, estimate: Any) -> bytes:
    """The estimated trajectory over the ground truth, as PNG bytes."""
    import tempfile

    from pytest_sal.analysis.plots import plot_trajectories

    title = f"{job.system.name} on {sequence_name}, {job.label}"
    with tempfile.TemporaryDirectory(prefix="sal-plot-") as tmp:
        path = plot_trajectories(groundtruth, {job.system.name: estimate}, Path(tmp) / "trajectory.png", title=title)
        return Path(path).read_bytes()


def _example_frame_png(sequence: Sequence, width: int = 480) -> bytes:
    """The middle frame of ``sequence``, scaled to ``width`` px, as PNG bytes (for reports)."""
    from sal_adapters.images import scaled_to_width

    image = scaled_to_width(sequence[len(sequence) // 2].image, width)
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise ValueError(f"could not encode the example frame of {sequence.name} as PNG")
    return data.tobytes()
