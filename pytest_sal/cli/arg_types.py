"""Argument types shared by the ``sal`` subcommands."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from sal_adapters import SalError

__all__ = [
    "add_cache_arguments",
    "add_executor_arguments",
    "add_slam_arguments",
    "age_seconds",
    "executor_from_args",
    "parse_key_values",
    "positive_int",
    "positive_seconds",
]

#: seconds per unit of an age (``30d``, ``12h``, ``90m``, ``2w``, ``45s``)
AGE_UNITS = {"s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0, "w": 604800.0}


def positive_int(text: str) -> int:
    """argparse type: a whole number >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a number >= 1, got {value}")
    return value


def positive_seconds(text: str) -> float:
    """argparse type: a finite number of seconds > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds, got {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"expected seconds > 0, got {text}")
    return value


def age_seconds(text: str) -> float:
    """argparse type: an age such as ``30d`` (s, m, h, d, w) in seconds, > 0."""
    number, unit = text[:-1], text[-1:].lower()
    try:
        value = float(number) * AGE_UNITS[unit]
    except (KeyError, ValueError):
        raise argparse.ArgumentTypeError(f"expected an age such as 30d, 12h, 90m or 2w, got {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"expected an age > 0, got {text!r}")
    return value


def parse_key_values(pairs: list[str], what: str = "--option") -> dict[str, Any]:
    """``["a=1", "b=[1,2]", "c=text"]`` -> ``{"a": 1, "b": [1, 2], "c": "text"}`` (JSON when it parses)."""
    options: dict[str, Any] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise SalError(f"{what} expects KEY=VALUE, got {pair!r}")
        try:
            options[key] = json.loads(value)
        except json.JSONDecodeError:
            options[key] = value
    return options


def add_slam_arguments(command: argparse.ArgumentParser, runs_help: str, default_runs: int | None = 1) -> None:
    """``--system NAME``, ``--system-option KEY=VALUE`` (repeatable), ``--runs N``, ``--timeout S``;
    ``--slam`` and ``--slam-option``, their first names, are still taken."""
    command.add_argument(
        "--system",
        "--slam",
        dest="slam",
        required=True,
        metavar="NAME",
        help="registered SLAM system (entry-point group sal.systems), e.g. reference_vo, orbslam3",
    )
    command.add_argument(
        "--system-option",
        "--slam-option",
        dest="slam_option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="option of the SLAM system, repeatable (values parsed as JSON when they can be)",
    )
    shown = "1 for a deterministic system, 5 for a noisy one" if default_runs is None else "%(default)s"
    command.add_argument("--runs", type=positive_int, default=default_runs, metavar="N", help=f"{runs_help} (default: {shown})")
    command.add_argument(
        "--timeout",
        type=positive_seconds,
        default=600.0,
        metavar="S",
        help="seconds per SLAM run before it is killed (default: %(default)s)",
    )


def add_cache_arguments(command: argparse.ArgumentParser, holds: str, no_cache: str | None = None) -> None:
    """``--cache-dir DIR`` (``holds``: what the cache keeps there) and, with ``no_cache`` (its
    help), ``--no-cache``."""
    command.add_argument("--cache-dir", type=Path, metavar="DIR", help=f"{holds} (default: .sal/cache)")
    if no_cache is not None:
        command.add_argument("--no-cache", action="store_true", help=no_cache)


def add_executor_arguments(cmd: argparse.ArgumentParser) -> None:
    """``--executor`` and ``--ray-address``: where the SLAM runs happen, as the plugin's
    ``--sal-executor`` and ``--sal-ray-address``."""
    cmd.add_argument(
        "--executor",
        choices=("local", "ray"),
        default="local",
        help="where SLAM runs happen: local (here, one at a time) or ray (Ray tasks, several at once; needs pytest-sal[ray]). "
        "Default: %(default)s",
    )
    cmd.add_argument(
        "--ray-address",
        default="",
        metavar="ADDRESS",
        help="Ray cluster of --executor ray: auto, ray://HOST:10001, HOST:PORT, or empty for a local Ray started for this command",
    )


def executor_from_args(args: argparse.Namespace) -> Any:
    """The ``Executor`` that ``--executor`` / ``--ray-address`` ask for (use it in a ``with``)."""
    from pytest_sal.engine.execution.executor_factory import make_executor

    return make_executor(args.executor, args.ray_address)
