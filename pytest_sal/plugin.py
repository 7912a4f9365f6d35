"""The pytest plugin (entry point ``pytest11: sal``): options, marks, fixtures and the hooks
that turn a ``sal.require`` test into a boundary search whose interval is the test outcome.

Heavy imports (OpenCV, evo, SLAM wrappers) happen inside fixtures and hooks, never here.
Per-test outcomes travel on the test report (``user_properties``), so under ``pytest -n 2``
only the controller collects them, prints the summary and writes history and reports.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest

from pytest_sal.api import levels_of, requirement_of
from pytest_sal.controller_lifeline import follow_controller
from pytest_sal.engine.outcomes.outcome import Outcome
from pytest_sal.engine.outcomes.quantity import num, with_unit
from pytest_sal.engine.requirements import InvalidRequirement
from pytest_sal.engine.search.requirement_search import failure_message
from pytest_sal.html_extras import HtmlExtras
from pytest_sal.option_table import add_options
from pytest_sal.report.formatting import trial_line
from pytest_sal.report.outcome_report import trial_metric_names
from pytest_sal.session import SAL_SESSION, SalSession
from pytest_sal.session_results import outcome_of

__all__ = [
    "PendingSearch",
    "level_id",
    "pytest_addoption",
    "pytest_collection_modifyitems",
    "pytest_configure",
    "pytest_generate_tests",
    "pytest_pyfunc_call",
    "pytest_report_header",
    "pytest_report_teststatus",
    "pytest_runtest_makereport",
    "pytest_runtest_setup",
    "pytest_sessionfinish",
    "pytest_terminal_summary",
    "pytest_unconfigure",
    "sal_dataset",
    "sal_level",
    "sal_outcome",
    "sal_runs",
    "sal_system",
    "sal_trial",
]

#: The outcome of a test, on its item.
OUTCOME = pytest.StashKey[Outcome]()
#: Why a robustness test's marks are misused (xdist workers report it at setup).
MISUSE = pytest.StashKey[str]()

MARKERS = (
    "sal: a SLAM robustness test run by pytest-sal (select with -m sal)",
    "sal_require(requirement): criteria that must hold wherever the envelope holds (sal.require)",
    "sal_sweep(param, levels): run the test at named severity levels (sal.sweep, sal.at)",
)


def pytest_addoption(parser: pytest.Parser) -> None:
    add_options(parser)


def pytest_configure(config: pytest.Config) -> None:
    for line in MARKERS:
        config.addinivalue_line("markers", line)
    if hasattr(config, "workerinput"):  # an xdist worker: it dies with its controller
        follow_controller()
    session = SalSession(config)
    config.stash[SAL_SESSION] = session
    config.pluginmanager.register(session, "sal-session")  # collects outcomes from reports
    if config.pluginmanager.hasplugin("html") and getattr(config.option, "htmlpath", None):
        config.pluginmanager.register(HtmlExtras(OUTCOME), "sal-html")  # pytest-html rows get boundary, plot, frames


def pytest_report_header(config: pytest.Config) -> list[str]:
    """Say at the start where runs happen when not here (``--sal-executor ray``), and when the
    robustness tests' local ORB-SLAM3 runs will not all get the cores they need (more xdist
    workers than cores, or a machine already busy): such runs fall behind the sensor clock;
    they are re-paced and marked, and take longer."""
    session: SalSession = config.stash[SAL_SESSION]
    lines = [f"pytest-sal: runs on {session.executor().describe()}"] if session.options.executor != "local" else []
    if session.default_system_name() != "orbslam3" or session.options.executor != "local":
        return lines
    from sal_wrappers import oversubscribed_warning

    workers = getattr(config.option, "numprocesses", None)
    warning = oversubscribed_warning(int(workers) if isinstance(workers, int) and workers > 0 else 1)
    return [warning] if warning else []


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    """``sal.sweep`` / ``sal.at``: one item per level, id ``L-rain.intensity_mm_h=3`` (see ``level_id``)."""
    levels = levels_of(metafunc.definition)
    if levels is None:
        return
    ref, named = levels
    if "sal_trial" not in metafunc.fixturenames:
        raise pytest.UsageError(
            f"{metafunc.function.__name__}: sal.sweep / sal.at tests take the sal_trial fixture (def {metafunc.function.__name__}(sal_trial): ...)"
        )
    values = [(ref, name, value) for name, value in named.items()]
    metafunc.parametrize("sal_level", values, ids=[level_id(*value) for value in values], indirect=True)


def level_id(ref: Any, name: str, value: float) -> str:
    """The test id of a ``sal.sweep`` level: ``H-rain.intensity_mm_h=50`` (level name, then the
    parameter, whose name carries its unit, and the value in that unit); a ``sal.at`` point
    (level ``at``) is ``fog.visibility_m=30``. ``-k`` matches substrings of names, case
    ignored, so ``-k H`` also matches the ``h`` of ``mm_h``; ``-k "[H-"`` or ``-k H-rain``
    selects level H (``=`` cannot appear in a ``-k`` word)."""
    point = f"{ref.label}={value:g}"
    return point if name == "at" else f"{name}-{point}"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Check every robustness test's marks before anything runs."""
    for item in items:
        requirement, levels = requirement_of(item), levels_of(item)
        message = None
        if levels is not None and requirement is None:
            message = f"{item.nodeid}: sal.sweep / sal.at need a sal.require(...) below them with the criteria each level must meet"
        elif requirement is not None and requirement.envelope is None and levels is None:
            message = (
                f"{item.nodeid}: {InvalidRequirement.__name__}: sal.require({requirement}) has no parameter bound to search; "
                f"add one (fog.visibility_m >= 25) or put sal.sweep(...) / sal.at(...) above it"
            )
        elif requirement is not None and requirement.envelope is not None and levels is not None:
            message = f"{item.nodeid}: sal.sweep / sal.at run fixed levels; drop the envelope {requirement.envelope} from sal.require"
        if message is None:
            continue
        if hasattr(config, "workerinput"):  # an xdist worker: xdist would show a UsageError as a bare INTERNALERROR
            item.stash[MISUSE] = message
        else:
            raise pytest.UsageError(message)


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    """Under xdist, a misused robustness test errors in its setup with the usage message."""
    message = item.stash.get(MISUSE, None)
    if message is not None:
        pytest.fail(message, pytrace=False)


