"""One trial: perturb the dataset at one severity, run the system ``runs`` times, score each
run with evo, aggregate, and judge the requirement. Results are cached content-addressed.

The cache key holds everything that changes a trial's result: the dataset fingerprint, the
configured module (name, version, every parameter), the seed, the system (name, version,
options), the number of runs and the runner version. An identical trial in a later session,
or in the other xdist worker, is read back instead of run again.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pytest_sal.cache import ContentCache
from pytest_sal.cache_keys import cache_key
from pytest_sal.metrics import evaluate
from pytest_sal.outcome import Trial
from pytest_sal.requirements import Requirement
from sal_adapters import Sequence
from sal_modules import perturb
from sal_modules.refs import ParamRef
from sal_wrappers import SlamSystem

__all__ = ["RUNNER_VERSION", "TrialRunner", "aggregate_metrics", "cached_sequence"]

#: Bumped when a change here changes cached trial results.
RUNNER_VERSION = 1
#: Metrics aggregated over runs (median) into a trial's metrics.
TRIAL_METRICS = ("ate_rmse", "rpe_trans", "rpe_rot", "tracking_rate", "scale_error", "first_tracked", "maps")


def aggregate_metrics(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Median of each metric over the runs. A metric missing (``None``) in more than half of
    the runs is ``None``: a run that crashed or tracked nothing counts against the trial."""
    out: dict[str, Any] = {}
    for name in TRIAL_METRICS:
        values = [r.get(name) for r in runs]
        known = [float(v) for v in values if v is not None and math.isfinite(float(v))]
        out[name] = float(np.median(known)) if known and 2 * len(known) > len(values) else None
    out["failures"] = [r["failure"] for r in runs if r.get("failure")]
    return out


@dataclass
class TrialRunner:
    """Runs trials of one robustness test.

    Args:
        dataset: the clean sequence.
        ref: the searched parameter (``fog.visibility_m``); values are in its search unit.
        system: the SLAM system under test.
        requirement: judges each trial's aggregated metrics.
        runs: runs per trial (the metrics are the median over them).
        seed: perturbation seed (the same random pattern at every severity).
        cache: the trial cache, or ``None`` to always run.
        workdir: where runs write their logs and files.
        timeout: seconds per run.
        artifacts: also store an example frame and a trajectory plot with each computed trial
            (for the HTML report; trials read from the cache keep what they were stored with).
        cache_frames: write each perturbed sequence once into the cache, in its dataset's
            layout, and give systems the copy read back from there: the same severity is then
            perturbed once for every system and session (worth it for several systems or an
            external ``command`` system; writing costs about 25-45 ms a frame).
    """

    dataset: Sequence
    ref: ParamRef
    system: SlamSystem
    requirement: Requirement
    runs: int = 1
    seed: int = 0
    cache: ContentCache | None = None
    workdir: Path = Path(".")
    timeout: float | None = 600.0
    artifacts: bool = False
    cache_frames: bool = False

    def module_value(self, value: float) -> Any:
        """The module's parameter value for search value ``value`` (``canonicalize``)."""
        scale = self.ref.param.search
        return scale.canonicalize(value) if scale is not None else value

    def key(self, value: float, attempt: int = 0) -> str:
        module = self.ref.module(self.module_value(value))
        repeat = {"attempt": attempt} if attempt else {}  # a repeat is its own trial, not the first one's cache entry
        return cache_key(
            runner=RUNNER_VERSION,
            dataset=self.dataset.fingerprint,
            module=module.to_dict(),
            seed=self.seed,
            system=self.system.identity(),
            runs=self.runs,
            **repeat,
        )

    def evaluate(self, value: float, attempt: int = 0) -> Trial:
        """The trial at search value ``value`` (from the cache when it was run before);
        ``attempt`` > 0: a repeat of it (the flakiness check), run and cached apart."""
        start = time.perf_counter()
        key = self.key(value, attempt)
        if self.cache is None:
            data, cached = self._run(value, key), False
        else:
            data, cached = self.cache.compute(key, lambda: self._run(value, key))
        metrics = data["metrics"]
        return Trial(
            value=float(value),
            passed=self.requirement.holds(metrics),
            metrics=metrics,
            runs=data["runs"],
            cached=cached,
            wall_time_s=time.perf_counter() - start,
            failed=[str(c) for c in self.requirement.failed(metrics)],
            artifacts=dict(data.get("artifacts", {})),
        )

    def _run(self, value: float, key: str) -> dict[str, Any]:
        module = self.ref.module(self.module_value(value))
        perturbed = perturb(self.dataset, module, seed=self.seed)
        if self.cache_frames and self.cache is not None:
            perturbed = cached_sequence(perturbed, self.cache)
        groundtruth = perturbed.groundtruth
        runs = []
        artifacts: dict[str, str] = {}
        folder = self.cache.root / "artifacts" if self.cache is not None and self.artifacts else None
        for number in range(self.runs):
            result = self.system.run(perturbed, self.workdir / f"{key[:12]}-run{number}", timeout=self.timeout)
            scored = evaluate(result, groundtruth)
            metrics = scored.to_dict()
            metrics["wall_time_s"] = result.wall_time_s
            runs.append(metrics)
            if folder is not None and number == 0 and scored.ate is not None and groundtruth is not None:
                from pytest_sal.plots import plot_trajectories

                title = f"{self.system.name} on {perturbed.name}, {self.ref.label} = {value:g} {self.ref.unit}".rstrip()
                artifacts["trajectory"] = str(plot_trajectories(groundtruth, {self.system.name: scored.ate.estimate}, folder / f"{key}-trajectory.png", title=title))
        if folder is not None and len(perturbed):
            artifacts["frame"] = str(_example_frame(perturbed, folder / f"{key}.png"))
        return {"value": value, "module": module.to_dict(), "metrics": aggregate_metrics(runs), "runs": runs, "artifacts": artifacts}


def cached_sequence(sequence: Sequence, cache: ContentCache, *, progress: bool = False) -> Sequence:
    """``sequence`` written once into ``cache`` (keyed by its fingerprint, which for a
    perturbed sequence covers source, chain, seed and depth provider) and opened from there;
    ``progress`` shows a bar while it is written."""
    from sal_adapters import DATASETS, open_dataset, write_sequence

    folder, _ = cache.compute_dir(cache_key(frames=sequence.fingerprint), lambda target: write_sequence(sequence, target, progress=progress))
    options = {"stereo": True} if sequence.sensor == "stereo" and "stereo" in DATASETS.get(sequence.kind).option_names() else {}
    reopened = open_dataset(sequence.kind, folder, **options)
    return reopened.replace(name=sequence.name, meta=dict(reopened.meta, perturbation=sequence.meta.get("perturbation")))


def _example_frame(sequence: Sequence, path: Path, width: int = 480) -> Path:
    """The middle frame of ``sequence``, scaled to ``width`` px, as a PNG (for reports)."""
    from sal_adapters.images import scaled_to_width, write_image

    path.parent.mkdir(parents=True, exist_ok=True)
    write_image(path, scaled_to_width(sequence[len(sequence) // 2].image, width))
    return path
