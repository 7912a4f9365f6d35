"""Session state of pytest-sal: options, the trial cache, the history, the outcomes collected
on the controller, the summary table and the reports written at the end."""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
from pathlib import Path
from typing import Any

import pytest

from pytest_sal.history.gate import MISSING_POLICIES, NOT_COMPARED, space_form_problem

__all__ = ["SAL_SESSION", "SalSession", "add_options", "outcome_of"]

#: The session object, in ``config.stash``.
SAL_SESSION = pytest.StashKey["SalSession"]()

#: Frames of the default synthetic worlds (short enough for CI, long enough to track).
DEFAULT_FRAMES = {"urban": 60, "indoor": 90}
#: Modules whose tests default to the urban street (weather and light); others to the room.
OUTDOOR_MODULES = {"fog", "rain", "snow", "night", "sun_glare", "motion_blur"}


def _compare_fail(text: str) -> Any:
    from pytest_sal.history.regression import parse_compare_fail

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
    from pytest_sal.store.byte_sizes import parse_size

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


def _ini_segments(config: pytest.Config) -> tuple[float, ...]:
    """ini ``sal_kitti_segments`` as segment lengths (m), or a usage error that names it."""
    from pytest_sal.analysis.kitti_segments import parse_segments
    from sal_adapters import SalError

    text = str(config.getini("sal_kitti_segments")).strip()
    try:
        return parse_segments(text)
    except SalError:
        raise pytest.UsageError(
            f"pytest-sal: ini option sal_kitti_segments = {text!r}: expected lengths > 0 (m) separated by commas, e.g. 10,20,30,40"
        ) from None


def _ini_size(text: str) -> int:
    from pytest_sal.store.byte_sizes import parse_size

    try:
        return parse_size(text)
    except ValueError as exc:
        raise pytest.UsageError(f"pytest-sal: ini option sal_cache_size = {text!r}: {exc}") from None


