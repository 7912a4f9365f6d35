"""The content-addressed cache of trial results and perturbed sequences.

A trial (perturb a dataset at one severity, run a SLAM system N times, score with evo) is named
by :func:`pytest_sal.cache_keys.cache_key` of everything that decides its outcome: the dataset fingerprint, the module
name, version and canonical parameters, the seed, the system name, options and version, and the
number of runs. :class:`ContentCache` stores one JSON-ready dict (a trial result) or one folder
(a perturbed sequence written with ``write_sequence``) per key, so that an identical trial is
computed once, also when two pytest-xdist workers ask for it at the same moment, and a second
identical run of a suite does not run SLAM at all.

Layout under the cache root (default ``.sal/cache`` under the pytest rootdir)::

    .gitignore                 "*", written when the folder is first created
    locks/<key>.lock           flock(2) lock of a key, present only while someone holds it
    ab/abcdef....json          a result entry (shard = first two hex digits of the key)
    ab/abcdef.../              a folder entry
    ab/.tmp-<key>-...          a write in progress (or left by a killed process; removed later)

Every entry appears by one ``os.replace``/``rename`` of a finished temporary sibling, so readers
see a whole entry or none. Reads set the entry's modification time, and :meth:`ContentCache.evict`
removes the least recently used entries first.

>>> from pytest_sal.cache_keys import cache_key
>>> key = cache_key(dataset="3f2a...", module={"name": "fog", "version": 1, "params": {"visibility_m": 30.0}},
...                 seed=0, system={"name": "orbslam3", "options": {}, "version": "1.0"}, runs=3)
>>> cache = ContentCache(Path(".sal/cache"))                      # doctest: +SKIP
>>> result, was_cached = cache.compute(key, run_trial)            # doctest: +SKIP
"""

from __future__ import annotations

import json
import os
import re
import secrets
import shutil
import time
import warnings
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, NamedTuple

from pytest_sal.cache_keys import CacheError
from sal_adapters.file_lock import FileLock

__all__ = [
    "DEFAULT_CACHE_DIR",
    "CacheError",
    "CacheWarning",
    "ContentCache",
    "command_cache",
    "default_cache_dir",
    "parse_size",
]

#: The cache folder relative to the pytest rootdir (or the current folder for ``sal cache``).
DEFAULT_CACHE_DIR = Path(".sal") / "cache"

_KEY = re.compile(r"[0-9a-f]{16,128}")
_TEMP = re.compile(r"\.tmp-(?P<key>[0-9a-f]{16,128})-")
_SHARD = re.compile(r"[0-9a-f]{2}")
_GITIGNORE = "# Created by pytest-sal: the trial cache; safe to delete (sal cache clear).\n*\n"


class CacheWarning(UserWarning):
    """An unreadable cache entry was ignored (it is recomputed and overwritten)."""


# --------------------------------------------------------------------------------------- keys


def _check_key(key: str) -> str:
    if not isinstance(key, str) or not _KEY.fullmatch(key):
        raise CacheError(f"invalid cache key {key!r}: expected 16..128 lowercase hex digits (see pytest_sal.cache_keys.cache_key)")
    return key


# ---------------------------------------------------------------------------------- helpers


def default_cache_dir(rootdir: str | os.PathLike[str] | None = None) -> Path:
    """``<rootdir>/.sal/cache``; ``rootdir`` defaults to the current folder (the plugin passes
    the pytest rootdir; ``--sal-cache-dir`` replaces the whole path)."""
    return Path(rootdir if rootdir is not None else os.getcwd()).expanduser() / DEFAULT_CACHE_DIR


_UNITS = {"": 1, "b": 1}
for _power, _letter in enumerate("kmgt", start=1):
    _UNITS[_letter] = _UNITS[_letter + "b"] = 1000**_power
    _UNITS[_letter + "i"] = _UNITS[_letter + "ib"] = 1024**_power
