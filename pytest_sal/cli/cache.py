"""``sal cache info`` and ``sal cache clear``: look at or empty the cache."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from pytest_sal.store.content_cache import DEFAULT_CACHE_DIR, ContentCache

__all__ = ["add_cache_commands", "format_bytes"]

CACHE_EPILOG = """\
examples:
  sal cache info                          entries and size of ./.sal/cache
  sal cache info --cache-dir /tmp/sal --json
  sal cache clear                         remove every stored run and perturbed sequence
  sal cache clear --cache-dir ~/proj/.sal/cache

The cache holds one entry per SLAM run (JSON: its metrics and verdict) and per stored perturbed
sequence (a folder), keyed by the dataset fingerprint, the perturbation and its parameters, the
seed, the system and its options and the run's number, so an identical run never runs SLAM twice. pytest uses <rootdir>/.sal/cache unless
given --sal-cache-dir; a cache folder is safe to delete at any time.
"""


def add_cache_commands(commands: argparse._SubParsersAction) -> None:
    """Add ``cache info`` and ``cache clear`` to the ``sal`` subcommands."""
    cache = commands.add_parser(
        "cache",
        help="show or clear the cache of runs and perturbed sequences",
        description="Look at or empty the cache: one entry per stored run (and per stored perturbed sequence).",
        epilog=CACHE_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = cache.add_subparsers(dest="cache_command", metavar="ACTION", required=True)
    info = actions.add_parser(
        "info",
        help="entries (stored runs, sequences) and total size of the cache",
        description="Print the cache folder, its number of entries and their total size.",
        epilog="example: sal cache info --cache-dir .sal/cache --json",
    )
    info.add_argument("--json", action="store_true", help="print the keys root, entries, results, folders, bytes as JSON")
    clear = actions.add_parser(
        "clear",
        help="remove every entry of the cache",
        description="Remove every stored run and perturbed sequence. Entries that a "
        "running test session is computing right now are left alone; files in the folder that "
        "are not cache entries are never touched.",
        epilog="example: sal cache clear --cache-dir ~/proj/.sal/cache",
    )
    for action in (info, clear):
        action.add_argument(
            "--cache-dir",
            type=Path,
            default=DEFAULT_CACHE_DIR,
            metavar="DIR",
            help="the cache folder (default: %(default)s under the current folder)",
        )
    info.set_defaults(run=_run_info)
    clear.set_defaults(run=_run_clear)


def format_bytes(size: int) -> str:
    """``1234567`` -> ``"1.2 MB"`` (powers of 1000, as ``parse_size`` reads ``MB``)."""
    value = float(size)
    for unit in ("B", "kB", "MB", "GB", "TB"):
        if value < 1000 or unit == "TB":
            return f"{size} B" if unit == "B" else f"{value:.1f} {unit}"
        value /= 1000
    raise AssertionError("unreachable")


def _run_info(args: argparse.Namespace) -> int:
    cache = ContentCache(args.cache_dir.expanduser())
    stats = cache.stats()
    if args.json:
        print(json.dumps({key: stats[key] for key in ("root", "entries", "results", "folders", "bytes")}, indent=2))
        return 0
    print(stats["root"] + ("" if cache.root.is_dir() else "  (does not exist yet)"))
    print(f"  entries  {stats['entries']} ({stats['results']} runs, {stats['folders']} sequences)")
    print(f"  size     {format_bytes(stats['bytes'])}")
    return 0


def _run_clear(args: argparse.Namespace) -> int:
    cache = ContentCache(args.cache_dir.expanduser())
    if cache.root.exists() and not cache.root.is_dir():
        cache.stats()  # raises the "not a folder" error
    if not cache.root.exists():
        print(f"no cache folder at {cache.root}; nothing removed")
        return 0
    before = cache.stats()["entries"]
    removed = cache.clear()
    kept = before - removed
    note = f"; {kept} in use by a running session kept" if kept > 0 else ""
    print(f"removed {removed} cache entries from {cache.root}{note}")
    return 0