def add_options(parser: pytest.Parser) -> None:
    """Every option of the plugin: ``--sal-*`` in one group, persistent ones mirrored in ini."""
    group = parser.getgroup("sal", "SLAM robustness (pytest-sal)")
    group.addoption(
        "--sal-cache-dir",
        dest="sal_cache_dir",
        metavar="DIR",
        default=None,
        help="trial cache folder (ini sal_cache_dir). Default: .sal/cache under the rootdir",
    )
    group.addoption(
        "--sal-cache-size",
        dest="sal_cache_size",
        metavar="SIZE",
        type=_size,
        default=None,
        help="evict least-recently-used cache entries above SIZE (e.g. 5GB; ini sal_cache_size). Default: no limit",
    )
    group.addoption(
        "--sal-no-cache",
        dest="sal_no_cache",
        action="store_true",
        default=False,
        help="run every trial, reading and writing no cache. Default: %(default)r",
    )
    group.addoption(
        "--sal-cache-frames",
        dest="sal_cache_frames",
        action="store_true",
        default=False,
        help="also store each perturbed sequence in the cache (dataset layout) and run systems on the copy: "
        "perturb once for several systems or sessions. Default: %(default)r",
    )
    group.addoption(
        "--sal-history-dir",
        dest="sal_history_dir",
        metavar="DIR",
        default=None,
        help="history store (ini sal_history_dir). Default: .sal/history under the rootdir",
    )
    group.addoption(
        "--sal-no-history",
        dest="sal_no_history",
        action="store_true",
        default=False,
        help="do not append this run's boundaries to the history. Default: %(default)r",
    )
    group.addoption(
        "--sal-save",
        dest="sal_save",
        metavar="NAME",
        default=None,
        help="name this run in the history, e.g. --sal-save=main on the main branch; a run in which a "
        "--sal-compare-fail check failed is saved without the name, so it cannot become the baseline",
    )
    group.addoption(
        "--sal-compare",
        dest="sal_compare",
        metavar="REF",
        nargs="?",
        const="",
        default=None,
        help="compare each boundary with a baseline in the history: a run name (default: ini sal_baseline, "
        "'main'), a run number, a commit prefix, or 'last' (the newest run that did not fail the gate)",
    )
    group.addoption(
        "--sal-compare-missing",
        dest="sal_compare_missing",
        choices=("pass", "fail"),
        default=None,
        help="a test the baseline lacks (or no baseline at all): pass, said in the summary, or fail "
        "(ini sal_compare_missing). Default: pass",
    )
    group.addoption(
        "--sal-compare-fail",
        dest="sal_compare_fail",
        metavar="CHECK",
        action="append",
        type=_compare_fail,
        default=[],
        help="fail a test whose result regressed against --sal-compare: boundary:10%% (relative), boundary:2.5 "
        "(in the parameter's unit), ate_rmse:0.2 or ate_rmse:15%% at the edge. Repeatable",
    )
    group.addoption(
        "--sal-report-md",
        dest="sal_report_md",
        metavar="FILE",
        default=None,
        help="write a Markdown summary (for a CI job summary) to FILE",
    )
    group.addoption(
        "--sal-report-html",
        dest="sal_report_html",
        metavar="DIR",
        default=None,
        help="write an HTML report with example frames and plots to DIR/index.html",
    )
    parser.addini("sal_cache_dir", "trial cache folder (default .sal/cache)", default=None)
    parser.addini("sal_cache_size", "cache size limit, e.g. 5GB (default: none)", default=None)
    parser.addini("sal_history_dir", "history store (default .sal/history)", default=None)
    parser.addini("sal_baseline", "the run name --sal-compare and --sal-compare-fail compare with (default main)", default="main")
    parser.addini("sal_compare_missing", "pass or fail: a test with no baseline to compare with (default pass)", default="pass")
    parser.addini("sal_tolerance", "default search tolerance: the bracket's width in percent of its larger end (default 10)", default="10")
    parser.addini("sal_max_trials", "default trial budget of a boundary search (default 8)", default="8")
    parser.addini(
        "sal_runs",
        "the most runs per trial; runs vote until one verdict leads by 2 (default auto: 1 for a deterministic system, 5 for a noisy one)",
        default="auto",
    )
    parser.addini("sal_seed", "perturbation seed (default 0)", default="0")
    parser.addini("sal_timeout", "seconds per SLAM run before it is killed (default 600)", default="600")
    parser.addini("sal_system", "default system: orbslam3 when installed, else reference_vo", default=None)
    parser.addini(
        "sal_kitti_segments",
        "segment lengths (m) of the KITTI metrics t_rel / r_rel, e.g. 10,20,30,40 for a short sequence "
        "(default the KITTI devkit's 100,200,...,800)",
        default="100,200,300,400,500,600,700,800",
    )


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
            from pytest_sal.engine.outcome import Outcome

            return Outcome.from_dict(json.loads(value))
    return None


