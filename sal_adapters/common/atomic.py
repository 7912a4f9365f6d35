"""Outputs that appear whole or not at all, with the permissions the user's umask gives.

Every published file or folder is built beside its final path under a hidden name in the same
folder (so the rename stays on one file system), flushed to disk, and renamed into place once
complete; the previous version stays until then. A folder is swapped in one step with Linux's
``renameat2(RENAME_EXCHANGE)`` where the file system offers it, otherwise by two renames (old
aside, new in). A run killed midway leaves only hidden siblings ``.NAME.sal-tmp-PID-HEX`` (a
copy being built) or ``.NAME.sal-old-PID-HEX`` (an old version moved aside): the next
replacement in that folder removes those of processes that are gone, and first puts an old
version back when its name is empty (the run died between the two renames).

Several outputs of one run that must switch as one generation (``sal perturb``'s
``images/<perturbation>/``, ``pipeline_results.json`` and ``config.yaml``) are staged in one
copy of the folder that holds them all, completed at commit with hard links to that folder's
other files, and swapped in with the one step above (``Replacement(within=FOLDER)``): folder by
folder, a kill between two swaps would leave new and old outputs side by side.

New files and folders are created with modes 0666 and 0777, which the kernel reduces by the
process umask (0644 and 0755 under umask 022; private under 077), never ``mkstemp``'s 0600.
Any ``OSError`` while writing becomes one ``WriteError`` naming the path.
"""

from __future__ import annotations

import ctypes
import errno
import os
import re
import secrets
import shutil
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType
from typing import Any

from sal_adapters.common.errors import WriteError

__all__ = ["Replacement", "copy_file", "copy_tree", "recover", "replacing_dir", "staged_file", "writing"]

_LEFTOVER = re.compile(r"(?:\.(?P<name>.+))?\.sal-(?P<kind>tmp|old)-(?P<pid>\d+)-[0-9a-f]+")
_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


@contextmanager
def writing(path: str | os.PathLike[str]) -> Iterator[None]:
    """Turn an ``OSError`` raised inside the block into a ``WriteError`` naming ``path`` (one
    already naming a path passes unchanged)."""
    try:
        yield
    except WriteError:
        raise
    except FileExistsError as exc:  # mkdir(exist_ok=True) met a file where a folder belongs
        raise WriteError(path, OSError(errno.ENOTDIR, f"{exc.filename} is a file, not a folder")) from exc
    except OSError as exc:
        raise WriteError(path, exc) from exc


