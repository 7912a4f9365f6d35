"""One pytest session's pytest-sal state: its options (``pytest_sal.options``), the trial cache
and the run history, the default dataset and system, and the searches of its robustness tests;
the outcomes, reports and summary at its end are ``pytest_sal.session_results``."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from pytest_sal.api import requirement_of
from pytest_sal.options import read_options
from pytest_sal.session_results import SessionResults

if TYPE_CHECKING:
    from pytest_sal.engine.execution.executor import Executor
    from pytest_sal.history.run_history import History
    from pytest_sal.store.content_cache import ContentCache

__all__ = ["SAL_SESSION", "SalSession"]

#: The session object, in ``config.stash``.
SAL_SESSION = pytest.StashKey["SalSession"]()

#: Frames of the default synthetic worlds (short enough for CI, long enough to track).
DEFAULT_FRAMES = {"urban": 60, "indoor": 90}
#: Modules whose tests default to the urban street (weather and light); others to the room.
OUTDOOR_MODULES = {"fog", "rain", "snow", "night", "sun_glare", "motion_blur"}


class SalSession:
    """One pytest session's pytest-sal state (also a plugin: it collects outcomes)."""

    def __init__(self, config: pytest.Config):
        self.config = config
        self.options = read_options(config)
        self.results = SessionResults(config, self.options)
        self._machine: str | None = None
        self._cache: ContentCache | None = None
        self._history: History | None = None
        self._executor: Executor | None = None
        self._datasets: dict[str, Any] = {}
        #: a noisy system's trials so far, per family (system, dataset, parameter and seed: ``outcome``)
        self._noisy_trials: dict[str, dict[float, Any]] = {}

    @property
    def runs(self) -> int | None:
        """The most runs per trial (ini ``sal_runs``; ``None``: auto), the ``sal_runs`` fixture's default."""
        return self.options.runs

    # -- collaborators -------------------------------------------------------------------------
    @property
    def cache(self) -> ContentCache | None:
        """The trial cache (``None`` under ``--sal-no-cache``), opened when first needed."""
        if self._cache is None and self.options.use_cache:
            from pytest_sal.store.content_cache import ContentCache

            self._cache = ContentCache(self.options.cache_dir, self.options.cache_size)
        return self._cache

    def executor(self) -> Executor:
        """Where runs happen (``--sal-executor``), made when first needed; a local Ray starts
        on its first run, not here. A method, not a property: pytest 8.0 reads every attribute
        of a registered plugin, which would make it (and import numpy) in every session."""
        if self._executor is None:
            from pytest_sal.engine.execution.executor_factory import make_executor

            # every xdist worker counts on its share of the cluster when it decides how many runs to send at once
            share = {"share": int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))} if self.options.executor == "ray" else {}
            self._executor = make_executor(self.options.executor, self.options.ray_address, **share)
        return self._executor

    @pytest.hookimpl(optionalhook=True)
    def pytest_configure_node(self, node: Any) -> None:
        """pytest-xdist (controller): every worker submits to one Ray cluster. A local Ray is
        started here once and its address handed to the workers, so ``-n N`` lets N tests
        submit at once without N clusters."""
        if self.options.executor == "ray" and not self.options.ray_address:
            executor = self.executor()
            executor.connect()  # type: ignore[attr-defined]
            node.workerinput["sal_ray_address"] = executor.address  # type: ignore[attr-defined]

    def close(self) -> None:
        """Release the executor (shut down a local Ray this process started)."""
        if self._executor is not None:
            self._executor.close()

    @property
    def history(self) -> History:
        """The run history, opened when first needed."""
        if self._history is None:
            from pytest_sal.history.run_history import History

            self._history = History(self.options.history_dir)
        return self._history

    def default_dataset(self, ref: Any) -> Any:
        """The synthetic world suiting the perturbation of ``ref`` (opened once per session)."""
        module = getattr(getattr(ref, "param", None), "owner", None)
        scene = "urban" if getattr(module, "name", "") in OUTDOOR_MODULES else "indoor"
        if scene not in self._datasets:
            from sal_adapters import open_dataset

            sensor = "stereo" if scene == "urban" else "rgbd"
            self._datasets[scene] = open_dataset("synthetic", scene=scene, frames=DEFAULT_FRAMES[scene], sensor=sensor)
        return self._datasets[scene]

    def default_system_name(self) -> str:
        """ini ``sal_system``, else ``orbslam3`` when ``pyorbslam3`` is installed, else ``reference_vo``."""
        if self.options.system_name:
            return self.options.system_name
        import importlib.util

        return "orbslam3" if importlib.util.find_spec("pyorbslam3") else "reference_vo"

    def default_system(self) -> Any:
        from sal_wrappers import create

        return create(self.default_system_name())

    # -- running -------------------------------------------------------------------------------
    def outcome(self, item: pytest.Item, dataset: Any, system: Any, runs: int | None, workdir: Path, level: Any = None) -> Any:
        """The outcome of ``item``: its ``Search`` (the boundary search of its requirement from
        the previous boundary, ``_start_from``, or the one value of its ``sal.sweep`` ``level``)
        run by ``run_search`` with the session's cache and executor; under ``-v`` each trial is
        printed as it ends; compared with the history when asked."""
        from pytest_sal.engine.search.requirement_search import Search, run_search
        from pytest_sal.history.regression import warm_start
        from pytest_sal.progress import trial_printer
        from pytest_sal.report.outcome_report import trial_metric_names
        from pytest_sal.store.cache_keys import cache_key

        requirement = requirement_of(item)
        assert requirement is not None  # the fixtures run only for tests with a sal.require mark
        where: dict[str, Any]  # the Search's warm_start, or its point
        if level is None:
            envelope = requirement.envelope
            assert envelope is not None  # collection refuses a sal.require without one unless sal.sweep / sal.at is above it
            ref, previous = envelope.ref, self._start_from((item.nodeid, system.name, dataset.name))
            where = {"warm_start": warm_start(previous, parameter=ref.label, edge=envelope.value, worse=ref.param.worse)}
        else:
            ref, _, value = level
            where = {"point": value}
        seed = int(requirement.options.get("seed", self.options.seed))
        # runs of one family are interchangeable between requirements (their records are metrics, judged by each requirement)
        family = cache_key(system=system.identity(), dataset=dataset.fingerprint, parameter=ref.label, seed=seed)
        search = Search(
            dataset,
            ref,
            system,
            requirement,
            item.nodeid,
            self.options.search,
            runs=runs,
            seed=seed,
            timeout=self.options.timeout,
            workdir=workdir,
            artifacts=bool(self.options.report_html or getattr(self.config.option, "htmlpath", None)),  # ours or pytest-html's
            cache_frames=self.options.cache_frames,
            kitti_segments=self.options.kitti_segments,
            early_stop=self.options.early_stop,
            earlier=tuple(self._earlier(family)),
            **where,
        )
        metrics = trial_metric_names(requirement.criteria_rows())  # as the reports show them
        progress = trial_printer(self.config, item.nodeid, ref.label, ref.unit, metrics)
        return self._finished(run_search(search, self.cache, self.executor(), progress), system, family)

    def _earlier(self, family: str) -> list[Any]:
        """The noisy system's trials of ``family`` run earlier in this session (every run counts)."""
        return list(self._noisy_trials.get(family, {}).values())

    def _start_from(self, key: tuple[str, str, str]) -> Any:
        """The outcome whose boundary the search tries first: the baseline's under
        ``--sal-compare``, else the last run's (``None`` when the history has neither)."""
        from sal_adapters.common.errors import SalError

        if not self.options.history_dir.is_dir():
            return None
        try:
            return self.history.previous(key, self.options.compare or "last")
        except SalError:  # the baseline is missing: the comparison says so
            return self.history.previous(key, "last")

    @property
    def machine(self) -> str:
        """This machine in words (``history.provenance.machine_text``), read once."""
        if self._machine is None:
            from pytest_sal.history.provenance import machine_info, machine_text

            self._machine = machine_text(machine_info())
        return self._machine

    def _finished(self, outcome: Any, system: Any, family: str) -> Any:
        """``outcome`` with where it ran and, under ``--sal-compare``, compared with its baseline;
        a noisy system's trials kept for the next requirement of the same ``family``."""
        if outcome.boundary.noisy:
            kept = self._noisy_trials.setdefault(family, {})
            for trial in outcome.trials:
                if len(trial.runs) >= len(kept[trial.value].runs if trial.value in kept else ()):
                    kept[trial.value] = trial
        outcome.machine = self.machine
        outcome.system_version = system.version_text()
        if self.options.compare is None:
            return outcome
        from pytest_sal.history.gate import compare_with_baseline

        return compare_with_baseline(outcome, self.history, self.options.compare, self.options.checks, missing=self.options.compare_missing)

    # -- the end (controller) --------------------------------------------------------------------
    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        self.results.collect(report)

    def terminal_summary(self, terminal: Any) -> None:
        self.results.terminal_summary(terminal)

    def finish(self) -> None:
        """Write the history and the reports (``SessionResults.finish``)."""
        self.results.finish()