class SalSession:
    """One pytest session's pytest-sal state (also a plugin: it collects outcomes)."""

    def __init__(self, config: pytest.Config):
        self.config = config
        root = Path(config.rootpath)
        opt = config.option
        if not hasattr(config, "workerinput"):  # the controller saw the command line; workers got it checked
            args = [*shlex.split(os.environ.get("PYTEST_ADDOPTS", "")), *config.invocation_params.args]
            problem = space_form_problem(args, str(config.rootpath), None if config.inipath is None else str(config.inipath))
            if problem:
                raise pytest.UsageError(f"pytest-sal: {problem}")

        def ini(name: str) -> Any:
            return config.getini(name)

        self.cache_dir = Path(getattr(opt, "sal_cache_dir", None) or ini("sal_cache_dir") or root / ".sal" / "cache")
        self.cache_size = getattr(opt, "sal_cache_size", None) or (_ini_size(ini("sal_cache_size")) if ini("sal_cache_size") else None)
        self.use_cache = not getattr(opt, "sal_no_cache", False)
        self.history_dir = Path(getattr(opt, "sal_history_dir", None) or ini("sal_history_dir") or root / ".sal" / "history")
        self.checks = list(getattr(opt, "sal_compare_fail", []) or [])
        self.compare = getattr(opt, "sal_compare", None)
        if self.compare == "" or (self.checks and self.compare is None):
            self.compare = str(ini("sal_baseline")).strip() or "main"
        self.compare_missing = getattr(opt, "sal_compare_missing", None) or str(ini("sal_compare_missing")).strip()
        if self.compare_missing not in MISSING_POLICIES:
            raise pytest.UsageError(f"pytest-sal: ini option sal_compare_missing = {self.compare_missing!r}: expected pass or fail")
        self.load_at_start = os.getloadavg() if hasattr(os, "getloadavg") else None
        self._machine: str | None = None
        self.runs = None if str(config.getini("sal_runs")).strip() == "auto" else _ini_number(config, "sal_runs")
        self.seed = _ini_number(config, "sal_seed")
        self.timeout = _ini_number(config, "sal_timeout")
        self.system_name = ini("sal_system")
        self.kitti_segments = _ini_segments(config)
        from pytest_sal.engine.requirement_runner import SearchSettings

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
                raise pytest.UsageError(
                    f"pytest-sal: ini option sal_system = {self.system_name!r}: unknown SLAM system; known: {', '.join(SYSTEMS.names())}"
                )
        self.outcomes: list[Any] = []
        self.unwritten: list[str] = []  # outputs finish() could not write, said in the summary
        self.written: list[Path] = []  # the files finish() wrote, named in the summary
        self._cache: Any = None
        self._history: Any = None
        self.notes: list[str] = []  # said at the end of the summary (a run saved without its name)
        self._datasets: dict[str, Any] = {}

    # -- collaborators -------------------------------------------------------------------------
    @property
    def cache(self) -> Any:
        if self._cache is None and self.use_cache:
            from pytest_sal.store.trial_cache import ContentCache

            self._cache = ContentCache(self.cache_dir, self.cache_size)
        return self._cache

    @property
    def history(self) -> Any:
        if self._history is None:
            from pytest_sal.history.run_history import History

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
        from pytest_sal.engine.trial_runner import TrialRunner
        from pytest_sal.progress import trial_printer
        from pytest_sal.report.outcome_report import trial_metric_names

        requirement = item.function.sal_requirement  # type: ignore[attr-defined]
        seed = int(requirement.options.get("seed", self.seed))
        metrics = trial_metric_names([(c.metric.name, c.op, c.threshold) for c in requirement.criteria])  # as the reports show them
        return TrialRunner(
            dataset,
            ref,
            system,
            requirement,
            runs=runs,
            seed=seed,
            cache=self.cache,
            workdir=workdir,
            timeout=self.timeout,
            artifacts=bool(self.config.option.sal_report_html or getattr(self.config.option, "htmlpath", None)),  # ours or pytest-html's
            cache_frames=bool(self.config.option.sal_cache_frames),
            kitti_segments=self.kitti_segments,
            progress=trial_printer(self.config, item.nodeid, ref.label, ref.unit, metrics),
        )

    def search(self, item: pytest.Item, dataset: Any, system: Any, runs: int | None, workdir: Path) -> Any:
        """Boundary search of ``item``'s requirement; compared with the history when asked."""
        from pytest_sal.engine.requirement_runner import search_outcome
        from pytest_sal.history.regression import warm_start

        requirement = item.function.sal_requirement  # type: ignore[attr-defined]
        runner = self._runner(item, requirement.envelope.ref, dataset, system, runs, workdir)
        previous = self._start_from((item.nodeid, system.name, dataset.name))
        envelope = requirement.envelope
        start = warm_start(previous, parameter=envelope.ref.label, edge=envelope.value, worse=envelope.ref.param.worse)
        outcome = search_outcome(runner, requirement, self.settings, item.nodeid, start)
        return self._finished(outcome, system)

    def single(self, item: pytest.Item, ref: Any, value: float, dataset: Any, system: Any, runs: int | None, workdir: Path) -> Any:
        from pytest_sal.engine.requirement_runner import single_outcome

        runner = self._runner(item, ref, dataset, system, runs, workdir)
        outcome = single_outcome(runner, item.function.sal_requirement, item.nodeid, value)  # type: ignore[attr-defined]
        return self._finished(outcome, system)

    def _start_from(self, key: tuple[str, str, str]) -> Any:
        """The outcome whose boundary the search tries first: the baseline's under
        ``--sal-compare``, else the last run's (``None`` when the history has neither)."""
        from sal_adapters.errors import SalError

        if not self.history_dir.is_dir():
            return None
        try:
            return self.history.previous(key, self.compare or "last")
        except SalError:  # the baseline is missing: the comparison says so
            return self.history.previous(key, "last")

    @property
    def machine(self) -> str:
        """This machine in words (``history.machine_text``), read once."""
        if self._machine is None:
            from pytest_sal.history.run_history import machine_info, machine_text

            self._machine = machine_text(machine_info())
        return self._machine

    def _finished(self, outcome: Any, system: Any) -> Any:
        """``outcome`` with where it ran and, under ``--sal-compare``, compared with its baseline."""
        outcome.machine = self.machine
        outcome.system_version = system.version_text()
        if self.compare is None:
            return outcome
        from pytest_sal.history.gate import compare_with_baseline

        return compare_with_baseline(outcome, self.history, self.compare, self.checks, missing=self.compare_missing)

    # -- collecting and reporting (controller) -------------------------------------------------
    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        if report.when == "call" and not hasattr(self.config, "workerinput"):  # controller or plain session
            outcome = outcome_of(report)
            if outcome is not None:
                self.outcomes.append(outcome)

    def terminal_summary(self, terminal: Any) -> None:
        if not self.outcomes:
            return
        from pytest_sal.report.outcome_report import terminal_table

        terminal.section("pytest-sal robustness boundaries")
        for line in terminal_table(self.outcomes, width=max(self.config.get_terminal_writer().fullwidth, 120)):
            terminal.write_line(line)
        for problem in self.unwritten:
            terminal.write_line(f"pytest-sal: {problem}", red=True)
        for path in self.written:
            terminal.write_line(f"pytest-sal: wrote {_shown(path)}")
        for note in self.comparison_notes() + self.notes:
            terminal.write_line(f"pytest-sal: {note}", yellow=True)

    def comparison_notes(self) -> list[str]:
        """What the gate could not compare, in one line (``--sal-compare-missing`` says what
        that did to the tests)."""
        missing = [o for o in self.outcomes if o.comparison.startswith(NOT_COMPARED)]
        if not missing:
            return []
        effect = "failed" if self.compare_missing == "fail" else "passed without a comparison; --sal-compare-missing=fail fails them"
        return [
            f"{len(missing)} of {len(self.outcomes)} tests not compared with {self.compare!r} ({effect}): {missing[0].comparison[len(NOT_COMPARED) :]}"
        ]

    def finish(self) -> None:
        """Write the history and the reports (controller only); ``terminal_summary`` then
        names each file written (``pytest-sal: wrote report/index.html``)."""
        if not self.outcomes:
            return
        from pytest_sal.history.run_history import commit_info, machine_info

        commit, dirty = commit_info(self.config.rootpath)
        machine = dict(machine_info(), load_avg_start=self.load_at_start)
        for outcome in self.outcomes:
            outcome.commit = commit + ("+dirty" if dirty else "")
        from pytest_sal.report.outcome_report import write_html_report, write_markdown
        from sal_adapters.atomic import writing
        from sal_adapters.errors import WriteError

        option = self.config.option
        name = self._save_name()
        writes = [
            (
                "history",
                None if option.sal_no_history else self.history_dir,
                lambda: self.history.append_run(self.outcomes, name=name, machine=machine),
            ),
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

    def _save_name(self) -> str | None:
        """``--sal-save``'s name, unless a test of this run failed the gate: a regressed run is
        saved without the name, so it cannot replace the baseline (said in the summary)."""
        name = self.config.option.sal_save
        failed = [o for o in self.outcomes if o.regression]
        if name and failed:
            self.notes.append(
                f"this run is saved without the name {name!r}: {len(failed)} test(s) failed the --sal-compare gate, so it cannot become the baseline"
            )
            return None
        return name