@contextmanager
def staged_file(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A new empty file beside ``path`` for the block to fill; moved onto ``path`` with
    ``os.replace`` when the block ends without error, removed otherwise. An ``OSError`` in
    the block raises ``WriteError`` naming ``path``."""
    path = Path(path)
    with writing(path):
        path.parent.mkdir(parents=True, exist_ok=True)
        temp = _hidden(path, "tmp")
        _new_file(temp)
        try:
            yield temp
            os.replace(temp, path)
        except BaseException:
            temp.unlink(missing_ok=True)
            raise


class Replacement:
    """Outputs replaced together: each is staged beside its target, and ``commit`` renames
    them into place (in the order they were staged) once every one is complete.

    ``with Replacement() as outputs:`` commits when the block ends without error and removes
    the staged copies otherwise, so the old outputs stay as they were.

    ``Replacement(within=root)``: every output lies under the folder ``root`` and they switch
    as one generation. They are staged in one copy of ``root`` beside it; ``commit`` hard-links
    (where the file system cannot: copies) every other file of the current ``root`` into that
    copy and swaps the copy in with one exchange, so a kill at any moment leaves the old
    generation or the new one, never a mix (between two renames, where the exchange is missing,
    ``recover`` puts the old one back). Files in the copy are never written in place.
    """

    def __init__(self, within: str | os.PathLike[str] | None = None) -> None:
        self._staged: list[tuple[Path, Path, bool]] = []  # (staging, target, entries)
        self._within = None if within is None else Path(within)
        self._tree: Path | None = None  # the staged copy of ``within``

    def __enter__(self) -> Replacement:
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        if kind is None:
            self.commit()
            return
        if isinstance(exc, WriteError) and exc.filename is not None:
            exc.filename = str(self.final(exc.filename))  # name the output, not its staging copy
        self.discard()

    def final(self, path: str | os.PathLike[str]) -> Path:
        """Where ``path``, inside a staged output, will be after the commit (other paths as
        they are)."""
        path = Path(path)
        for staging, target, _ in self._staged:
            if path.is_relative_to(staging):
                return target / path.relative_to(staging)
        return path

    def folder(self, target: str | os.PathLike[str]) -> Path:
        """A new empty folder to fill; it replaces the folder ``target`` at commit."""
        target = Path(target)
        return self._stage(target.parent, self._staging(target), target, entries=False)

    def entries(self, directory: str | os.PathLike[str]) -> Path:
        """A new empty folder whose top-level files and folders each replace the entry of the
        same name in ``directory`` at commit; ``directory``'s other entries stay (a page and
        its ``assets/`` in a folder the user chose)."""
        directory = Path(directory)
        return self._stage(directory, directory / f".sal-tmp-{os.getpid()}-{secrets.token_hex(4)}", directory, entries=True)

    def write_text(self, target: str | os.PathLike[str], text: str) -> Path:
        """Stage the file ``target`` holding ``text`` (UTF-8); it replaces ``target`` at commit."""
        target = Path(target)
        staging = self._stage(target.parent, self._staging(target), target, entries=False, folder=False)
        with writing(target):
            staging.write_text(text, encoding="utf-8", newline="\n")
        return target

    def _staging(self, target: Path) -> Path:
        """Where ``target`` is staged: beside it, or at its place in the staged copy of ``within``."""
        if self._within is None:
            return _hidden(target, "tmp")
        if self._within not in target.parents:
            raise ValueError(f"{target} is not inside {self._within}, the folder this replacement switches")
        with writing(target):
            for folder in target.parents:  # a file where a folder of the output belongs is the user's: refused
                if folder == self._within.parent:
                    break
                if os.path.lexists(folder) and not folder.is_dir():
                    raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), str(folder))
            if self._tree is None:
                self._within.parent.mkdir(parents=True, exist_ok=True)
                recover(self._within.parent)
                self._tree = _hidden(self._within, "tmp")
                self._tree.mkdir()
        return self._tree / target.relative_to(self._within)

    def _stage(self, parent: Path, staging: Path, target: Path, entries: bool, folder: bool = True) -> Path:
        with writing(target):
            if self._tree is not None:
                parent = staging.parent
            parent.mkdir(parents=True, exist_ok=True)
            recover(parent)
            self._staged.append((staging, target, entries))
            if folder:
                staging.mkdir()
            else:
                _new_file(staging)
        return staging

    def commit(self) -> None:
        """Flush every staged output to disk, rename each into place (``within``: the staged
        copy, completed with the current folder's other files, in one swap), then remove the
        old versions (after an error: the staged copies not yet in place)."""
        if self._within is not None and self._tree is not None:
            parts = {staging for staging, _, _ in self._staged}
            tree, self._staged = self._tree, [(self._tree, self._within, False)]
            with writing(self._within):
                if self._within.is_dir():
                    _link_tree(self._within, tree, parts)
        moves: list[tuple[Path, Path]] = []
        for staging, target, entries in self._staged:
            if entries:  # folders before files: a page's assets before the page
                moves += [(child, target / child.name) for child in sorted(staging.iterdir(), key=lambda p: (p.is_file(), p.name))]
            else:
                moves.append((staging, target))
        old: list[Path | None] = []
        try:
            for staging, target in moves:
                with writing(target):
                    _fsync_tree(staging)
            for staging, target in moves:
                with writing(target):
                    old.append(_swap(staging, target))
            for parent in {target.parent for _, target in moves}:
                with writing(parent):
                    _fsync(parent)
        finally:
            self.discard()  # emptied entries folders, and whatever an error left staged
            for path in old:
                if path is not None:
                    _remove(path)

    def discard(self) -> None:
        """Remove every staged output; the targets stay as they are."""
        for staging, _, _ in self._staged:
            _remove(staging)
        self._staged.clear()
        if self._tree is not None:
            _remove(self._tree)
            self._tree = None


@contextmanager
def replacing_dir(target: str | os.PathLike[str]) -> Iterator[Path]:
    """``with replacing_dir(target) as folder:`` fill ``folder``; it replaces the folder
    ``target`` when the block ends without error (see ``Replacement``)."""
    with Replacement() as outputs:
        yield outputs.folder(target)


def copy_file(source: str | os.PathLike[str], target: str | os.PathLike[str]) -> None:
    """Copy the file ``source`` to ``target`` (its folder made) with the umask's mode;
    ``WriteError`` naming ``target`` on failure."""
    target = Path(target)
    with writing(target):
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source, target)


def copy_tree(source: str | os.PathLike[str], target: str | os.PathLike[str]) -> None:
    """Copy the files and folders of ``source`` into the folder ``target`` with the modes new
    files get (the umask's, not the source's); wrap it in ``writing(PATH)`` to name the output
    an error is about."""
    source, target = Path(source), Path(target)
    for folder, _, names in os.walk(source):
        out = target / Path(folder).relative_to(source)
        out.mkdir(parents=True, exist_ok=True)
        for name in names:
            shutil.copyfile(os.path.join(folder, name), out / name)


def _link_tree(old: Path, new: Path, parts: set[Path]) -> None:
    """Complete ``new`` with every entry of ``old`` it lacks: folders made, files hard-linked
    (copied where the file system has no hard links), symbolic links recreated; the staged
    outputs ``parts`` (paths in ``new``) are left as they are, and leftovers of replacements
    (``.NAME.sal-tmp-...``) are not carried over."""
    with os.scandir(old) as found:
        entries = list(found)
    for entry in entries:
        target = new / entry.name
        if _LEFTOVER.fullmatch(entry.name) or target in parts:
            continue
        if entry.is_dir(follow_symlinks=False):
            if not os.path.lexists(target):
                target.mkdir()
            if target.is_dir() and not target.is_symlink():
                _link_tree(Path(entry.path), target, parts)
        elif os.path.lexists(target):
            continue
        elif entry.is_symlink():
            os.symlink(os.readlink(entry.path), target)
        else:
            try:
                os.link(entry.path, target)
            except OSError:  # no hard links here (some network and FUSE file systems)
                shutil.copy2(entry.path, target)


def recover(folder: str | os.PathLike[str]) -> None:
    """Clean up after replacements in ``folder`` whose process was killed: put the newest old
    version back where its name is empty, then remove the other leftovers of processes that
    are gone (a running process's staging is left alone)."""
    folder = Path(folder)
    try:
        names = os.listdir(folder)
    except OSError:
        return
    found = [(match, folder / name) for name in names if (match := _LEFTOVER.fullmatch(name)) and not _alive(int(match["pid"]))]
    found.sort(key=lambda item: _mtime(item[1]), reverse=True)
    for match, path in found:
        name = match["name"]
        if match["kind"] == "old" and name is not None and not os.path.lexists(folder / name):
            os.rename(path, folder / name)
        else:
            _remove(path)


def _hidden(target: Path, kind: str) -> Path:
    return target.with_name(f".{target.name}.sal-{kind}-{os.getpid()}-{secrets.token_hex(4)}")


def _new_file(path: Path) -> None:
    """Create the empty file ``path`` (it must not exist) with mode 0666 less the umask."""
    os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o666))


