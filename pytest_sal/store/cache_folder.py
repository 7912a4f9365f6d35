"""A cache folder on disk: where entries live, their locks and use times, and removing them.

Layout under the cache root::

    locks/<key>.lock           flock(2) lock of a key, present only while someone holds it
    ab/abcdef....json          a result entry (shard = first two hex digits of the key)
    ab/abcdef.../manifest.json a folder entry: its manifest and its files in data/
    ab/.tmp-<key>-...          a write in progress (or left by a killed process; removed later)

An entry's modification time is its last use (strictly increasing within a process), so
``evict`` removes the least recently used entries first. Entries are removed only under their
key's lock, and a folder is renamed away before it is deleted, so no reader sees half of one.
"""

from __future__ import annotations

import errno
import os
import re
import secrets
import shutil
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import NamedTuple

from pytest_sal.store.cache_keys import CacheError
from pytest_sal.store.entry_format import FILES, MANIFEST, file_listing, pack_entry
from sal_adapters.common.file_lock import FileLock
from sal_adapters.common.textfiles import atomic_write_text

__all__ = ["CacheFolder", "StoredEntry", "check_key", "write_refused"]

_KEY = re.compile(r"[0-9a-f]{16,128}")
_TEMP = re.compile(r"\.tmp-(?P<key>[0-9a-f]{16,128})-")
_SHARD = re.compile(r"[0-9a-f]{2}")
_GITIGNORE = "# Created by pytest-sal: the cache; safe to delete (sal cache clear).\n*\n"
#: errno values of a write the file system refuses: read-only (mount or permissions) or full
#: (disk, quota, file size limit).
_REFUSED = frozenset({errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOSPC, errno.EDQUOT, errno.EFBIG})


def write_refused(exc: BaseException) -> str | None:
    """Why the file system refused a write (``"No space left on device"``) when ``exc`` is such
    an ``OSError`` (read-only or full, see ``_REFUSED``), else ``None``."""
    if isinstance(exc, OSError) and exc.errno in _REFUSED:
        return exc.strerror or os.strerror(exc.errno)
    return None


def check_key(key: str) -> str:
    """``key`` when it is 16..128 lowercase hex digits, else ``CacheError``."""
    if not isinstance(key, str) or not _KEY.fullmatch(key):
        raise CacheError(f"invalid cache key {key!r}: expected 16..128 lowercase hex digits (see pytest_sal.store.cache_keys.cache_key)")
    return key


class StoredEntry(NamedTuple):
    """One entry found in the folder: its key, path, kind, size (bytes) and last use (ns)."""

    key: str
    path: Path
    is_dir: bool
    size: int
    used_ns: int


