"""The content-addressed cache: one entry per stored run (a JSON-ready dict) or perturbed
sequence (a folder written with ``write_sequence``).

An entry is named by :func:`pytest_sal.store.cache_keys.cache_key` of everything that decides
it: the dataset fingerprint, the module's name, version and parameters, the seed, the system's
identity and the run's number. So a run is computed once, also when two pytest-xdist workers ask
for it at the same moment, and a second identical session runs no SLAM at all.

Under the cache root (default ``.sal/cache`` under the pytest rootdir) a ``.gitignore`` of
``*`` is written when the folder is first created; the entries, their locks and temporary
siblings are laid out as :mod:`pytest_sal.store.cache_folder` says, and their bytes as
:mod:`pytest_sal.store.entry_format` says.

Every entry appears by one ``os.replace``/``rename`` of a finished temporary sibling, so readers
see a whole entry or none. Reads set the entry's modification time, and :meth:`ContentCache.evict`
removes the least recently used entries first.

Entries check themselves (checksums, a folder's manifest) and name the key they were stored
under, inside what the checksum covers. Every read checks the checksum, the key and the reader's own
``check`` of the data's shape; every use of a folder entry compares the files' names and sizes
with the manifest, and its first use by a :class:`ContentCache` object (once a session) also
their SHA-256. An entry that is not UTF-8, not JSON, has no checksum, does not match it, is
another key's (a valid entry copied), fails ``check`` or has a damaged file is never served: it
is removed under its key's lock and computed again, with one :class:`CacheWarning` naming it and
what was wrong. Entries written before checksums or keys existed are such entries (trial runs
changed keys instead, see ``pytest_sal.engine.execution.trial_runner.RUNNER_VERSION``). A ``compute`` whose ``transient`` hook gives a reason is
returned and not stored (a run the machine decided).

A cache that cannot be written (a read-only mount, a folder this user cannot write, a full disk
or quota) is used as it is: its entries are served, and what it lacks is computed, returned and
not stored, with one :class:`CacheWarning` per :class:`ContentCache` object naming the folder and
why. This holds from the first write the file system refuses, the ``.gitignore`` included; a
refused write leaves no temporary file.

>>> from pytest_sal.store.cache_keys import cache_key
>>> key = cache_key(dataset="3f2a...", module={"name": "fog", "version": 1, "params": {"visibility_m": 30.0}},
...                 seed=0, system={"name": "orbslam3", "options": {}, "version": "1.0"}, run=0)
>>> cache = ContentCache(Path(".sal/cache"))                      # doctest: +SKIP
>>> record, was_cached = cache.compute(key, run_once)            # doctest: +SKIP
"""

from __future__ import annotations

import atexit
import functools
import json
import os
import shutil
import tempfile
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from pytest_sal.store.cache_folder import CacheFolder, check_key, write_refused
from pytest_sal.store.cache_keys import CacheError
from pytest_sal.store.entry_format import MANIFEST, file_listing, listing_mismatch, pack_entry, unpack_entry
from sal_adapters.common.errors import CacheWarning
from sal_adapters.common.file_lock import FileLock
from sal_adapters.common.textfiles import atomic_write

__all__ = ["DEFAULT_CACHE_DIR", "CacheError", "CacheWarning", "ContentCache", "EntryCheck", "command_cache", "content_cache_dir"]

#: The cache folder relative to the pytest rootdir (or the current folder for ``sal cache``).
DEFAULT_CACHE_DIR = Path(".sal") / "cache"

#: What is wrong with a stored dict, in words, or ``None`` (``ContentCache.compute``'s ``check``).
EntryCheck = Callable[[dict[str, Any]], str | None]


# ---------------------------------------------------------------------------------- helpers


def content_cache_dir(rootdir: str | os.PathLike[str] | None = None) -> Path:
    """``<rootdir>/.sal/cache``; ``rootdir`` defaults to the current folder (the plugin passes
    the pytest rootdir; ``--sal-cache-dir`` replaces the whole path)."""
    return Path(rootdir if rootdir is not None else os.getcwd()).expanduser() / DEFAULT_CACHE_DIR


