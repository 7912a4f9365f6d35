"""The plugin's options: the ``--sal-*`` command-line options and ``sal_*`` ini keys it declares
(``add_options``), and what they say for one session (``read_options`` gives a ``SalOptions``,
read and checked once at configure time; a bad value is a ``pytest.UsageError`` that names the
option and what it takes)."""

from __future__ import annotations

import argparse
import math
import os
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from pytest_sal.history.gate import MISSING_POLICIES, space_form_problem
from sal_adapters.common.errors import SalDeprecationWarning

if TYPE_CHECKING:
    from pytest_sal.engine.search.requirement_search import SearchSettings
    from pytest_sal.history.regression import RegressionCheck

__all__ = ["INI_KEYS", "OPTIONS", "SalOptions", "add_options", "read_options"]


def _compare_fail(text: str) -> RegressionCheck:
    from pytest_sal.history.regression import parse_compare_fail

    return parse_compare_fail(text)


def _size(text: str) -> int:
    from pytest_sal.store.byte_sizes import parse_size

    try:
        return parse_size(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


#: the ``--sal-*`` options, in the order ``--help`` lists them: (flag, ``addoption`` keywords)
OPTIONS: tuple[tuple[str, dict[str, Any]], ...] = (
    (
        "--sal-cache-dir",
        dict(
            dest="sal_cache_dir",
            metavar="DIR",
            default=None,
            help="cache folder (ini sal_cache_dir). Default: .sal/cache under the rootdir",
        ),
    ),
    (
        "--sal-cache-size",
        dict(
            dest="sal_cache_size",
            metavar="SIZE",
            type=_size,
            default=None,
            help="evict least-recently-used cache entries above SIZE (e.g. 5GB; ini sal_cache_size). Default: no limit",
        ),
    ),
    (
        "--sal-no-cache",
        dict(
            dest="sal_no_cache",
            action="store_true",
            default=False,
            help="run every trial, reading and writing no cache. Default: %(default)r",
        ),
    ),
    (
        "--sal-cache-frames",
        dict(
            dest="sal_cache_frames",
            action="store_true",
            default=False,
            help="also store each perturbed sequence in the cache (dataset layout) and run systems on the copy: "
            "perturb once for several systems or sessions. Default: %(default)r",
        ),
    ),
    (
        "--sal-no-early-stop",
        dict(
            dest="sal_no_early_stop",
            action="store_true",
            default=False,
            help="run every SLAM run to its last frame, even once its requirement can no longer hold "
            "(ini sal_early_stop = false). Default: stop it early",
        ),
    ),
    (
        "--sal-history-dir",
        dict(
            dest="sal_history_dir",
            metavar="DIR",
            default=None,
            help="history store (ini sal_history_dir). Default: .sal/history under the rootdir",
        ),
    ),
    (
        "--sal-no-history",
        dict(
            dest="sal_no_history",
            action="store_true",
            default=False,
            help="do not append this run's boundaries to the history. Default: %(default)r",
        ),
    ),
    (
        "--sal-save",
        dict(
            dest="sal_save",
            metavar="NAME",
            default=None,
            help="name this run in the history (at most 100 characters), e.g. --sal-save=main on the main branch; a run in which a "
            "--sal-compare-fail check failed is saved without the name, so it cannot become the baseline",
        ),
    ),
    (
        "--sal-compare",
        dict(
            dest="sal_compare",
            metavar="REF",
            nargs="?",
            const="",
            default=None,
            help="compare each boundary with a baseline in the history: a run name (default: ini sal_baseline, "
            "'main'), a run number, a commit prefix, or 'last' (the newest run that did not fail the gate)",
        ),
    ),
    (
        "--sal-compare-missing",
        dict(
            dest="sal_compare_missing",
            choices=("pass", "fail"),
            default=None,
            help="a test the baseline lacks (or no baseline at all): pass, said in the summary, or fail (ini sal_compare_missing). Default: pass",
        ),
    ),
    (
        "--sal-compare-fail",
        dict(
            dest="sal_compare_fail",
            metavar="CHECK",
            action="append",
            type=_compare_fail,
            default=[],
            help="fail a test whose result regressed against --sal-compare: boundary:10%% (relative), boundary:2.5 "
            "(in the parameter's unit), ate_rmse:0.2 or ate_rmse:15%% at the edge. Repeatable",
        ),
    ),
    (
        "--sal-executor",
        dict(
            dest="sal_executor",
            choices=("local", "ray"),
            default=None,
            help="where SLAM runs happen: local (this process, one at a time) or ray (Ray tasks on a cluster, several "
            "at once; needs pytest-sal[ray]; ini sal_executor). Default: local",
        ),
    ),
    (
        "--sal-ray-address",
        dict(
            dest="sal_ray_address",
            metavar="ADDRESS",
            default=None,
            help="the Ray cluster of --sal-executor ray: auto (the one on this machine), ray://HOST:10001 (Ray client), "
            "HOST:PORT (its GCS), or empty: a local Ray started for the session (ini sal_ray_address). Default: empty",
        ),
    ),
    (
        "--sal-report-md",
        dict(dest="sal_report_md", metavar="FILE", default=None, help="write a Markdown summary (for a CI job summary) to FILE"),
    ),
    (
        "--sal-report-html",
        dict(
            dest="sal_report_html", metavar="DIR", default=None, help="write an HTML report with example frames and plots to DIR/index.html"
        ),
    ),
)

#: the ``sal_*`` ini keys: (name, help, default)
INI_KEYS: tuple[tuple[str, str, str | None], ...] = (
    ("sal_cache_dir", "cache folder (default .sal/cache)", None),
    ("sal_cache_size", "cache size limit, e.g. 5GB (default: none)", None),
    ("sal_history_dir", "history store (default .sal/history)", None),
    ("sal_baseline", "the run name --sal-compare and --sal-compare-fail compare with (default main)", "main"),
    ("sal_compare_missing", "pass or fail: a test with no baseline to compare with (default pass)", "pass"),
    ("sal_tolerance", "default search tolerance, a percent of the bracket's larger end, e.g. 5% (default 10%)", "10%"),
    ("sal_max_trials", "default trial budget of a boundary search (default 8)", "8"),
    ("sal_reliability", "noisy systems: the share of runs that must hold the requirement at the envelope's edge (default 0.8)", "0.8"),
    ("sal_confidence", "noisy systems: the one-sided confidence that this reliability is met (default 0.9)", "0.9"),
    ("sal_max_runs", "noisy systems: the most runs of one requirement's search (default 30)", "30"),
    (
        "sal_runs",
        "the most runs per trial; above 1 the system is searched as a noisy one (default auto: 1 for a deterministic system, 5 for a noisy one)",
        "auto",
    ),
    ("sal_seed", "perturbation seed (default 0)", "0"),
    (
        "sal_early_stop",
        "true or false: stop a SLAM run once its requirement can no longer hold, e.g. tracking_rate >= 0.9 "
        "with 15 of 140 frames lost (default true)",
        "true",
    ),
    ("sal_timeout", "seconds per SLAM run before it is killed (default 600)", "600"),
    ("sal_system", "default system: orbslam3 when installed, else reference_vo", None),
    ("sal_executor", "where SLAM runs happen: local or ray (default local)", "local"),
    ("sal_ray_address", "Ray cluster of the ray executor: auto, ray://HOST:10001, HOST:PORT or empty for a local Ray (default empty)", ""),
    (
        "sal_kitti_segments",
        "segment lengths (m) of the KITTI metrics t_rel / r_rel, e.g. 10,20,30,40 for a short sequence "
        "(default the KITTI devkit's 100,200,...,800)",
        "100,200,300,400,500,600,700,800",
    ),
)

#: ini keys read as numbers: (type, smallest value, whether the smallest is excluded, what it is)
_INI_NUMBERS: dict[str, tuple[type, float, bool, str]] = {
    "sal_runs": (int, 1, False, "a whole number >= 1 (the most runs per trial), or auto"),
    "sal_seed": (int, 0, False, "a whole number >= 0 (perturbation seed)"),
    "sal_max_trials": (int, 1, False, "a whole number >= 1 (trials per boundary search)"),
    "sal_reliability": (float, 0.0, True, "a probability between 0 and 1 (the share of runs that must hold)"),
    "sal_confidence": (float, 0.5, True, "a probability between 0.5 and 1 (one-sided confidence)"),
    "sal_max_runs": (int, 1, False, "a whole number >= 1 (runs per search of a noisy system)"),
    "sal_timeout": (float, 0.0, True, "a number > 0 (seconds per SLAM run)"),
}


def add_options(parser: pytest.Parser) -> None:
    """Every option of the plugin: ``--sal-*`` in one group (``OPTIONS``), the persistent ones
    mirrored in ini keys (``INI_KEYS``)."""
    group = parser.getgroup("sal", "SLAM robustness (pytest-sal)")
    for flag, spec in OPTIONS:
        group.addoption(flag, **spec)
    for name, text, default in INI_KEYS:
        parser.addini(name, text, default=default)


@dataclass(frozen=True)
class SalOptions:
    """What the options and ini keys say for one session, checked.

    Attributes:
        cache_dir, cache_size, use_cache, cache_frames: the cache (size limit in bytes,
            ``None``: none) and whether perturbed sequences are cached too.
        history_dir, save_history, save_name: the run history, whether this run is appended to
            it and under what name (``--sal-save``).
        compare, checks, compare_missing: the baseline compared with (``None``: no comparison),
            the ``--sal-compare-fail`` checks and what a test without a baseline does.
        runs, seed, timeout: the most runs per trial (``None``: auto), the perturbation seed and
            the seconds per SLAM run.
        early_stop: stop a run once its requirement can no longer hold (``--sal-no-early-stop``,
            ini ``sal_early_stop``).
        system_name: ini ``sal_system`` (``None``: the default system).
        kitti_segments: segment lengths (m) of ``t_rel`` / ``r_rel``.
        search: the default tolerance and trial budget of a boundary search.
        report_md, report_html: where the Markdown and HTML reports go (``None``: not written).
        executor, ray_address: where runs happen (``local`` or ``ray``) and the Ray cluster
            (``""``: a local Ray started for the session; an xdist worker gets the one its
            controller started).
    """

    cache_dir: Path
    cache_size: int | None
    use_cache: bool
    cache_frames: bool
    history_dir: Path
    save_history: bool
    save_name: str | None
    compare: str | None
    checks: list[RegressionCheck]
    compare_missing: str
    runs: int | None
    seed: int
    timeout: float
    early_stop: bool
    system_name: str | None
    kitti_segments: tuple[float, ...]
    search: SearchSettings
    report_md: Path | None
    report_html: Path | None
    executor: str = "local"
    ray_address: str = ""


def read_options(config: pytest.Config) -> SalOptions:
    """The session's ``SalOptions``; a ``pytest.UsageError`` before anything runs for a bad
    value, an output that cannot be written or an unknown system."""
    from pytest_sal.engine.search.requirement_search import SearchSettings

    if not hasattr(config, "workerinput"):  # the controller saw the command line; workers got it checked
        _check_space_forms(config)
    root, option = Path(config.rootpath), config.option
    checks = list(option.sal_compare_fail or [])
    compare = option.sal_compare
    if compare == "" or (checks and compare is None):
        compare = str(config.getini("sal_baseline")).strip() or "main"
    cache_size_text = config.getini("sal_cache_size")
    options = SalOptions(
        cache_dir=Path(option.sal_cache_dir or config.getini("sal_cache_dir") or root / ".sal" / "cache"),
        cache_size=option.sal_cache_size or (_ini_size(cache_size_text) if cache_size_text else None),
        use_cache=not option.sal_no_cache,
        cache_frames=bool(option.sal_cache_frames),
        history_dir=Path(option.sal_history_dir or config.getini("sal_history_dir") or root / ".sal" / "history"),
        save_history=not option.sal_no_history,
        save_name=_save_name(option.sal_save),
        compare=compare,
        checks=checks,
        compare_missing=_compare_missing(config),
        runs=None if str(config.getini("sal_runs")).strip() == "auto" else int(_ini_number(config, "sal_runs")),
        seed=int(_ini_number(config, "sal_seed")),
        timeout=_ini_number(config, "sal_timeout"),
        early_stop=not option.sal_no_early_stop and _ini_bool(config, "sal_early_stop"),
        system_name=config.getini("sal_system") or None,
        kitti_segments=_ini_segments(config),
        search=SearchSettings(
            tolerance_pct=_ini_tolerance(config),
            max_trials=int(_ini_number(config, "sal_max_trials")),
            reliability=_ini_probability(config, "sal_reliability"),
            confidence=_ini_probability(config, "sal_confidence"),
            max_runs=int(_ini_number(config, "sal_max_runs")),
        ),
        report_md=Path(option.sal_report_md) if option.sal_report_md else None,
        report_html=Path(option.sal_report_html) if option.sal_report_html else None,
        executor=_executor(config),
        ray_address=_ray_address(config),
    )
    _check_outputs(options)
    _check_system(options.system_name)
    return options


# -- reading and checking ------------------------------------------------------------------------
def _check_space_forms(config: pytest.Config) -> None:
    """A usage error for a ``--sal-*`` path option given with a space (see ``space_form_problem``)."""
    args = [*shlex.split(os.environ.get("PYTEST_ADDOPTS", "")), *config.invocation_params.args]
    problem = space_form_problem(args, str(config.rootpath), None if config.inipath is None else str(config.inipath))
    if problem:
        raise pytest.UsageError(f"pytest-sal: {problem}")


#: the longest ``--sal-save`` name: it becomes part of each run file's name (255 bytes at most on most file systems)
_SAVE_NAME_MAX = 100


def _save_name(name: str | None) -> str | None:
    """``--sal-save``'s name, checked before anything runs: not empty, at most ``_SAVE_NAME_MAX``
    characters (a longer one used to pass and silently leave the baseline unsaved)."""
    if name is None:
        return None
    if not name.strip():
        raise pytest.UsageError("pytest-sal: --sal-save needs a name, e.g. --sal-save=main")
    if len(name) > _SAVE_NAME_MAX:
        raise pytest.UsageError(
            f"pytest-sal: --sal-save: the name is {len(name)} characters long; at most {_SAVE_NAME_MAX} "
            "(it becomes part of the history's file names)"
        )
    return name


def _compare_missing(config: pytest.Config) -> str:
    """``--sal-compare-missing``, else ini ``sal_compare_missing``: ``pass`` or ``fail``."""
    policy = config.option.sal_compare_missing or str(config.getini("sal_compare_missing")).strip()
    if policy not in MISSING_POLICIES:
        raise pytest.UsageError(f"pytest-sal: ini option sal_compare_missing = {policy!r}: expected pass or fail")
    return str(policy)


def _executor(config: pytest.Config) -> str:
    """``--sal-executor``, else ini ``sal_executor``: ``local`` or ``ray`` (a usage error when
    Ray is asked for and not installed)."""
    import importlib.util

    name = config.option.sal_executor or str(config.getini("sal_executor")).strip() or "local"
    if name not in ("local", "ray"):
        raise pytest.UsageError(f"pytest-sal: ini option sal_executor = {name!r}: expected local or ray")
    if name == "ray" and importlib.util.find_spec("ray") is None:
        raise pytest.UsageError("pytest-sal: --sal-executor ray needs Ray, which is not installed: pip install 'pytest-sal[ray]'")
    return name


def _ray_address(config: pytest.Config) -> str:
    """The Ray cluster's address: the one the xdist controller started (a worker), else
    ``--sal-ray-address``, else ini ``sal_ray_address``; checked for its form."""
    workerinput = getattr(config, "workerinput", {})
    if workerinput.get("sal_ray_address"):
        return str(workerinput["sal_ray_address"])
    given = config.option.sal_ray_address
    text = (given if given is not None else str(config.getini("sal_ray_address"))).strip()
    if text and text != "auto" and not _address_form(text):
        where = "--sal-ray-address" if given is not None else "ini option sal_ray_address"
        raise pytest.UsageError(f"pytest-sal: {where} = {text!r}: expected auto, ray://HOST:PORT, HOST:PORT or nothing (a local Ray)")
    return text


def _address_form(text: str) -> bool:
    """``HOST:PORT`` or ``ray://HOST:PORT`` with a port number."""
    host, _, port = text.removeprefix("ray://").rpartition(":")
    return bool(host) and port.isdigit() and 0 < int(port) < 65536


def _ini_number(config: pytest.Config, name: str) -> float:
    """The ini key ``name`` as its number (an ``int`` for the whole-number keys), or a usage error
    that names it and what it takes."""
    kind, smallest, exclusive, what = _INI_NUMBERS[name]
    text = str(config.getini(name)).strip()
    try:
        value = kind(text)
    except ValueError:
        value = None
    if value is None or not math.isfinite(value) or value < smallest or (exclusive and value == smallest):
        raise pytest.UsageError(f"pytest-sal: ini option {name} = {text!r}: expected {what}")
    return float(value) if kind is float else int(value)


def _ini_tolerance(config: pytest.Config) -> float:
    """ini ``sal_tolerance`` as a percent (``pytest_sal.engine.tolerance``); its old form, a bare
    number, is read as one with a deprecation warning (once, by the controller)."""
    from pytest_sal.engine.tolerance import ini_tolerance_percent

    text = str(config.getini("sal_tolerance"))
    try:
        percent, deprecated = ini_tolerance_percent(text)
    except ValueError as exc:
        raise pytest.UsageError(f"pytest-sal: ini option sal_tolerance = {text.strip()!r}: {exc}") from None
    if deprecated and not hasattr(config, "workerinput"):
        config.issue_config_time_warning(SalDeprecationWarning(deprecated), stacklevel=2)
    return percent


def _ini_probability(config: pytest.Config, name: str) -> float:
    """The ini key ``name`` as a probability below 1 (``_ini_number`` checks the lower end)."""
    value = _ini_number(config, name)
    if value >= 1:
        text = str(config.getini(name)).strip()
        raise pytest.UsageError(f"pytest-sal: ini option {name} = {text!r}: expected {_INI_NUMBERS[name][3]}")
    return value


def _ini_bool(config: pytest.Config, name: str) -> bool:
    """The ini key ``name`` as true or false (also yes/no, on/off, 1/0), or a usage error that names it."""
    text = str(config.getini(name)).strip()
    value = {"true": True, "yes": True, "on": True, "1": True, "false": False, "no": False, "off": False, "0": False}.get(text.lower())
    if value is None:
        raise pytest.UsageError(f"pytest-sal: ini option {name} = {text!r}: expected true or false")
    return value


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


def _check_outputs(options: SalOptions) -> None:
    """Stop the session before anything runs when a folder or file it would write cannot be."""
    if options.use_cache and not options.cache_dir.is_dir():  # an existing read-only cache serves what it holds
        _check_writable(options.cache_dir, "cache folder (--sal-cache-dir, ini sal_cache_dir)", folder=True)
    if options.save_history:
        _check_writable(options.history_dir, "history folder (--sal-history-dir, ini sal_history_dir)", folder=True)
    if options.report_html is not None:
        _check_writable(options.report_html, "--sal-report-html", folder=True)
    if options.report_md is not None:
        _check_writable(options.report_md, "--sal-report-md", folder=False)


def _check_writable(path: Path, option: str, folder: bool) -> None:
    """A usage error when ``path`` (a folder, or a file with ``folder=False``) cannot be created
    or written: a nearer existing part is a file, or the existing folder it goes in is read-only."""
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


def _check_system(name: str | None) -> None:
    """A usage error when ini ``sal_system`` names no known SLAM system."""
    if not name:
        return
    from sal_wrappers import SYSTEMS

    if name not in SYSTEMS.names():
        raise pytest.UsageError(f"pytest-sal: ini option sal_system = {name!r}: unknown SLAM system; known: {', '.join(SYSTEMS.names())}")