def _mtime(path: Path) -> float:
    try:
        return path.lstat().st_mtime
    except OSError:  # removed meanwhile by another process's recovery
        return 0.0


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        pass
    return True


def _swap(new: Path, target: Path) -> Path | None:
    """Put ``new`` at ``target``; return where the old version now lies (to remove), if any."""
    if not os.path.lexists(target) or (new.is_file() and not target.is_dir()):
        os.replace(new, target)
        return None
    if _exchange(new, target):
        return new  # the old version now has the staging name
    old = _hidden(target, "old")
    os.rename(target, old)
    try:
        os.rename(new, target)
    except BaseException:
        os.rename(old, target)
        raise
    return old


def _load_renameat2() -> Callable[..., int] | None:
    try:
        function: Any = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):  # not Linux with glibc >= 2.28
        return None
    function.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    function.restype = ctypes.c_int
    return function


_RENAMEAT2 = _load_renameat2()


def _exchange(a: Path, b: Path) -> bool:
    """Swap ``a`` and ``b`` in one step; False where the system or file system cannot (the
    caller's two renames then report any real problem)."""
    return _RENAMEAT2 is not None and _RENAMEAT2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0


def _fsync(path: str | os.PathLike[str]) -> None:
    fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_tree(root: Path) -> None:
    """fsync every file and folder under ``root`` (or the file ``root``); symlinks are skipped."""
    if not root.is_dir():
        _fsync(root)
        return
    for folder, _, names in os.walk(root):
        for name in names:
            path = os.path.join(folder, name)
            if not os.path.islink(path):
                _fsync(path)
        _fsync(folder)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)
