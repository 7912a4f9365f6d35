"""Session state of pytest-sal: options, the trial cache, the history, the outcomes collected
on the controller, the summary table and the reports written at the end."""

from __future__ import annotations

import argparse
import json
import math
import os
from pathlib import Path
from typing import Any

import pytest

__all__ = ["SAL_SESSION", "SalSession", "add_options", "outcome_of"]

#: The session object, in ``config.stash``.
SAL_SESSION = pytest.StashKey["SalSession"]()

#: Frames of the default synthetic worlds (short enough for CI, long enough to track).
DEFAULT_FRAMES = {"urban": 60, "indoor": 90}
#: Modules whose tests default to the urban street (weather and light); others to the room.
OUTDOOR_MODULES = {"fog", "rain", "snow", "night", "sun_glare", "motion_blur"}


def _compare_fail(text: str) -> Any:
    from pytest_sal.regression import parse_compare_fail

    return parse_compare_fail(text)


#: ini options read as numbers: (type, smallest value, whether the smallest is excluded, what it is)
_INI_NUMBERS: dict[str, tuple[type, float, bool, str]] = {
    "sal_runs": (int, 1, False, "a whole number >= 1 (the most runs per trial), or auto"),
    "sal_seed": (int, 0, False, "a whole number >= 0 (perturbation seed)"),
    "sal_max_trials": (int, 1, False, "a whole number >= 1 (trials per boundary search)"),
    "sal_tolerance": (float, 0.0, True, "a number > 0 (percent of the boundary value)"),
    "sal_timeout": (float, 0.0, True, "a number > 0 (seconds per SLAM run)"),
}


def _ini_number(config: pytest.Config, name: str) -> Any:
    """The ini option ``name`` as its number, or a usage error that names it and what it takes."""
    kind, smallest, exclusive, what = _INI_NUMBERS[name]
    text = str(config.getini(name)).strip()
    try:
        value = kind(text)
    except ValueError:
        value = None
    if value is None or not math.isfinite(value) or value < smallest or (exclusive and value == smallest):
        raise pytest.UsageError(f"pytest-sal: ini option {name} = {text!r}: expected {what}")
    return value


