"""The cache across processes: a killed compute or put leaves no entry, two processes
compute once, and a waiter computes when the holder fails."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

from cache_parts import BASE, REPO, _key

from pytest_sal.store.cache_keys import cache_key
from pytest_sal.store.content_cache import (
    ContentCache,
)

# ------------------------------------------------------------------------------- processes

CHILD = textwrap.dedent(
    """
    import os, sys, time
    from pathlib import Path
    from pytest_sal.store.content_cache import ContentCache
    root, key, mode, signal_file = sys.argv[1:5]
    cache = ContentCache(root)

    def wait_for(name):
        while not Path(name).exists():
            time.sleep(0.005)

    if mode == "dir-crash":
        def fill(folder):
            (folder / "frame0.png").write_bytes(b"x" * 1000)
            Path(signal_file).touch()
            time.sleep(60)
        cache.compute_dir(key, fill)
    elif mode == "put-crash":
        real_replace = os.replace
        def stuck_replace(src, dst):
            if not str(dst).endswith(key + ".json"):
                return real_replace(src, dst)
            Path(signal_file).touch()
            time.sleep(60)
        os.replace = stuck_replace
        cache.put(key, {"half": "written" * 100})
    elif mode == "race":
        Path(signal_file + ".ready").touch()
        wait_for(signal_file + ".go")
        def trial():
            with open(signal_file + ".count", "a") as f:
                f.write(f"{os.getpid()}\\n")
            time.sleep(0.4)
            return {"pid": os.getpid(), "ate": (0.25, 0.5)}
        data, cached = cache.compute(key, trial)
        print(repr((data, cached)))
    elif mode == "raise":
        def trial():
            Path(signal_file).touch()
            time.sleep(0.4)
            Path(signal_file + ".raised").touch()
            raise RuntimeError("boom in child")
        cache.compute(key, trial)
    """
)


def _child(tmp_path: Path, root: Path, key: str, mode: str) -> tuple[subprocess.Popen, Path]:
    signal_file = tmp_path / f"{mode}.signal"
    proc = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(root), key, mode, str(signal_file)],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    return proc, signal_file


def _wait_for(path: Path, proc: subprocess.Popen) -> None:
    """Until the child writes ``path`` (no clock: the child writes it or exits)."""
    while not path.exists():
        if proc.poll() is not None:
            raise AssertionError(f"child exited {proc.returncode}: {proc.stderr.read()}")
        time.sleep(0.005)


def _kill(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGKILL)
    proc.communicate()  # reaps it and closes its pipes
    assert proc.returncode == -signal.SIGKILL


def test_killed_compute_dir_leaves_no_entry(tmp_path: Path) -> None:
    root = tmp_path / "cache"
    key = _key(1)
    proc, started = _child(tmp_path, root, key, "dir-crash")
    _wait_for(started, proc)
    _kill(proc)
    cache = ContentCache(root)
    assert not cache.path(key, folder=True).exists() and cache.stats()["entries"] == 0
    assert any(p.name.startswith(".tmp-") for p in (root / key[:2]).iterdir())  # the debris exists...
    folder, cached = cache.compute_dir(key, lambda d: (d / "frame0.png").write_bytes(b"ok"))
    assert not cached and (folder / "frame0.png").read_bytes() == b"ok"
    assert [p.name for p in (root / key[:2]).iterdir()] == [key]  # ...and is cleaned


def test_killed_put_leaves_no_entry(tmp_path: Path) -> None:
    root = tmp_path / "cache"
    key = _key(2)
    proc, started = _child(tmp_path, root, key, "put-crash")
    _wait_for(started, proc)
    _kill(proc)
    cache = ContentCache(root)
    assert cache.get(key) is None and cache.stats() == {**cache.stats(), "entries": 0, "bytes": 0}
    assert any(p.name.startswith(".tmp-") for p in (root / key[:2]).iterdir())
    assert cache.compute(key, lambda: {"fresh": 1}) == ({"fresh": 1}, False)
    assert [p.name for p in (root / key[:2]).iterdir()] == [f"{key}.json"]  # the debris went
    assert cache.clear() == 1
    assert list((root / key[:2]).iterdir()) == []


def test_two_processes_compute_once(tmp_path: Path) -> None:
    root = tmp_path / "cache"
    key = cache_key(**BASE)
    proc, signal_file = _child(tmp_path, root, key, "race")
    _wait_for(Path(f"{signal_file}.ready"), proc)
    Path(f"{signal_file}.go").touch()

    def trial() -> dict:
        with open(f"{signal_file}.count", "a") as f:
            f.write(f"{os.getpid()}\n")
        time.sleep(0.4)
        return {"pid": os.getpid(), "ate": (0.25, 0.5)}

    mine, mine_cached = ContentCache(root).compute(key, trial)
    out, err = proc.communicate()
    assert proc.returncode == 0, err
    theirs, theirs_cached = eval(out.strip())
    assert Path(f"{signal_file}.count").read_text().count("\n") == 1  # SLAM ran exactly once
    assert mine == theirs and mine["ate"] == [0.25, 0.5]
    assert sorted([mine_cached, theirs_cached]) == [False, True]


def test_waiter_computes_when_the_holder_fails(tmp_path: Path) -> None:
    root = tmp_path / "cache"
    key = _key(3)
    proc, started = _child(tmp_path, root, key, "raise")
    _wait_for(started, proc)  # the child holds the lock and is inside fn
    child_failed_first: list[bool] = []

    def trial() -> dict[str, str]:
        child_failed_first.append(Path(f"{started}.raised").exists())
        return {"by": "parent"}

    data, cached = ContentCache(root).compute(key, trial)
    assert child_failed_first == [True]  # it waited for the child, then computed once
    assert (data, cached) == ({"by": "parent"}, False)
    _, err = proc.communicate()
    assert proc.returncode == 1 and "boom in child" in err