# -- fixtures ----------------------------------------------------------------------------------
@pytest.fixture
def sal_runs(request: pytest.FixtureRequest) -> int | None:
    """The most runs per trial: ``runs=`` of ``sal.require``, else ini ``sal_runs``, else
    ``None`` (1 for a deterministic system, 5 for a noisy one such as ORB-SLAM3); above 1 the
    system is searched as a noisy one (its chance to hold). Override in conftest.py for every test."""
    requirement = requirement_of(request.node)
    if requirement is not None and "runs" in requirement.options:
        return int(requirement.options["runs"])
    return request.config.stash[SAL_SESSION].runs


@pytest.fixture
def sal_dataset(request: pytest.FixtureRequest) -> Any:
    """The clean sequence to perturb. Default: the synthetic world that suits the perturbation
    (the urban street, stereo, for weather and light; the indoor room, RGB-D, otherwise).
    Override in conftest.py, e.g. ``sal_dataset = sal.dataset_fixture("kitti", "/data/kitti", sequence="07")``."""
    return request.config.stash[SAL_SESSION].default_dataset(_ref_of(request))


@pytest.fixture
def sal_system(request: pytest.FixtureRequest) -> Any:
    """The SLAM system under test. Default: ORB-SLAM3 when ``pyorbslam3`` is installed, else
    the built-in reference VO (ini ``sal_system`` names another). Parametrise it in
    conftest.py to test several systems: one item per system."""
    return request.config.stash[SAL_SESSION].default_system()


@pytest.fixture
def sal_level(request: pytest.FixtureRequest) -> Any:
    """The ``(param, name, value)`` of a ``sal.sweep`` level (set by parametrisation)."""
    return request.param


@pytest.fixture
def sal_outcome(request: pytest.FixtureRequest, sal_dataset: Any, sal_system: Any, sal_runs: int | None, tmp_path: Path) -> Any:
    """The ``Outcome`` of the boundary search of this test's ``sal.require``: verdict,
    boundary interval, trials and their metrics. The search runs in the test's call phase
    (as hypothesis runs its examples), so it is booked as the test's time, an error in it
    fails the test and Ctrl-C interrupts the session cleanly; a requirement that does not
    hold fails the test before its body runs. Read it in the test body: a fixture that asks
    for ``sal_outcome`` gets the pending search, not its result."""
    return PendingSearch(request.node, sal_dataset, sal_system, sal_runs, tmp_path)


@pytest.fixture
def sal_trial(
    request: pytest.FixtureRequest, sal_level: Any, sal_dataset: Any, sal_system: Any, sal_runs: int | None, tmp_path: Path
) -> Any:
    """The ``Trial`` at this item's ``sal.sweep`` level or ``sal.at`` point: ``metrics``
    (ate_rmse, tracking_rate, ...), ``passed``, ``runs``. Run in the call phase like
    ``sal_outcome``; a level that misses the requirement fails the test before its body runs."""
    return PendingSearch(request.node, sal_dataset, sal_system, sal_runs, tmp_path, level=sal_level)


