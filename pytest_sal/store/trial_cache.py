"""The content-addressed cache of trial results and perturbed sequences.

A trial (perturb a dataset at one severity, run a SLAM system N times, score with evo) is named
by :func:`pytest_sal.store.cache_keys.cache_key` of everything that decides its outcome: the dataset fingerprint, the module
name, version and canonical parameters, the seed, the system name, options and version, and the
number of runs. :class:`ContentCache` stores one JSON-ready dict (a trial result) or one folder
(a perturbed sequence written with ``write_sequence``) per key, so that an identical trial is
computed once, also when two pytest-xdist workers ask for it at the same moment, and a second
identical run of a suite does not run SLAM at all.

Layout under the cache root (default ``.sal/cache`` under the pytest rootdir)::

    .gitignore                 "*", written when the folder is first created
    locks/<key>.lock           flock(2) lock of a key, present only while someone holds it
    ab/abcdef....json          a result entry (shard = first two hex digits of the key)
    ab/abcdef.../manifest.json a folder entry: the size and SHA-256 of every file in data/,
    ab/abcdef.../data/         and the files (the folder ``compute_dir`` returns)
    ab/.tmp-<key>-...          a write in progress (or left by a killed process; removed later)

Every entry appears by one ``os.replace``/``rename`` of a finished temporary sibling, so readers
see a whole entry or none. Reads set the entry's modification time, and :meth:`ContentCache.evict`
removes the least recently used entries first.

Entries check themselves. A result entry is ``{"sha256": ..., "data": {...}}``, the checksum
being that of the canonical JSON of ``data`` (keys sorted, compact); a folder entry's manifest,
written last, is such an entry too. Every read checks the checksum and the reader's own
``check`` of the data's shape; every use of a folder entry compares the files' names and sizes
with the manifest, and its first use by a :class:`ContentCache` object (once a session) also
their SHA-256. An entry that is not UTF-8, not JSON, has no checksum, does not match it, fails
``check`` or has a damaged file is never served: it is removed under its key's lock and
computed again, with one :class:`CacheWarning` naming it and what was wrong. Entries written
before checksums existed are such entries (trial runs changed keys instead, see
``pytest_sal.engine.trial_runner.RUNNER_VERSION``). A ``compute`` whose ``transient`` hook gives a reason is
returned and not stored (a run the machine decided).

A read-only cache (a read-only mount, or a folder this user cannot write) is used as it is:
its entries are served, and what it lacks is computed and not stored, with one
:class:`CacheWarning` per :class:`ContentCache` object saying so.

>>> from pytest_sal.store.cache_keys import cache_key
>>> key = cache_key(dataset="3f2a...", module={"name": "fog", "version": 1, "params": {"visibility_m": 30.0}},
...                 seed=0, system={"name": "orbslam3", "options": {}, "version": "1.0"}, runs=3)
>>> cache = ContentCache(Path(".sal/cache"))                      # doctest: +SKIP
>>> result, was_cached = cache.compute(key, run_trial)            # doctest: +SKIP
"""

from __future__ import annotations

import atexit
import errno
import hashlib
import json
import os
import re
import secrets
import shutil
import tempfile
import time
import warnings
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, NamedTuple

from pytest_sal.store.cache_keys import CacheError
from sal_adapters.errors import CacheWarning
from sal_adapters.file_lock import FileLock

