"""What the plugin's options say for one session: ``read_options`` gives a ``SalOptions``, read
and checked once at configure time; a bad value is a ``pytest.UsageError`` that names the
option and what it takes. The options themselves are declared in :mod:`pytest_sal.option_table`."""

from __future__ import annotations

import math
import os
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from pytest_sal.history.gate import MISSING_POLICIES
from pytest_sal.option_table import space_form_problem
from sal_adapters.common.errors import SalDeprecationWarning

if TYPE_CHECKING:
    from pytest_sal.engine.search.requirement_search import SearchSettings
    from pytest_sal.history.regression import RegressionCheck

__all__ = ["SalOptions", "read_options"]


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