def _size(text: str) -> int:
    from pytest_sal.cache import parse_size

    try:
        return parse_size(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _check_writable(path: Path, option: str, folder: bool) -> None:
    """Stop the session before anything runs when ``path`` (a folder, or a file with
    ``folder=False``) cannot be created or written: a nearer existing part is a file, or the
    existing folder it goes in is read-only."""
    existing = path
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if existing == path and folder != path.is_dir():
        problem = f"{path} exists and is not a folder" if folder else f"{path} is a folder"
    elif existing != path and not existing.is_dir():
        problem = f"{existing} is not a folder, so {path} cannot be created"
    elif not os.access(existing if existing.is_dir() else existing.parent, os.W_OK):
        problem = f"{existing} is not writable"
    else:
        return
    raise pytest.UsageError(f"pytest-sal: {option} {path}: {problem}; give another {'folder' if folder else 'file'}")


def _ini_size(text: str) -> int:
    from pytest_sal.cache import parse_size

    try:
        return parse_size(text)
    except ValueError as exc:
        raise pytest.UsageError(f"pytest-sal: ini option sal_cache_size = {text!r}: {exc}") from None


def add_options(parser: pytest.Parser) -> None:
    """Every option of the plugin: ``--sal-*`` in one group, persistent ones mirrored in ini."""
    group = parser.getgroup("sal", "SLAM robustness (pytest-sal)")
    group.addoption("--sal-cache-dir", dest="sal_cache_dir", metavar="DIR", default=None,
                    help="trial cache folder (ini sal_cache_dir). Default: .sal/cache under the rootdir")
    group.addoption("--sal-cache-size", dest="sal_cache_size", metavar="SIZE", type=_size, default=None,
                    help="evict least-recently-used cache entries above SIZE (e.g. 5GB; ini sal_cache_size). Default: no limit")
    group.addoption("--sal-no-cache", dest="sal_no_cache", action="store_true", default=False,
                    help="run every trial, reading and writing no cache. Default: %(default)r")
    group.addoption("--sal-cache-frames", dest="sal_cache_frames", action="store_true", default=False,
                    help="also store each perturbed sequence in the cache (dataset layout) and run systems on the copy: "
                    "perturb once for several systems or sessions. Default: %(default)r")
    group.addoption("--sal-history-dir", dest="sal_history_dir", metavar="DIR", default=None,
                    help="history store (ini sal_history_dir). Default: .sal/history under the rootdir")
    group.addoption("--sal-no-history", dest="sal_no_history", action="store_true", default=False,
                    help="do not append this run's boundaries to the history. Default: %(default)r")
    group.addoption("--sal-save", dest="sal_save", metavar="NAME", default=None,
                    help="name this run in the history (compare against it later with --sal-compare=NAME)")
    group.addoption("--sal-compare", dest="sal_compare", metavar="REF", nargs="?", const="last", default=None,
                    help="compare each boundary with the history: the last run (default), a run number, name or commit")
    group.addoption("--sal-compare-fail", dest="sal_compare_fail", metavar="CHECK", action="append", type=_compare_fail, default=[],
                    help="fail a test whose result regressed against --sal-compare: boundary:10%% (relative), boundary:2.5 "
                    "(in the parameter's unit), ate_rmse:0.2 or ate_rmse:15%% at the edge. Repeatable")
    group.addoption("--sal-report-md", dest="sal_report_md", metavar="FILE", default=None,
                    help="write a Markdown summary (for a CI job summary) to FILE")
    group.addoption("--sal-report-html", dest="sal_report_html", metavar="DIR", default=None,
                    help="write an HTML report with example frames and plots to DIR/index.html")
    parser.addini("sal_cache_dir", "trial cache folder (default .sal/cache)", default=None)
    parser.addini("sal_cache_size", "cache size limit, e.g. 5GB (default: none)", default=None)
    parser.addini("sal_history_dir", "history store (default .sal/history)", default=None)
    parser.addini("sal_tolerance", "default search tolerance: the bracket's width in percent of its larger end (default 10)", default="10")
    parser.addini("sal_max_trials", "default trial budget of a boundary search (default 8)", default="8")
    parser.addini("sal_runs", "the most runs per trial; runs vote until one verdict leads by 2 (default auto: 1 for a deterministic system, 5 for a noisy one)", default="auto")
    parser.addini("sal_seed", "perturbation seed (default 0)", default="0")
    parser.addini("sal_timeout", "seconds per SLAM run before it is killed (default 600)", default="600")
    parser.addini("sal_system", "default system: orbslam3 when installed, else reference_vo", default=None)


def _shown(path: Path) -> str:
    """``path`` for a message: as the user gave it when relative, else relative to the working
    directory when it lies below it, else whole."""
    if path.is_absolute() and path.is_relative_to(Path.cwd()):
        return str(path.relative_to(Path.cwd()))
    return str(path)


def outcome_of(report: pytest.TestReport) -> Any:
    """The ``Outcome`` a report carries, or ``None``."""
    for name, value in report.user_properties:
        if name == "sal_outcome":
            from pytest_sal.outcome import Outcome

            return Outcome.from_dict(json.loads(value))
    return None


class SalSession:
    """One pytest session's pytest-sal state (also a plugin: it collects outcomes)."""

    def __init__(self, config: pytest.Config):
        self.config = config
        root = Path(config.rootpath)
        opt = config.option

        def ini(name: str) -> Any:
            return config.getini(name)

        self.cache_dir = Path(getattr(opt, "sal_cache_dir", None) or ini("sal_cache_dir") or root / ".sal" / "cache")
        self.cache_size = getattr(opt, "sal_cache_size", None) or (_ini_size(ini("sal_cache_size")) if ini("sal_cache_size") else None)
        self.use_cache = not getattr(opt, "sal_no_cache", False)
        self.history_dir = Path(getattr(opt, "sal_history_dir", None) or ini("sal_history_dir") or root / ".sal" / "history")
        self.compare = getattr(opt, "sal_compare", None)
        self.checks = list(getattr(opt, "sal_compare_fail", []) or [])
        if self.checks and self.compare is None:
            self.compare = "last"
        self.runs = None if str(config.getini("sal_runs")).strip() == "auto" else _ini_number(config, "sal_runs")
        self.seed = _ini_number(config, "sal_seed")
        self.timeout = _ini_number(config, "sal_timeout")
        self.system_name = ini("sal_system")
        from pytest_sal.robustness import SearchSettings

        self.settings = SearchSettings(
            tolerance_pct=_ini_number(config, "sal_tolerance"),
            max_trials=_ini_number(config, "sal_max_trials"),
        )
        if self.use_cache and not self.cache_dir.is_dir():  # an existing read-only cache serves what it holds
            _check_writable(self.cache_dir, "cache folder (--sal-cache-dir, ini sal_cache_dir)", folder=True)
        if not getattr(opt, "sal_no_history", False):
            _check_writable(self.history_dir, "history folder (--sal-history-dir, ini sal_history_dir)", folder=True)
        for option, folder in (("sal_report_html", True), ("sal_report_md", False)):
            if getattr(opt, option, None):
                _check_writable(Path(getattr(opt, option)), "--" + option.replace("_", "-"), folder=folder)
        if self.system_name:
            from sal_wrappers import SYSTEMS

            if self.system_name not in SYSTEMS.names():
                raise pytest.UsageError(f"pytest-sal: ini option sal_system = {self.system_name!r}: unknown SLAM system; known: {', '.join(SYSTEMS.names())}")
        self.outcomes: list[Any] = []
        self.unwritten: list[str] = []  # outputs finish() could not write, said in the summary
        self.written: list[Path] = []  # the files finish() wrote, named in the summary
        self._cache: Any = None
        self._history: Any = None
        if self.compare not in (None, "last") and self.history.runs():
            from sal_adapters import SalError

            try:  # a ref that names no saved run; with no history yet there is nothing to compare
                self.history.find_runs(self.compare)
            except SalError as exc:
                raise pytest.UsageError(f"pytest-sal: --sal-compare={self.compare}: {exc}") from None
        self._datasets: dict[str, Any] = {}

    # -- collaborators -------------------------------------------------------------------------
    @property
    def cache(self) -> Any:
        if self._cache is None and self.use_cache:
            from pytest_sal.cache import ContentCache

            self._cache = ContentCache(self.cache_dir, self.cache_size)
        return self._cache

    @property
    def history(self) -> Any:
        if self._history is None:
            from pytest_sal.history import History

            self._history = History(self.history_dir)
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
        if self.system_name:
            return str(self.system_name)
        import importlib.util

        return "orbslam3" if importlib.util.find_spec("pyorbslam3") else "reference_vo"

    def default_system(self) -> Any:
        from sal_wrappers import create

        return create(self.default_system_name())

    # -- running -------------------------------------------------------------------------------
    def _runner(self, item: pytest.Item, ref: Any, dataset: Any, system: Any, runs: int | None, workdir: Path) -> Any:
        """The trial runner of ``item``; under ``-v`` it prints each trial as it ends."""
        from pytest_sal.progress import trial_printer
        from pytest_sal.report import TRIAL_METRICS
        from pytest_sal.trials import TrialRunner

        requirement = item.function.sal_requirement  # type: ignore[attr-defined]
        seed = int(requirement.options.get("seed", self.seed))
        metrics = list(dict.fromkeys([*TRIAL_METRICS, *(c.metric.name for c in requirement.criteria)]))  # as the reports show them
        return TrialRunner(
            dataset, ref, system, requirement, runs=runs, seed=seed, cache=self.cache, workdir=workdir, timeout=self.timeout,
            artifacts=bool(self.config.option.sal_report_html), cache_frames=bool(self.config.option.sal_cache_frames),
            progress=trial_printer(self.config, item.nodeid, ref.label, ref.unit, metrics),
        )

    def search(self, item: pytest.Item, dataset: Any, system: Any, runs: int | None, workdir: Path) -> Any:
        """Boundary search of ``item``'s requirement; compared with the history when asked."""
        from pytest_sal.regression import warm_start
        from pytest_sal.robustness import search_outcome

        requirement = item.function.sal_requirement  # type: ignore[attr-defined]
        runner = self._runner(item, requirement.envelope.ref, dataset, system, runs, workdir)
        previous = self._previous(item.nodeid, system.name, dataset.name, self.compare or "last")
        envelope = requirement.envelope
        start = warm_start(previous, parameter=envelope.ref.label, edge=envelope.value, worse=envelope.ref.param.worse)
        outcome = search_outcome(runner, requirement, self.settings, item.nodeid, start)
        return self._compared(outcome, previous)

    def single(self, item: pytest.Item, ref: Any, value: float, dataset: Any, system: Any, runs: int | None, workdir: Path) -> Any:
        from pytest_sal.robustness import single_outcome

        runner = self._runner(item, ref, dataset, system, runs, workdir)
        outcome = single_outcome(runner, item.function.sal_requirement, item.nodeid, value)  # type: ignore[attr-defined]
        previous = self._previous(item.nodeid, system.name, dataset.name, self.compare) if self.compare else None
        return self._compared(outcome, previous)

    def _previous(self, test_id: str, system: str, dataset: str, ref: str) -> Any:
        if not self.history_dir.is_dir():
            return None
        return self.history.previous((test_id, system, dataset), ref)

    def _compared(self, outcome: Any, previous: Any) -> Any:
        """``outcome`` with the ``--sal-compare`` result against ``previous`` (the same test's
        outcome in the history run compared with, already looked up by the caller)."""
        if self.compare is None or previous is None:
            return outcome
        from pytest_sal.regression import regressions

        outcome.previous = previous.boundary
        found = regressions(self.checks, outcome, previous)
        outcome.regression = "; ".join(found) if found else None
        return outcome

    # -- collecting and reporting (controller) -------------------------------------------------
    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        if report.when == "call" and not hasattr(self.config, "workerinput"):  # controller or plain session
            outcome = outcome_of(report)
            if outcome is not None:
                self.outcomes.append(outcome)

    def terminal_summary(self, terminal: Any) -> None:
        if not self.outcomes:
            return
        from pytest_sal.report import terminal_table

        terminal.section("pytest-sal robustness boundaries")
        for line in terminal_table(self.outcomes, width=max(self.config.get_terminal_writer().fullwidth, 120)):
            terminal.write_line(line)
        for problem in self.unwritten:
            terminal.write_line(f"pytest-sal: {problem}", red=True)
        for path in self.written:
            terminal.write_line(f"pytest-sal: wrote {_shown(path)}")

    def finish(self) -> None:
        """Write the history and the reports (controller only); ``terminal_summary`` then
        names each file written (``pytest-sal: wrote report/index.html``)."""
        if not self.outcomes:
            return
        from pytest_sal.history import commit_info, machine_info

        commit, dirty = commit_info(self.config.rootpath)
        machine = machine_info()
        for outcome in self.outcomes:
            outcome.commit = commit + ("+dirty" if dirty else "")
            outcome.machine = machine.get("hostname", "")
        from pytest_sal.report import write_html_report, write_markdown
        from sal_adapters.atomic import writing
        from sal_adapters.errors import WriteError

        option = self.config.option
        writes = [
            ("history", None if option.sal_no_history else self.history_dir, lambda: self.history.append_run(self.outcomes, name=option.sal_save)),
            ("--sal-report-md", option.sal_report_md, lambda: write_markdown(self.outcomes, Path(option.sal_report_md))),
            ("--sal-report-html", option.sal_report_html, lambda: write_html_report(self.outcomes, Path(option.sal_report_html))),
        ]
        for what, path, write in writes:
            if path is None:
                continue
            try:  # a full disk or a read-only folder costs that output, not the tests' results
                with writing(path):
                    self.written.append(write())
            except WriteError as exc:
                self.unwritten.append(f"{what} not written: {exc}")