__all__ = [
    "DEFAULT_CACHE_DIR",
    "CacheError",
    "CacheWarning",
    "ContentCache",
    "EntryCheck",
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
_MANIFEST = "manifest.json"
_FILES = "data"
#: errno values of a write refused because the cache is read-only (mount or permissions).
_READ_ONLY = frozenset({errno.EACCES, errno.EPERM, errno.EROFS})

#: What is wrong with a stored dict, in words, or ``None`` (``ContentCache.compute``'s ``check``).
EntryCheck = Callable[[dict[str, Any]], str | None]


# --------------------------------------------------------------------------------------- keys


def _check_key(key: str) -> str:
    if not isinstance(key, str) or not _KEY.fullmatch(key):
        raise CacheError(f"invalid cache key {key!r}: expected 16..128 lowercase hex digits (see pytest_sal.store.cache_keys.cache_key)")
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

    Attributes:
        read_only: why entries cannot be stored (``"Read-only file system"``), found at the
            first store; ``None`` while the cache is writable.
    """

    def __init__(self, root: str | os.PathLike[str], max_bytes: int | None = None):
        if max_bytes is not None and (isinstance(max_bytes, bool) or not isinstance(max_bytes, int) or max_bytes < 0):
            raise ValueError(f"max_bytes must be None or an int >= 0, got {max_bytes!r}")
        self.root = Path(os.path.abspath(Path(root).expanduser()))
        self.max_bytes = max_bytes
        self.read_only: str | None = None
        self._ready = False
        self._last_ns = 0
        self._hashed: set[str] = set()  # folder entries whose file hashes this object checked

    def __repr__(self) -> str:
        return f"ContentCache({str(self.root)!r}, max_bytes={self.max_bytes!r})"

    # ---- paths

    def path(self, key: str, folder: bool = False) -> Path:
        """Where the entry of ``key`` lives: a ``.json`` file, or when ``folder`` the folder of
        files that :meth:`compute_dir` returns (``data/`` in the entry, beside its manifest)."""
        _check_key(key)
        shard = self.root / key[:2]
        return shard / key / _FILES if folder else shard / f"{key}.json"

    # ---- result entries

    def get(self, key: str, check: EntryCheck | None = None) -> dict[str, Any] | None:
        """The stored dict of ``key`` (and mark it used), or None when there is none or it is
        bad (then it is removed, with a :class:`CacheWarning`); ``check`` as in :meth:`compute`."""
        path = self.path(key)
        data, problem = self._read(key, check)
        if problem is None or not self._ensure_root():
            self._discard(key, path, problem)
            return data
        with self.lock(key):
            data, problem = self._read(key, check)
            self._discard(key, path, problem)
        return data

    def put(self, key: str, data: Mapping[str, Any]) -> None:
        """Store ``data`` (a JSON-ready dict; tuples come back as lists) under ``key``, atomically
        (nothing happens in a read-only cache)."""
        raw, _ = self._encode(key, data)
        if not self._ensure_root():
            return
        with self.lock(key):
            self._write(key, raw)
            self._evict_if_bounded()

    def compute(
        self, key: str, fn: Callable[[], Mapping[str, Any]], *, check: EntryCheck | None = None, transient: EntryCheck | None = None
    ) -> tuple[dict[str, Any], bool]:
        """``(data, was_cached)``: the stored dict of ``key``, or ``fn()`` stored under it.

        Only one process computes a key at a time: the others block on the key's lock and then
        read what it stored. When ``fn`` raises, nothing is stored, the exception propagates
        and the next waiting process computes itself. The returned dict is the stored JSON read
        back, so a computing and a waiting process get equal data.

        Args:
            check: what is wrong with a stored dict in words (``None``: nothing), for the
                fields its reader needs; a stored dict it faults is discarded and recomputed.
            transient: why a computed dict must not be stored (``None``: store it), e.g. a run
                the machine decided; it is returned all the same.
        """
        data, problem = self._read(key, check)
        if data is not None:
            return data, True
        if not self._ensure_root():
            self._discard(key, self.path(key), problem)
            return self._encode(key, fn())[1], False
        with self.lock(key):
            data, problem = self._read(key, check)
            if data is not None:
                return data, True
            self._discard(key, self.path(key), problem)
            raw, data = self._encode(key, fn())
            if transient is None or transient(data) is None:
                self._write(key, raw)
                self._evict_if_bounded()
        return data, False

    # ---- folder entries

    def compute_dir(self, key: str, fn: Callable[[Path], None]) -> tuple[Path, bool]:
        """``(folder, was_cached)``: the stored folder of ``key``, or one that ``fn`` filled.

        ``fn`` gets an empty folder inside a temporary sibling of the entry (give it to
        ``write_sequence(sequence, folder)``); when it returns, the manifest of its files is
        written beside it and the entry is renamed into place in one step, so a process killed
        midway leaves no entry (its temporary folder is removed by a later ``compute_dir`` of
        the key, :meth:`evict` or :meth:`clear`). A stored folder whose files do not match
        its manifest is discarded and filled again. In a read-only cache a missing folder is
        filled in a temporary folder outside it, removed when the process exits. Locking and
        exceptions are as in :meth:`compute`.
        """
        files = self.path(key, folder=True)
        entry = files.parent
        found, problem = self._verify_dir(key)
        if found:
            return files, True
        if not self._ensure_root():
            self._discard(key, entry, problem)
            return _fill_outside(fn), False
        with self.lock(key):
            found, problem = self._verify_dir(key)
            if found:
                return files, True
            self._discard(key, entry, problem)
            self._remove_stale_temps(key[:2], only_key=key, holding=True)
            staging = self._temp_path(key)
            work = staging / "entry"
            try:
                (work / _FILES).mkdir(parents=True)
                fn(work / _FILES)
                if not (work / _FILES).is_dir():
                    raise CacheError(f"compute_dir: the function removed its output folder {work / _FILES}", files)
                (work / _MANIFEST).write_bytes(_pack({"files": _listing(work / _FILES, hashes=True)}))  # last
                os.rename(work, entry)
                self._hashed.add(key)
                self._touch(entry)
            finally:
                shutil.rmtree(staging, ignore_errors=True)
            self._evict_if_bounded()
        return files, False

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

    def _ensure_root(self) -> bool:
        """Create the cache folder once and try a write in it; False when it is read-only
        (warned once)."""
        if self._ready or self.read_only is not None:
            return self._ready
        root = self.root
        try:
            fresh = not root.exists() or (root.is_dir() and not any(root.iterdir()))
            root.mkdir(parents=True, exist_ok=True)
            (root / "locks").mkdir(exist_ok=True)
            probe = root / "locks" / f".probe-{os.getpid()}-{secrets.token_hex(4)}"
            os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
            os.unlink(probe)
        except (FileExistsError, NotADirectoryError):
            raise CacheError("not a folder; choose another cache folder", root) from None
        except OSError as exc:
            if exc.errno not in _READ_ONLY:
                raise CacheError(f"cannot create the cache folder: {exc.strerror}", root) from None
            self.read_only = exc.strerror or str(exc)
            warnings.warn(
                CacheWarning(
                    f"the cache at {root} is read-only ({self.read_only}): the entries it holds are used, new results are computed and not stored"
                ),
                stacklevel=3,
            )
            return False
        gitignore = root / ".gitignore"
        if fresh and not gitignore.exists():
            temp = root / f".gitignore.{secrets.token_hex(4)}.tmp"
            temp.write_text(_GITIGNORE, encoding="utf-8")
            os.replace(temp, gitignore)
        self._ready = True
        return True

    def _encode(self, key: str, data: Any) -> tuple[bytes, dict[str, Any]]:
        """The entry's bytes for ``data`` and ``data`` as it reads back (tuples become lists)."""
        path = self.path(key)
        if not isinstance(data, Mapping):
            raise CacheError(f"cache entry {key[:12]}...: expected a dict, got a {type(data).__name__}", path)
        try:
            raw = _pack(data)
        except (TypeError, ValueError) as exc:
            raise CacheError(f"cache entry {key[:12]}... is not JSON-ready: {exc}", path) from None
        return raw, json.loads(raw)["data"]

    def _read(self, key: str, check: EntryCheck | None) -> tuple[dict[str, Any] | None, str | None]:
        """``(data, None)`` of a good entry (marked used), ``(None, None)`` when there is none,
        ``(None, what is wrong)`` for a bad one."""
        path = self.path(key)
        try:
            raw = path.read_bytes()
        except FileNotFoundError:
            return None, None
        except NotADirectoryError:
            raise CacheError("not a folder; choose another cache folder", self.root) from None
        except OSError as exc:
            return None, f"cannot read it ({exc.strerror})"
        data, problem = _unpack(raw)
        if data is not None and check is not None:
            problem = check(data)
        if problem is not None:
            return None, problem
        self._touch(path)
        return data, None

    def _discard(self, key: str, path: Path, problem: str | None) -> None:
        """Warn that the entry of ``key`` at ``path`` is bad (when ``problem``) and remove it: the
        caller holds the key's lock, or the cache is read-only and the entry stays."""
        if problem is None:
            return
        done = "ignored (the cache is read-only)" if self.read_only else "removed"
        warnings.warn(CacheWarning(f"{path}: bad cache entry, {done} and computed again: {problem}"), stacklevel=3)
        self._hashed.discard(key)
        if self.read_only is None:
            self._bury(key, path)

    def _verify_dir(self, key: str) -> tuple[bool, str | None]:
        """``(True, None)`` when the folder entry of ``key`` matches its manifest (names and sizes,
        and on this object's first use of it the SHA-256 of each file; marked used),
        ``(False, None)`` when there is none, ``(False, what is wrong)`` for a bad one."""
        files = self.path(key, folder=True)
        entry = files.parent
        if not entry.is_dir():
            return False, None
        try:
            raw = (entry / _MANIFEST).read_bytes()
        except FileNotFoundError:
            return False, f"no {_MANIFEST} (written before pytest-sal checked its entries, or a damaged entry)"
        except OSError as exc:
            return False, f"cannot read {_MANIFEST} ({exc.strerror})"
        manifest, problem = _unpack(raw)
        if manifest is None:
            return False, f"{_MANIFEST}: {problem}"
        try:
            problem = _mismatch(manifest.get("files"), _listing(files, hashes=key not in self._hashed))
        except OSError as exc:
            problem = f"cannot read {exc.filename} ({exc.strerror})"
        if problem is not None:
            return False, problem
        self._hashed.add(key)
        self._touch(entry)
        return True, None

    def _write(self, key: str, raw: bytes) -> None:
        """Write the entry through a temporary sibling and ``os.replace`` (caller holds the lock)."""
        path = self.path(key)
        temp = self._temp_path(key, ".json")
        try:
            path.parent.mkdir(exist_ok=True)
            self._remove_stale_temps(key[:2], only_key=key, holding=True)  # a killed writer's
            with open(temp, "xb") as handle:
                handle.write(raw)
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
            return self._bury(entry.key, entry.path)
        finally:
            lock.release()

    def _bury(self, key: str, path: Path) -> bool:
        """Remove the entry of ``key`` at ``path`` (the caller holds the key's lock); a folder is
        renamed away first, so no reader sees half of one. False when it was gone already."""
        try:
            if path.is_dir() and not path.is_symlink():
                grave = self._temp_path(key)
                os.rename(path, grave)
                shutil.rmtree(grave, ignore_errors=True)
            else:
                path.unlink()
        except FileNotFoundError:
            return False
        except OSError as exc:
            raise CacheError(f"cannot remove cache entry: {exc.strerror}", path) from None
        return True

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


def _canonical(data: Mapping[str, Any]) -> str:
    """The JSON text an entry's checksum covers: keys sorted, compact, UTF-8 kept."""
    return json.dumps(dict(data), sort_keys=True, separators=(",", ":"), ensure_ascii=False)


def _sha256(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _pack(data: Mapping[str, Any]) -> bytes:
    """The bytes of an entry holding ``data``: ``{"sha256": <of the canonical JSON>, "data": ...}``."""
    payload = _canonical(data)
    return f'{{"sha256":"{_sha256(payload)}","data":{payload}}}\n'.encode()


def _unpack(raw: bytes) -> tuple[dict[str, Any] | None, str | None]:
    """``(data, None)`` of an entry's bytes, or ``(None, what is wrong)`` in a few words."""
    try:
        entry = json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        return None, f"not UTF-8 (byte 0x{raw[exc.start]:02x} at offset {exc.start})"
    except ValueError as exc:
        return None, f"not JSON ({exc})" if raw.strip() else "empty"
    if not isinstance(entry, dict) or set(entry) != {"sha256", "data"}:
        shape = f"keys {', '.join(sorted(entry)[:5]) or '(none)'}" if isinstance(entry, dict) else f"a JSON {type(entry).__name__}"
        return None, f"no checksum: {shape}, not sha256 and data (written by hand, or before pytest-sal checked its entries)"
    if not isinstance(entry["data"], dict):
        return None, f"its data is a JSON {type(entry['data']).__name__}, not an object"
    if _sha256(_canonical(entry["data"])) != entry["sha256"]:
        return None, "checksum mismatch: changed after it was written"
    return entry["data"], None


def _listing(folder: Path, hashes: bool) -> dict[str, list[Any]]:
    """``{relative path: [size, SHA-256 or None]}`` of every file under ``folder``."""
    out: dict[str, list[Any]] = {}
    for base, _dirs, names in os.walk(folder):
        for name in names:
            path = os.path.join(base, name)
            out[os.path.relpath(path, folder)] = [os.stat(path).st_size, _file_sha256(path) if hashes else None]
    return out


def _file_sha256(path: str) -> str:
    with open(path, "rb") as handle:
        return hashlib.file_digest(handle, "sha256").hexdigest()


def _mismatch(listed: Any, found: dict[str, list[Any]]) -> str | None:
    """How the files ``found`` (``_listing``) differ from a manifest's ``listed`` files."""
    if not isinstance(listed, dict) or not all(isinstance(v, list) and len(v) == 2 for v in listed.values()):
        return f"{_MANIFEST} lists no files"
    for name in sorted(set(listed) | set(found)):
        if name not in found:
            return f"{_FILES}/{name} is missing"
        if name not in listed:
            return f"{_FILES}/{name} is not in {_MANIFEST}"
        (size, digest), (real_size, real_digest) = listed[name], found[name]
        if real_size != size:
            return f"{_FILES}/{name} has {real_size} bytes, {_MANIFEST} says {size}"
        if real_digest is not None and real_digest != digest:
            return f"{_FILES}/{name}: content differs from its SHA-256 in {_MANIFEST}"
    return None


def _fill_outside(fn: Callable[[Path], None]) -> Path:
    """A temporary folder outside the cache filled by ``fn`` (a read-only cache's miss),
    removed when the process exits."""
    folder = Path(tempfile.mkdtemp(prefix="sal-uncached-"))
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    fn(folder)
    return folder


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
