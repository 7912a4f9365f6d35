"""The helper ``sal_adapters.common.atomic`` and the writers on it (issue 12): an atomic write on a full
disk names the file and keeps the old one, ``write_sequence`` into a symlink loop is one error
naming the path, a failed folder replacement keeps the old folder and leaves nothing, folders and
files are swapped together, and ``recover`` puts back an old version and removes dead leftovers."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest
from output_leftovers import leftovers

from sal_adapters import SalError, open_dataset, write_sequence
from sal_adapters.common import atomic
from sal_adapters.common.atomic import Replacement, recover, replacing_dir
from sal_adapters.common.errors import WriteError
from sal_adapters.common.textfiles import atomic_write_text


def test_atomic_write_on_a_full_disk_names_the_file_and_keeps_the_old_one(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = atomic_write_text(tmp_path / "history" / "run.json", "old\n")
    monkeypatch.setattr(os, "fsync", lambda fd: (_ for _ in ()).throw(OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))))

    with pytest.raises(WriteError) as caught:
        atomic_write_text(path, "new\n")

    assert str(caught.value) == f"cannot write {path}: No space left on device"
    assert caught.value.errno == errno.ENOSPC and isinstance(caught.value, SalError)
    assert path.read_text() == "old\n" and os.listdir(path.parent) == ["run.json"]


def test_write_sequence_into_a_symlink_loop_names_the_path(tmp_path: Path) -> None:
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    sequence = open_dataset("synthetic", scene="urban", frames=1, sensor="mono")
    target = tmp_path / "a" / "out"

    with pytest.raises(SalError) as caught:
        write_sequence(sequence, target)

    message = str(caught.value)
    assert str(target) in message and ("symlink loop" in message or "symbolic links" in message)
    assert "\n" not in message


# -------------------------------------------------------------------------------- the helper


def test_a_failed_replacement_keeps_the_old_folder_and_leaves_nothing(tmp_path: Path) -> None:
    target = tmp_path / "out"
    (target / "sub").mkdir(parents=True)
    (target / "sub" / "old.txt").write_text("old")

    with pytest.raises(RuntimeError), replacing_dir(target) as staging:
        (staging / "new.txt").write_text("half")
        raise RuntimeError("the run failed")

    assert (target / "sub" / "old.txt").read_text() == "old" and not (target / "new.txt").exists()
    assert os.listdir(tmp_path) == ["out"]


@pytest.mark.parametrize("exchange", [True, False], ids=["renameat2", "two-renames"])
def test_replacement_swaps_folders_and_files_together(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, exchange: bool) -> None:
    if not exchange:
        monkeypatch.setattr(atomic, "_exchange", lambda a, b: False)
    page = tmp_path / "page"
    (page / "assets").mkdir(parents=True)
    (page / "assets" / "old.png").write_bytes(b"old")
    (page / "index.html").write_text("old page")
    (page / "notes.txt").write_text("the user's")

    with Replacement() as outputs:
        staged = outputs.entries(page)
        (staged / "assets").mkdir()
        (staged / "assets" / "new.png").write_bytes(b"new")
        (staged / "index.html").write_text("new page")
        folder = outputs.folder(tmp_path / "data")
        (folder / "x").write_text("x")
        outputs.write_text(tmp_path / "results.json", "{}\n")

    assert sorted(os.listdir(page)) == ["assets", "index.html", "notes.txt"]
    assert os.listdir(page / "assets") == ["new.png"] and (page / "index.html").read_text() == "new page"
    assert (tmp_path / "data" / "x").read_text() == "x" and (tmp_path / "results.json").read_text() == "{}\n"
    assert leftovers(tmp_path) == []


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_recover_puts_back_an_old_version_and_removes_dead_leftovers(tmp_path: Path) -> None:
    dead = _dead_pid()
    old = tmp_path / f".out.sal-old-{dead}-00ff"  # killed between the two renames
    old.mkdir()
    (old / "kept.txt").write_text("previous")
    (tmp_path / f".out.sal-tmp-{dead}-0a0b").mkdir()  # its complete new copy, never moved in
    (tmp_path / f".other.sal-tmp-{dead}-0c0d").write_text("half")
    running = tmp_path / f".out.sal-tmp-{os.getpid()}-0e0f"  # a replacement in progress
    running.mkdir()

    recover(tmp_path)

    assert (tmp_path / "out" / "kept.txt").read_text() == "previous"
    assert sorted(os.listdir(tmp_path)) == sorted(["out", running.name])


def test_a_write_error_pickles_whole() -> None:
    """A WriteError raised where a run happened (a Ray worker) comes back to the controller whole."""
    import errno
    import pickle

    error = WriteError("/data/out/x.png", OSError(errno.ENOSPC, "No space left on device"))
    back = pickle.loads(pickle.dumps(error))
    assert isinstance(back, WriteError) and str(back) == "cannot write /data/out/x.png: No space left on device"
    assert (back.errno, back.filename) == (errno.ENOSPC, "/data/out/x.png")