class CacheFolder:
    """The files of one cache root: paths, locks, use times, listing and removing entries.

    Args:
        root: the cache folder (absolute); nothing here creates it.
    """

    def __init__(self, root: Path):
        self.root = root
        self._last_ns = 0

    def create(self) -> str | None:
        """Create the folder and ``locks/``, write a ``.gitignore`` of ``*`` in a new folder (or one
        holding only ``locks/``: its first ``.gitignore`` was refused), and try a write in it:
        ``None`` when writable, else why not (``write_refused``: ``"Read-only file system"``,
        ``"No space left on device"``). A refused ``.gitignore`` leaves no temporary file.

        Raises:
            CacheError: the root is not a folder, or cannot be created for another reason.
        """
        root = self.root
        try:
            fresh = not root.exists() or (root.is_dir() and {child.name for child in root.iterdir()} <= {"locks"})
            root.mkdir(parents=True, exist_ok=True)
            (root / "locks").mkdir(exist_ok=True)
            probe = root / "locks" / f".probe-{os.getpid()}-{secrets.token_hex(4)}"
            os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
            os.unlink(probe)
            gitignore = root / ".gitignore"
            if fresh and not gitignore.exists():
                atomic_write_text(gitignore, _GITIGNORE)
        except (FileExistsError, NotADirectoryError):
            raise CacheError("not a folder; choose another cache folder", root) from None
        except OSError as exc:
            if (refused := write_refused(exc)) is None:
                raise CacheError(f"cannot create the cache folder: {exc.strerror}", root) from None
            return refused
        return None

    # ---- paths and locks

    def entry_path(self, key: str, folder: bool = False) -> Path:
        """``ab/<key>.json``, or when ``folder`` the ``ab/<key>/data`` folder of a folder entry."""
        check_key(key)
        shard = self.root / key[:2]
        return shard / key / FILES if folder else shard / f"{key}.json"

    def temp_path(self, key: str, suffix: str = "") -> Path:
        """A fresh temporary sibling of the entry of ``key`` (``ab/.tmp-<key>-<pid>-<random>``)."""
        return self.root / key[:2] / f".tmp-{key}-{os.getpid()}-{secrets.token_hex(4)}{suffix}"

    def lock(self, key: str) -> FileLock:
        """The ``flock(2)`` lock of ``key`` (``locks/<key>.lock``), not yet acquired."""
        return FileLock(self.root / "locks" / f"{key}.lock")

    # ---- writing entries (the caller holds the key's lock)

    def write_entry(self, key: str, raw: bytes) -> None:
        """Write a result entry's bytes through a temporary sibling and ``os.replace``; the
        temporary file is removed when that fails. A write the file system refuses
        (``write_refused``) raises its ``OSError``, any other ``CacheError``."""
        path = self.entry_path(key)
        temp = self.temp_path(key, ".json")
        try:
            path.parent.mkdir(exist_ok=True)
            self.remove_stale_temps(key[:2], only_key=key, holding=True)  # a killed writer's
            with open(temp, "xb") as handle:
                handle.write(raw)
                handle.flush()
                os.fsync(handle.fileno())
            self.stamp(temp)
            os.replace(temp, path)
        except OSError as exc:
            if write_refused(exc) is not None:
                raise
            raise CacheError(f"cannot write cache entry: {exc.strerror or exc}", path) from None
        finally:
            if temp.exists():
                temp.unlink()

    def write_folder(self, key: str, fill: Callable[[Path], None]) -> None:
        """Let ``fill`` write files into an empty ``data/`` inside a temporary sibling, write the
        manifest of those files beside it (last), and rename the whole entry into place."""
        files = self.entry_path(key, folder=True)
        self.remove_stale_temps(key[:2], only_key=key, holding=True)
        staging = self.temp_path(key)
        work = staging / "entry"
        try:
            (work / FILES).mkdir(parents=True)
            fill(work / FILES)
            if not (work / FILES).is_dir():
                raise CacheError(f"compute_dir: the function removed its output folder {work / FILES}", files)
            (work / MANIFEST).write_bytes(pack_entry(key, {"files": file_listing(work / FILES, hashes=True)}))  # last
            os.rename(work, files.parent)
            self.touch(files.parent)
        finally:
            shutil.rmtree(staging, ignore_errors=True)

    # ---- use times

    def stamp(self, path: Path) -> None:
        """Set ``path``'s modification time to now (wall-clock ns, strictly increasing)."""
        self._last_ns = max(time.time_ns(), self._last_ns + 1)
        os.utime(path, ns=(self._last_ns, self._last_ns))

    def touch(self, path: Path) -> None:
        """``stamp`` an entry just used; an entry evicted meanwhile, or a read-only cache, is fine."""
        try:
            self.stamp(path)
        except OSError:
            pass

    # ---- listing and removing

    def entries(self) -> Iterator[StoredEntry]:
        """Every entry in the shard folders (temporary files and anything else left out)."""
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
                yield StoredEntry(key, Path(child.path), is_dir, size, info.st_mtime_ns)

    def evict(self, limit: int) -> int:
        """Remove least recently used unlocked entries until their total is at most ``limit``
        bytes (and leftover temporary files); returns how many entries went."""
        self.remove_stale_temps()
        entries = sorted(self.entries(), key=lambda entry: (entry.used_ns, entry.key, entry.is_dir))
        total = sum(entry.size for entry in entries)
        removed = 0
        for entry in entries:
            if total <= limit:
                break
            if self._remove_unlocked(entry):
                total -= entry.size
                removed += 1
        return removed

    def clear(self) -> int:
        """Remove every unlocked entry (and leftover temporary files); returns how many went."""
        self.remove_stale_temps()
        return sum(self._remove_unlocked(entry) for entry in list(self.entries()))

    def bury(self, key: str, path: Path) -> bool:
        """Remove the entry of ``key`` at ``path`` (the caller holds the key's lock); a folder is
        renamed away first, so no reader sees half of one. False when it was gone already."""
        try:
            if path.is_dir() and not path.is_symlink():
                grave = self.temp_path(key)
                os.rename(path, grave)
                shutil.rmtree(grave, ignore_errors=True)
            else:
                path.unlink()
        except FileNotFoundError:
            return False
        except OSError as exc:
            raise CacheError(f"cannot remove cache entry: {exc.strerror}", path) from None
        return True

    def remove_stale_temps(self, shard_name: str | None = None, only_key: str | None = None, holding: bool = False) -> None:
        """Remove temporary files and folders whose key nobody holds locked (killed writers):
        in one shard or all, of one key or all; ``holding``: the caller holds ``only_key``'s lock."""
        shards = [self.root / shard_name] if shard_name else list(self._shards())
        for shard in shards:
            for child in _scandir(shard):
                match = _TEMP.match(child.name)
                if match is None or (only_key is not None and match["key"] != only_key):
                    continue
                if holding:
                    _remove_path(Path(child.path))
                    continue
                lock = self.lock(match["key"])
                if lock.acquire(blocking=False):
                    try:
                        _remove_path(Path(child.path))
                    finally:
                        lock.release()

    def _remove_unlocked(self, entry: StoredEntry) -> bool:
        lock = self.lock(entry.key)
        if not lock.acquire(blocking=False):
            return False
        try:
            return self.bury(entry.key, entry.path)
        finally:
            lock.release()

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