class PendingSearch:
    """What ``sal_outcome`` / ``sal_trial`` hold until the call phase runs the search and
    hands the test body its result."""

    def __init__(self, item: pytest.Item, dataset: Any, system: Any, runs: int | None, workdir: Path, level: Any = None):
        self.item, self.dataset, self.system, self.runs, self.workdir, self.level = item, dataset, system, runs, workdir, level

    def run(self) -> Any:
        """The outcome: the boundary search, or the one trial at the sweep level."""
        session: SalSession = self.item.config.stash[SAL_SESSION]
        return session.outcome(self.item, self.dataset, self.system, self.runs, self.workdir, self.level)

    def __getattr__(self, name: str) -> Any:
        raise AttributeError(
            f"{name!r}: the search has not run yet; pytest-sal runs it in the test's call phase, so read sal_outcome / sal_trial in the test body, not in a fixture"
        )


def _ref_of(request: pytest.FixtureRequest) -> Any:
    requirement = requirement_of(request.node)
    if requirement is not None and requirement.envelope is not None:
        return requirement.envelope.ref
    levels = levels_of(request.node)
    return levels[0] if levels else None


# -- the verdict and the report ----------------------------------------------------------------
@pytest.hookimpl(tryfirst=True)
def pytest_pyfunc_call(pyfuncitem: pytest.Function) -> None:
    """Run the search of a robustness test in its call phase and hand the body its result;
    fail the test when its requirement does not hold (or its boundary regressed), so it is
    reported FAILED with the search's message."""
    for name in ("sal_outcome", "sal_trial"):
        pending = pyfuncitem.funcargs.get(name)
        if not isinstance(pending, PendingSearch):
            continue
        outcome = pending.run()
        pyfuncitem.stash[OUTCOME] = outcome
        pyfuncitem.funcargs[name] = outcome if name == "sal_outcome" else outcome.trials[0]
        if not outcome.passed:
            __tracebackhide__ = True
            pytest.fail(failure_message(outcome), pytrace=False)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Any:
    report = yield
    errors = sys.modules.get("sal_adapters.common.errors")  # not loaded: the error cannot be a SalError
    if call.excinfo is not None and errors is not None and call.excinfo.errisinstance(errors.SalError):
        report.longrepr = call.excinfo.getrepr(style="value")  # its message is the whole story (a dataset file:line)
    outcome = item.stash.get(OUTCOME, None)
    if outcome is not None and report.when == "call":
        properties = [
            ("sal_boundary_pass", "" if outcome.boundary.pass_value is None else f"{outcome.boundary.pass_value:g}"),
            ("sal_boundary_fail", "" if outcome.boundary.fail_value is None else f"{outcome.boundary.fail_value:g}"),
            ("sal_trials", str(len(outcome.trials))),
            ("sal_runs", str(outcome.runs)),
            ("sal_confidence", outcome.confidence()),
            ("sal_unit", outcome.boundary.unit),
            ("sal_outcome", json.dumps(outcome.to_dict())),
        ]
        report.user_properties.extend(properties)
        item.user_properties.extend(properties)  # JUnit XML writes the properties of the teardown report
        report.sections.append(("pytest-sal", _trace(outcome)))
    return report


def pytest_report_teststatus(report: pytest.TestReport, config: pytest.Config) -> Any:
    """Verbose mode shows the boundary: ``PASSED (fog.visibility_m boundary 14-16 m)``."""
    if report.when != "call" or not report.passed:
        return None
    outcome = outcome_of(report)
    if outcome is None:
        return None
    if outcome.termination == "single":
        trial = outcome.trials[0]
        names = dict.fromkeys(name for name, _, _ in outcome.criteria)
        shown = ", ".join(f"{name} {num(trial.metrics[name], 3)}" for name in names if trial.metrics.get(name) is not None)
        value = with_unit(trial.value, outcome.boundary.unit, digits=6)
        return "passed", ".", (f"PASSED ({outcome.parameter} = {value}: {shown})", {"green": True})
    return "passed", ".", (f"PASSED ({outcome.parameter} boundary {outcome.boundary.text()})", {"green": True})


def pytest_terminal_summary(terminalreporter: Any, exitstatus: int, config: pytest.Config) -> None:
    if hasattr(config, "workerinput"):  # an xdist worker (not the env variable: a nested pytest inherits it)
        return
    config.stash[SAL_SESSION].terminal_summary(terminalreporter)


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    if hasattr(session.config, "workerinput"):
        return
    session.config.stash[SAL_SESSION].finish()


def pytest_unconfigure(config: pytest.Config) -> None:
    """Release the executor: a local Ray this process started is shut down."""
    session = config.stash.get(SAL_SESSION, None)
    if session is not None:
        session.close()


def _trace(outcome: Outcome) -> str:
    """The report section of a robustness test: requirement, boundary, votes, a line per trial."""
    lines = [f"{outcome.requirement}; boundary {outcome.boundary.text()} ({outcome.termination})"]
    lines.append(f"  confidence: {outcome.confidence()} ({len(outcome.trials)} trials, {outcome.runs} runs)")
    names = trial_metric_names(outcome.criteria)
    lines += [f"  {trial_line(trial, outcome.parameter, outcome.boundary.unit, names)}" for trial in outcome.trials]
    return "\n".join(lines)