_SIZE = re.compile(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([a-z]*)\s*", re.IGNORECASE)


def command_cache(cache_dir: str | os.PathLike[str] | None = None) -> ContentCache:
    """The cache a ``sal`` command uses: ``--cache-dir``, else ``./.sal/cache``."""
    return ContentCache(cache_dir if cache_dir is not None else default_cache_dir())


def parse_size(text: str | int) -> int:
    """Bytes of a size such as ``"500MB"``, ``"2G"``, ``"1.5GiB"``, ``"4096"`` or ``"2 gb"``.

    ``K``/``M``/``G``/``T`` (with or without ``B``) are powers of 1000, ``Ki``/``Mi``/``Gi``/``Ti``
    (with or without ``B``) powers of 1024; case does not matter; fractions are rounded to bytes.

    Raises:
        ValueError: for anything else, quoting the text.
    """
    if isinstance(text, int) and not isinstance(text, bool):
        if text < 0:
            raise ValueError(f"invalid size {text}: must be >= 0 bytes")
        return text
    match = _SIZE.fullmatch(str(text))
    unit = match.group(2).lower() if match else None
    if match is None or unit not in _UNITS:
        raise ValueError(
            f"invalid size {text!r}: expected bytes with an optional unit, e.g. 500MB, 2G, 1.5GiB, 4096 "
            "(K, M, G, T = powers of 1000; Ki, Mi, Gi, Ti = powers of 1024)"
        )
    return round(float(match.group(1)) * _UNITS[unit])


class _Entry(NamedTuple):
    key: str
    path: Path
    is_dir: bool
    size: int
    used_ns: int


# ------------------------------------------------------------------------------------ cache


class ContentCache:
    """Content-addressed store of JSON-ready dicts and folders, safe across processes.

    Args:
        root: the cache folder (created, with a ``.gitignore`` of ``*``, on the first write).
        max_bytes: when set, :meth:`evict` runs after every store and keeps the total size
            of the entries at or under it by removing the least recently used ones.
    """

    def __init__(self, root: str | os.PathLike[str], max_bytes: int | None = None):
        if max_bytes is not None and (isinstance(max_bytes, bool) or not isinstance(max_bytes, int) or max_bytes < 0):
            raise ValueError(f"max_bytes must be None or an int >= 0, got {max_bytes!r}")
        self.root = Path(os.path.abspath(Path(root).expanduser()))
        self.max_bytes = max_bytes
        self._ready = False
        self._last_ns = 0

    def __repr__(self) -> str:
        return f"ContentCache({str(self.root)!r}, max_bytes={self.max_bytes!r})"

    # ---- paths

    def path(self, key: str, folder: bool = False) -> Path:
        """Where the entry of ``key`` lives (a ``.json`` file, or a folder when ``folder``)."""
        _check_key(key)
        return self.root / key[:2] / (key if folder else key + ".json")

    # ---- result entries

    def get(self, key: str) -> dict[str, Any] | None:
        """The stored dict of ``key`` (and mark it used), or None when there is none."""
        path = self.path(key)
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return None
        except NotADirectoryError:
            raise CacheError("not a folder; choose another cache folder", self.root) from None
        except OSError as exc:
            raise CacheError(f"cannot read cache entry: {exc.strerror}", path) from None
        try:
            data = json.loads(text)
        except ValueError as exc:
            data, problem = None, f"not JSON ({exc})"
        else:
            problem = None if isinstance(data, dict) else f"holds a {type(data).__name__}, not a dict"
        if problem is not None:
            warnings.warn(CacheWarning(f"{path}: ignoring cache entry: {problem}"), stacklevel=2)
            return None
        self._touch(path)
        return data

    def put(self, key: str, data: Mapping[str, Any]) -> None:
        """Store ``data`` (a JSON-ready dict; tuples come back as lists) under ``key``, atomically."""
        text = self._encode(key, data)
        self._ensure_root()
        with self.lock(key):
            self._write(key, text)
            self._evict_if_bounded()

    def compute(self, key: str, fn: Callable[[], Mapping[str, Any]]) -> tuple[dict[str, Any], bool]:
        """``(data, was_cached)``: the stored dict of ``key``, or ``fn()`` stored under it.

        Only one process computes a key at a time: the others block on the key's lock and then
        read what it stored. When ``fn`` raises, nothing is stored, the exception propagates
        and the next waiting process computes itself. The returned dict is the stored JSON read
        back, so a computing and a waiting process get equal data.
        """
        data = self.get(key)
        if data is not None:
            return data, True
        self._ensure_root()
        with self.lock(key):
            data = self.get(key)
            if data is not None:
                return data, True
            text = self._encode(key, fn())
            self._write(key, text)
            self._evict_if_bounded()
        return json.loads(text), False

    # ---- folder entries

    def compute_dir(self, key: str, fn: Callable[[Path], None]) -> tuple[Path, bool]:
        """``(folder, was_cached)``: the stored folder of ``key``, or one that ``fn`` filled.

        ``fn`` gets an empty folder inside a temporary sibling of the entry (give it to
        ``write_sequence(sequence, folder)``); when it returns, the folder is renamed into place
        in one step, so a process killed midway leaves no entry (its temporary folder is removed
        by a later ``compute_dir`` of the key, :meth:`evict` or :meth:`clear`). Locking and
        exceptions are as in :meth:`compute`.
        """
        final = self.path(key, folder=True)
        if self._use_dir(final):
            return final, True
        self._ensure_root()
        with self.lock(key):
            if self._use_dir(final):
                return final, True
            self._remove_stale_temps(key[:2], only_key=key, holding=True)
            staging = self._temp_path(key)
            work = staging / "entry"
            try:
                work.mkdir(parents=True)
                fn(work)
                if not work.is_dir():
                    raise CacheError(f"compute_dir: the function removed its output folder {work}", final)
                os.rename(work, final)
                self._touch(final)
            finally:
                shutil.rmtree(staging, ignore_errors=True)
            self._evict_if_bounded()
        return final, False

    # ---- locking

    def lock(self, key: str) -> FileLock:
        """The exclusive lock of ``key`` as a context manager (``with cache.lock(key): ...``).

        It is an ``flock(2)`` on ``root/locks/<key>.lock``, released when the holder exits or
        dies. Not re-entrant: :meth:`compute` and :meth:`put` take it themselves.
        """
        _check_key(key)
        self._ensure_root()
        return FileLock(self.root / "locks" / f"{key}.lock")

    # ---- maintenance

    def evict(self, max_bytes: int | None = None) -> int:
        """Remove least recently used entries until their total size is at most ``max_bytes``
        (default: the cache's own); returns how many were removed.

        Entries whose key another process holds locked (being computed) are skipped, and
        half-written temporary files are never counted as entries. A folder entry is renamed
        away before it is deleted, so no reader sees half of one; a process still reading an
        evicted folder loses it, so size the limit well above what one suite uses.
        """
        limit = self.max_bytes if max_bytes is None else max_bytes
        if limit is None or not self.root.is_dir():
            return 0
        self._remove_stale_temps()
        entries = sorted(self._entries(), key=lambda entry: (entry.used_ns, entry.key, entry.is_dir))
        total = sum(entry.size for entry in entries)
        removed = 0
        for entry in entries:
            if total <= limit:
                break
            if self._remove_entry(entry):
                total -= entry.size
                removed += 1
        return removed

    def clear(self) -> int:
        """Remove every entry (and leftover temporary files); returns how many entries went.

        Entries locked by a running computation are left alone, and so is anything in the
        folder that is not a cache entry.
        """
        if not self.root.is_dir():
            return 0
        self._remove_stale_temps()
        return sum(self._remove_entry(entry) for entry in list(self._entries()))

    def stats(self) -> dict[str, Any]:
        """``{"root", "entries", "results", "folders", "bytes", "max_bytes"}`` of the cache."""
        if self.root.exists() and not self.root.is_dir():
            raise CacheError("not a folder; choose another cache folder", self.root)
        entries = list(self._entries()) if self.root.is_dir() else []
        folders = sum(entry.is_dir for entry in entries)
        return {
            "root": str(self.root),
            "entries": len(entries),
            "results": len(entries) - folders,
            "folders": folders,
            "bytes": sum(entry.size for entry in entries),
            "max_bytes": self.max_bytes,
        }

    # ---- internals

    def _ensure_root(self) -> None:
        if self._ready:
            return
        root = self.root
        try:
            fresh = not root.exists() or (root.is_dir() and not any(root.iterdir()))
            root.mkdir(parents=True, exist_ok=True)
            (root / "locks").mkdir(exist_ok=True)
        except (FileExistsError, NotADirectoryError):
            raise CacheError("not a folder; choose another cache folder", root) from None
        except OSError as exc:
            raise CacheError(f"cannot create the cache folder: {exc.strerror}", root) from None
        gitignore = root / ".gitignore"
        if fresh and not gitignore.exists():
            temp = root / f".gitignore.{secrets.token_hex(4)}.tmp"
            temp.write_text(_GITIGNORE, encoding="utf-8")
            os.replace(temp, gitignore)
        self._ready = True

    def _encode(self, key: str, data: Any) -> str:
        path = self.path(key)
        if not isinstance(data, Mapping):
            raise CacheError(f"cache entry {key[:12]}...: expected a dict, got a {type(data).__name__}", path)
        try:
            return json.dumps(dict(data), ensure_ascii=False)
        except (TypeError, ValueError) as exc:
            raise CacheError(f"cache entry {key[:12]}... is not JSON-ready: {exc}", path) from None

    def _write(self, key: str, text: str) -> None:
        """Write the entry through a temporary sibling and ``os.replace`` (caller holds the lock)."""
        path = self.path(key)
        temp = self._temp_path(key, ".json")
        try:
            path.parent.mkdir(exist_ok=True)
            self._remove_stale_temps(key[:2], only_key=key, holding=True)  # a killed writer's
            with open(temp, "x", encoding="utf-8") as handle:
                handle.write(text)
                handle.flush()
                os.fsync(handle.fileno())
            self._stamp(temp)
            os.replace(temp, path)
        except OSError as exc:
            raise CacheError(f"cannot write cache entry: {exc.strerror or exc}", path) from None
        finally:
            if temp.exists():
                temp.unlink()

    def _temp_path(self, key: str, suffix: str = "") -> Path:
        return self.root / key[:2] / f".tmp-{key}-{os.getpid()}-{secrets.token_hex(4)}{suffix}"

    def _evict_if_bounded(self) -> None:
        if self.max_bytes is not None:
            self.evict()

    def _now_ns(self) -> int:
        """Wall-clock ns, strictly increasing within this process (file times are LRU order)."""
        self._last_ns = max(time.time_ns(), self._last_ns + 1)
        return self._last_ns

    def _stamp(self, path: Path) -> None:
        now = self._now_ns()
        os.utime(path, ns=(now, now))

    def _touch(self, path: Path) -> None:
        try:
            self._stamp(path)
        except OSError:  # evicted meanwhile, or a read-only cache: the data is still good
            pass

    def _use_dir(self, path: Path) -> bool:
        if not path.is_dir():
            return False
        self._touch(path)
        return True

    def _shards(self) -> Iterator[Path]:
        try:
            children = list(os.scandir(self.root))
        except FileNotFoundError:
            return
        except OSError as exc:
            raise CacheError(f"cannot list the cache folder: {exc.strerror}", self.root) from None
        for child in children:
            if _SHARD.fullmatch(child.name) and child.is_dir(follow_symlinks=False):
                yield Path(child.path)

    def _entries(self) -> Iterator[_Entry]:
        for shard in self._shards():
            for child in _scandir(shard):
                name = child.name
                is_dir = child.is_dir(follow_symlinks=False)
                key = name if is_dir else name.removesuffix(".json")
                if not _KEY.fullmatch(key) or key[:2] != shard.name or (not is_dir and not name.endswith(".json")):
                    continue
                try:
                    info = child.stat(follow_symlinks=False)
                    size = _tree_size(Path(child.path)) if is_dir else info.st_size
                except FileNotFoundError:  # removed meanwhile
                    continue
                yield _Entry(key, Path(child.path), is_dir, size, info.st_mtime_ns)

    def _remove_entry(self, entry: _Entry) -> bool:
        lock = FileLock(self.root / "locks" / f"{entry.key}.lock")
        if not lock.acquire(blocking=False):
            return False
        try:
            if entry.is_dir:
                grave = self._temp_path(entry.key)
                try:
                    os.rename(entry.path, grave)
                except FileNotFoundError:
                    return False
                shutil.rmtree(grave, ignore_errors=True)
            else:
                try:
                    entry.path.unlink()
                except FileNotFoundError:
                    return False
            return True
        finally:
            lock.release()

    def _remove_stale_temps(self, shard_name: str | None = None, only_key: str | None = None, holding: bool = False) -> None:
        """Remove temporary files and folders whose key nobody holds locked (killed writers)."""
        shards = [self.root / shard_name] if shard_name else list(self._shards())
        for shard in shards:
            for child in _scandir(shard):
                match = _TEMP.match(child.name)
                if match is None or (only_key is not None and match["key"] != only_key):
                    continue
                if holding:
                    _remove_path(Path(child.path))
                    continue
                lock = FileLock(self.root / "locks" / f"{match['key']}.lock")
                if lock.acquire(blocking=False):
                    try:
                        _remove_path(Path(child.path))
                    finally:
                        lock.release()


def _scandir(folder: Path) -> list[os.DirEntry[str]]:
    try:
        return list(os.scandir(folder))
    except (FileNotFoundError, NotADirectoryError):
        return []


def _tree_size(folder: Path) -> int:
    total = 0
    for base, _dirs, files in os.walk(folder):
        for name in files:
            try:
                total += os.lstat(os.path.join(base, name)).st_size
            except FileNotFoundError:
                pass
    return total


def _remove_path(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        try:
            path.unlink()
        except FileNotFoundError:
            pass
