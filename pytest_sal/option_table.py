"""The plugin's options as tables: the ``--sal-*`` command-line options (``OPTIONS``) and the
``sal_*`` ini keys (``INI_KEYS``), in the order ``--help`` lists them, and ``add_options``, which
declares them. What they say for one session is read and checked in :mod:`pytest_sal.options`."""

from __future__ import annotations

import argparse
import os
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    from pytest_sal.history.regression import RegressionCheck

__all__ = ["INI_KEYS", "OPTIONS", "PATH_OPTIONS", "VALUE_OPTIONS", "add_options", "space_form_problem"]


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

#: options whose value is a path (``DIR``, ``FILE``): given with a space, pytest takes it for a test path
PATH_OPTIONS = tuple(flag for flag, spec in OPTIONS if spec.get("metavar") in ("DIR", "FILE"))
#: the other options that take a value (refused with a space only when the value is an existing path)
VALUE_OPTIONS = tuple(
    flag for flag, spec in OPTIONS if spec.get("action") not in ("store_true", "store_false") and flag not in PATH_OPTIONS
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


def add_options(parser: pytest.Parser) -> None:
    """Every option of the plugin: ``--sal-*`` in one group (``OPTIONS``), the persistent ones
    mirrored in ini keys (``INI_KEYS``)."""
    group = parser.getgroup("sal", "SLAM robustness (pytest-sal)")
    for flag, spec in OPTIONS:
        group.addoption(flag, **spec)
    for name, text, default in INI_KEYS:
        parser.addini(name, text, default=default)


def space_form_problem(args: Sequence[str], rootdir: str, inifile: str | None) -> str | None:
    """Why ``args`` cannot be run as given, or ``None``.

    pytest picks its rootdir and ini file from the arguments that look like existing paths
    before plugins are loaded, so ``--sal-history-dir /x/history`` written with a space makes
    ``/x/history`` count as a test path there: the rootdir moves, the project's ini file is not
    read and node ids change. A path option given with a space is refused every time (a folder
    that exists only from the second run on would change the outcome between runs); another
    option only when its value names an existing path.
    """
    for option, value in zip(args, args[1:]):
        is_path_option = option in PATH_OPTIONS
        if not (is_path_option or (option in VALUE_OPTIONS and not value.startswith("-") and os.path.exists(value))):
            continue
        return (
            f"write {option}={value} with '=': given as two words, pytest takes {value} for a test path while it "
            f"chooses the rootdir and ini file, before pytest-sal is loaded (rootdir {rootdir}, ini file "
            f"{inifile or 'none'}), so the project's settings and test ids could change"
        )
    return None