def command_cache(cache_dir: str | os.PathLike[str] | None = None) -> ContentCache:
    """The cache a ``sal`` command uses: ``--cache-dir``, else ``./.sal/cache``."""
    return ContentCache(cache_dir if cache_dir is not None else content_cache_dir())


# ------------------------------------------------------------------------------------ cache


class ContentCache:
    """Content-addressed store of JSON-ready dicts and folders, safe across processes.

    Args:
        root: the cache folder (created, with a ``.gitignore`` of ``*``, on the first write).
        max_bytes: when set, :meth:`evict` runs after every store and keeps the total size
            of the entries at or under it by removing the least recently used ones.

    Attributes:
        unwritable: why entries cannot be stored (``"Read-only file system"``, ``"No space left
            on device"``), from the first store the file system refused; ``None`` until then.
    """

    def __init__(self, root: str | os.PathLike[str], max_bytes: int | None = None):
        if max_bytes is not None and (isinstance(max_bytes, bool) or not isinstance(max_bytes, int) or max_bytes < 0):
            raise ValueError(f"max_bytes must be None or an int >= 0, got {max_bytes!r}")
        self.root = Path(os.path.abspath(Path(root).expanduser()))
        self.max_bytes = max_bytes
        self.unwritable: str | None = None
        self._ready = False
        self._folder = CacheFolder(self.root)
        self._hashed: set[str] = set()  # folder entries whose file hashes this object checked

    def __repr__(self) -> str:
        return f"ContentCache({str(self.root)!r}, max_bytes={self.max_bytes!r})"

    # ---- paths

    def path(self, key: str, folder: bool = False) -> Path:
        """Where the entry of ``key`` lives: a ``.json`` file, or when ``folder`` the folder of
        files that :meth:`compute_dir` returns (``data/`` in the entry, beside its manifest)."""
        return self._folder.entry_path(key, folder)

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
        (nothing happens in a cache that cannot be written)."""
        raw, _ = self._encode(key, data)
        if not self._ensure_root():
            return
        with self.lock(key):
            if self._store(functools.partial(self._folder.write_entry, key, raw)):
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
            if (transient is None or transient(data) is None) and self._store(functools.partial(self._folder.write_entry, key, raw)):
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
        its manifest is discarded and filled again. In a cache that cannot be written a missing
        folder is filled in a temporary folder outside it, removed when the process exits.
        Locking and exceptions are as in :meth:`compute`.
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
            stored = self._store(functools.partial(self._folder.write_folder, key, fn))
        if not stored:
            return _fill_outside(fn), False
        self._hashed.add(key)
        self._evict_if_bounded()
        return files, False

    # ---- report images

    def put_artifact(self, name: str, data: bytes) -> Path | None:
        """Write ``data`` (a report image) to ``artifacts/<name>`` atomically and return its path;
        ``None`` in a cache that cannot be written (nothing of it is left)."""
        path = self.root / "artifacts" / name
        if self._ensure_root() and self._store(functools.partial(atomic_write, path, lambda handle: handle.write(data), binary=True)):
            return path
        return None

    # ---- locking

    def lock(self, key: str) -> FileLock:
        """The exclusive lock of ``key`` as a context manager (``with cache.lock(key): ...``).

        It is an ``flock(2)`` on ``root/locks/<key>.lock``, released when the holder exits or
        dies. Not re-entrant: :meth:`compute` and :meth:`put` take it themselves.
        """
        check_key(key)
        self._ensure_root()
        return self._folder.lock(key)

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
        return self._folder.evict(limit)

    def clear(self) -> int:
        """Remove every entry (and leftover temporary files); returns how many entries went.

        Entries locked by a running computation are left alone, and so is anything in the
        folder that is not a cache entry.
        """
        if not self.root.is_dir():
            return 0
        return self._folder.clear()

    def stats(self) -> dict[str, Any]:
        """``{"root", "entries", "results", "folders", "bytes", "max_bytes"}`` of the cache."""
        if self.root.exists() and not self.root.is_dir():
            raise CacheError("not a folder; choose another cache folder", self.root)
        entries = list(self._folder.entries()) if self.root.is_dir() else []
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
        """Create the cache folder once and try a write in it; False when it cannot be written
        (warned once)."""
        if self._ready or self.unwritable is not None:
            return self._ready
        refused = self._folder.create()
        if refused is not None:
            self._refuse(refused)
            return False
        self._ready = True
        return True

    def _store(self, write: Callable[[], object]) -> bool:
        """``write()`` into the cache (an entry under its key's lock, or a report image); False
        when the cache cannot be written, or the file system refused this write (``write_refused``):
        the writers leave nothing, and the cache stores nothing more (warned once)."""
        if self.unwritable is not None:
            return False
        try:
            write()
        except OSError as exc:
            if (refused := write_refused(exc)) is None:
                raise
            self._refuse(refused)
            return False
        return True

    def _refuse(self, why: str) -> None:
        """From now on store nothing: the file system refused a write, ``why`` (warned once)."""
        if self.unwritable is not None:  # another thread's write was refused first
            return
        self._ready, self.unwritable = False, why
        message = (
            f"the cache at {self.root} cannot be written ({why}): the entries it holds are used, new results are computed and not stored"
        )
        warnings.warn(CacheWarning(message), stacklevel=4)

    def _encode(self, key: str, data: Any) -> tuple[bytes, dict[str, Any]]:
        """The entry's bytes for ``data`` and ``data`` as it reads back (tuples become lists)."""
        path = self.path(key)
        if not isinstance(data, Mapping):
            raise CacheError(f"cache entry {key[:12]}...: expected a dict, got a {type(data).__name__}", path)
        try:
            raw = pack_entry(key, data)
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
        data, problem = unpack_entry(raw, key)
        if data is not None and check is not None:
            problem = check(data)
        if problem is not None:
            return None, problem
        self._folder.touch(path)
        return data, None

    def _discard(self, key: str, path: Path, problem: str | None) -> None:
        """Warn that the entry of ``key`` at ``path`` is bad (when ``problem``) and remove it: the
        caller holds the key's lock, or the cache cannot be written and the entry stays."""
        if problem is None:
            return
        done = "ignored (the cache cannot be written)" if self.unwritable else "removed"
        warnings.warn(CacheWarning(f"{path}: bad cache entry, {done} and computed again: {problem}"), stacklevel=3)
        self._hashed.discard(key)
        if self.unwritable is None:
            self._folder.bury(key, path)

    def _verify_dir(self, key: str) -> tuple[bool, str | None]:
        """``(True, None)`` when the folder entry of ``key`` matches its manifest (names and sizes,
        and on this object's first use of it the SHA-256 of each file; marked used),
        ``(False, None)`` when there is none, ``(False, what is wrong)`` for a bad one."""
        files = self.path(key, folder=True)
        entry = files.parent
        if not entry.is_dir():
            return False, None
        try:
            raw = (entry / MANIFEST).read_bytes()
        except FileNotFoundError:
            return False, f"no {MANIFEST} (written before pytest-sal checked its entries, or a damaged entry)"
        except OSError as exc:
            return False, f"cannot read {MANIFEST} ({exc.strerror})"
        manifest, problem = unpack_entry(raw, key)
        if manifest is None:
            return False, f"{MANIFEST}: {problem}"
        try:
            problem = listing_mismatch(manifest.get("files"), file_listing(files, hashes=key not in self._hashed))
        except OSError as exc:
            problem = f"cannot read {exc.filename} ({exc.strerror})"
        if problem is not None:
            return False, problem
        self._hashed.add(key)
        self._folder.touch(entry)
        return True, None

    def _evict_if_bounded(self) -> None:
        if self.max_bytes is not None:
            self.evict()


def _fill_outside(fn: Callable[[Path], None]) -> Path:
    """A temporary folder outside the cache filled by ``fn`` (the miss of a cache that cannot be written),
    removed when the process exits."""
    folder = Path(tempfile.mkdtemp(prefix="sal-uncached-"))
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    fn(folder)
    return folder
