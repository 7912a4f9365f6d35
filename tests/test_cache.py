"""The content-addressed trial cache: keys, atomic entries, cross-process locking, LRU eviction,
``sal cache``."""

from __future__ import annotations

import hashlib
import json
import math
import os
import signal
import subprocess
import sys
import textwrap
import time
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

from pytest_sal.cli.main import main
from pytest_sal.store.byte_sizes import parse_size
from pytest_sal.store.cache_keys import cache_key
from pytest_sal.store.trial_cache import (
    CacheError,
    CacheWarning,
    ContentCache,
    default_cache_dir,
)
from sal_adapters import SalError, open_dataset, write_sequence

REPO = Path(__file__).resolve().parents[1]

BASE = {
    "dataset": "f" * 64,
    "module": {"name": "fog", "version": 2, "params": {"visibility_m": 30.5, "density": "uniform"}},
    "seed": 0,
    "system": {"name": "orbslam3", "options": {"features": 1000, "mono": True}, "version": "1.0.3"},
    "runs": 3,
}


def _key(n: int) -> str:
    return cache_key(n=n)


# ------------------------------------------------------------------------------------- keys


def test_key_is_sha256_of_documented_canonical_json() -> None:
    assert cache_key(b=(1, 2), a=1) == hashlib.sha256(b'{"a":1,"b":[1,2]}').hexdigest()
    # pinned: a change of the canonical form silently invalidates every user's cache
    assert cache_key(**BASE) == "e806b06dce8ee2a7333c94d59586125177b2293053e54934b54d77457d969784"
    assert cache_key(**BASE) == cache_key(**BASE)
    assert len(cache_key(**BASE)) == 64 and all(c in "0123456789abcdef" for c in cache_key(**BASE))


def test_key_is_stable_across_processes() -> None:
    code = "import json,sys; from pytest_sal.store.cache_keys import cache_key; print(cache_key(**json.loads(sys.argv[1])))"
    out = subprocess.run(
        [sys.executable, "-c", code, json.dumps(BASE)],
        capture_output=True,
        text=True,
        check=True,
        cwd=REPO,
        env={**os.environ, "PYTHONHASHSEED": "123"},
    )
    assert out.stdout.strip() == cache_key(**BASE)


def _variants() -> list[dict]:
    out = []
    for change in [
        ("dataset", "e" * 64),
        ("seed", 1),
        ("runs", 4),
        ("module.name", "rain"),
        ("module.version", 3),
        ("module.params.visibility_m", 30.500000001),
        ("module.params.density", "patchy"),
        ("system.name", "reference_vo"),
        ("system.version", "1.0.4"),
        ("system.options.features", 1200),
        ("system.options.mono", False),
        ("system.options.mono", 1),  # bool stays distinct from int
    ]:
        parts = json.loads(json.dumps(BASE))
        *path, last = change[0].split(".")
        target = parts
        for name in path:
            target = target[name]
        target[last] = change[1]
        out.append(parts)
    extra = json.loads(json.dumps(BASE))
    extra["system"]["options"]["extra"] = None
    out.append(extra)
    return out


def test_any_part_change_changes_the_key() -> None:
    keys = {cache_key(**parts) for parts in _variants()}
    assert len(keys) == len(_variants())
    assert cache_key(**BASE) not in keys


def test_order_and_equal_values_do_not_change_the_key() -> None:
    reordered = {
        "runs": 3,
        "system": {"version": "1.0.3", "options": {"mono": True, "features": 1000}, "name": "orbslam3"},
        "seed": 0,
        "module": {"params": {"density": "uniform", "visibility_m": 30.5}, "version": 2, "name": "fog"},
        "dataset": "f" * 64,
    }
    assert cache_key(**reordered) == cache_key(**BASE)
    assert cache_key(x=(1, 2.0)) == cache_key(x=[1, 2])  # tuples are lists, 2.0 is 2
    assert cache_key(x=-0.0) == cache_key(x=0)
    assert cache_key(x=np.float32(0.5), y=np.arange(3)) == cache_key(x=0.5, y=[0, 1, 2])
    assert cache_key(x=Path("a/b")) == cache_key(x="a/b")
    assert cache_key(x={3, 1, 2}) == cache_key(x=frozenset([2, 3, 1]))
    assert cache_key(x=math.nan) == cache_key(x=float("nan")) != cache_key(x=math.inf)
    assert cache_key(x=0.1 + 0.2) != cache_key(x=0.3)


def test_unhashable_parts_name_where_they_are() -> None:
    with pytest.raises(CacheError, match=r"parts\['system'\]\['options'\]\['cb'\].*function"):
        cache_key(system={"options": {"cb": lambda: 1}})
    with pytest.raises(CacheError, match="mapping key 1"):
        cache_key(x={1: "a"})
    assert issubclass(CacheError, SalError)


def test_parse_size() -> None:
    assert parse_size("4096") == 4096
    assert parse_size("500MB") == 500_000_000
    assert parse_size("2G") == parse_size("2gb") == parse_size(" 2 GB ") == 2_000_000_000
    assert parse_size("1.5GiB") == 1536 * 1024**2
    assert parse_size("64Ki") == 65536
    assert parse_size("10B") == 10 and parse_size(0) == 0
    for junk in ["", "GB", "2XB", "-1MB", "1.2.3G", "lots", "2 G B", "nan"]:
        with pytest.raises(ValueError, match=r"invalid size .*e\.g\. 500MB"):
            parse_size(junk)


def test_default_cache_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert default_cache_dir(tmp_path) == tmp_path / ".sal" / "cache"
    monkeypatch.chdir(tmp_path)
    assert default_cache_dir() == tmp_path / ".sal" / "cache"


# ---------------------------------------------------------------------------------- entries


def test_put_get_round_trip_layout_and_gitignore(tmp_path: Path) -> None:
    root = tmp_path / "proj" / ".sal" / "cache"
    cache = ContentCache(root)
    key = cache_key(**BASE)
    assert cache.get(key) is None and not root.exists()  # reading creates nothing
    data = {"ate_m": [0.1, 0.2, math.nan], "runs": ({"ok": True}, {"ok": False}), "note": "ünïcode"}
    cache.put(key, data)
    entry = root / key[:2] / f"{key}.json"
    assert entry.is_file()
    got = cache.get(key)
    assert got["runs"] == [{"ok": True}, {"ok": False}] and got["note"] == "ünïcode"
    assert got["ate_m"][:2] == [0.1, 0.2] and math.isnan(got["ate_m"][2])
    assert "*" in (root / ".gitignore").read_text().splitlines()
    assert list((root / "locks").iterdir()) == []  # lock files go with their holder
    assert [p.name for p in entry.parent.iterdir()] == [entry.name]  # no temp file left
    cache.put(key, {"v": 2})
    assert cache.get(key) == {"v": 2}


def test_gitignore_not_written_into_a_folder_in_use(tmp_path: Path) -> None:
    (tmp_path / "mine.txt").write_text("x")
    ContentCache(tmp_path).put(_key(1), {"a": 1})
    assert not (tmp_path / ".gitignore").exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    ContentCache(empty).put(_key(1), {"a": 1})
    assert (empty / ".gitignore").read_text().splitlines()[-1] == "*"


def test_bad_input_names_the_path(tmp_path: Path) -> None:
    cache = ContentCache(tmp_path / "c")
    with pytest.raises(CacheError, match="invalid cache key"):
        cache.get("../../etc/passwd")
    with pytest.raises(CacheError, match=r"c/[0-9a-f]{2}/.*not JSON-ready"):
        cache.put(_key(1), {"x": object()})
    with pytest.raises(CacheError, match="expected a dict"):
        cache.compute(_key(1), lambda: [1, 2])
    afile = tmp_path / "afile"
    afile.write_text("")
    with pytest.raises(CacheError, match=f"{afile}: not a folder"):
        ContentCache(afile).put(_key(1), {"a": 1})


def test_corrupt_entry_is_a_miss_and_is_recomputed(tmp_path: Path) -> None:
    cache = ContentCache(tmp_path)
    key = _key(1)
    cache.put(key, {"a": 1})
    cache.path(key).write_text('{"a": ')
    with pytest.warns(CacheWarning, match="bad cache entry, removed and computed again: not JSON"):
        data, cached = cache.compute(key, lambda: {"a": 2})
    assert (data, cached) == ({"a": 2}, False) and cache.get(key) == {"a": 2}


def test_compute_runs_once_then_reads(tmp_path: Path) -> None:
    cache = ContentCache(tmp_path)
    calls = []

    def trial() -> dict:
        calls.append(1)
        return {"ate": (1.5, 2.5)}

    first = cache.compute(cache_key(**BASE), trial)
    second = ContentCache(tmp_path).compute(cache_key(**BASE), trial)  # a second run of the suite
    assert first == ({"ate": [1.5, 2.5]}, False) and second == ({"ate": [1.5, 2.5]}, True)
    assert len(calls) == 1


def test_exception_in_fn_stores_nothing(tmp_path: Path) -> None:
    cache = ContentCache(tmp_path)
    key = _key(7)

    def broken(*_: object) -> dict:
        raise RuntimeError("slam crashed")

    with pytest.raises(RuntimeError, match="slam crashed"):
        cache.compute(key, broken)
    with pytest.raises(RuntimeError, match="slam crashed"):
        cache.compute_dir(key, broken)
    assert cache.get(key) is None and cache.stats()["entries"] == 0
    assert [p for p in tmp_path.rglob("*") if p.name.startswith(".tmp-")] == []
    assert list((tmp_path / "locks").iterdir()) == []
    assert cache.compute(key, lambda: {"ok": 1}) == ({"ok": 1}, False)


def test_compute_dir_with_write_sequence(tmp_path: Path) -> None:
    images = tmp_path / "images"
    images.mkdir()
    rng = np.random.default_rng(0)
    for i in range(3):
        cv2.imwrite(str(images / f"{i:06d}.png"), rng.integers(0, 255, (12, 16, 3), dtype=np.uint8))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # assumed intrinsics
        sequence = open_dataset("folder", images, fps=10)
    cache = ContentCache(tmp_path / "cache")
    key = cache_key(dataset=sequence.fingerprint, module=None)
    calls = []

    def fill(folder: Path) -> None:
        assert folder.is_dir() and not any(folder.iterdir())
        calls.append(write_sequence(sequence, folder).relative_to(folder))

    folder, cached = cache.compute_dir(key, fill)
    assert not cached and folder == cache.path(key, folder=True) and folder.is_dir()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        back = open_dataset("folder", folder / calls[0])
    assert len(back) == 3 and np.array_equal(back[2].image, sequence[2].image)
    again, cached = cache.compute_dir(key, fill)
    assert again == folder and cached and len(calls) == 1
    assert [p.name for p in folder.parent.parent.iterdir()] == [key]  # nothing but the entry
    assert sorted(p.name for p in folder.parent.iterdir()) == ["data", "manifest.json"]
    stats = cache.stats()
    assert stats["folders"] == 1 and stats["bytes"] > 0


# ------------------------------------------------------------------------------- processes

CHILD = textwrap.dedent(
    """
    import os, sys, time
    from pathlib import Path
    from pytest_sal.store.trial_cache import ContentCache
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


def _wait_for(path: Path, proc: subprocess.Popen, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists():
        if proc.poll() is not None:
            raise AssertionError(f"child exited {proc.returncode}: {proc.stderr.read()}")
        if time.monotonic() > deadline:
            proc.kill()
            raise AssertionError(f"child never wrote {path}")
        time.sleep(0.005)


def _kill(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=10)  # reaps it and closes its pipes
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
    out, err = proc.communicate(timeout=20)
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
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 1 and "boom in child" in err


# --------------------------------------------------------------------------- eviction, clear


def test_lru_eviction_keeps_recently_read_entries(tmp_path: Path) -> None:
    payload = {"x": "y" * 1000}
    size = len(json.dumps(payload))
    cache = ContentCache(tmp_path, max_bytes=int(3.5 * size))
    a, b, c, d, e = (_key(i) for i in range(5))
    for key in (a, b, c):
        cache.put(key, payload)
    assert cache.stats()["entries"] == 3
    assert cache.get(a) == payload  # a is now the most recently used
    cache.put(d, payload)  # over the limit: b, the least recently used, goes
    assert [cache.path(k).exists() for k in (a, b, c, d)] == [True, False, True, True]
    assert cache.stats()["bytes"] <= cache.max_bytes
    assert cache.compute(c, dict) == (payload, True)  # reading c: now a is the oldest
    cache.compute(e, lambda: payload)
    assert {k for k in (a, b, c, d, e) if cache.path(k).exists()} == {c, d, e}
    # an entry a process holds locked (computing it) is never evicted
    with cache.lock(d):
        assert cache.evict(max_bytes=0) == 2
        assert cache.path(d).exists()
    assert cache.evict(max_bytes=0) == 1 and cache.stats()["entries"] == 0


def test_folder_entries_are_evicted_by_size(tmp_path: Path) -> None:
    cache = ContentCache(tmp_path, max_bytes=5000)
    first, _ = cache.compute_dir(_key(1), lambda d: (d / "img.png").write_bytes(b"1" * 3000))
    cache.put(_key(2), {"small": 1})
    second, _ = cache.compute_dir(_key(3), lambda d: (d / "img.png").write_bytes(b"3" * 3000))
    assert not first.exists() and second.is_dir() and cache.get(_key(2)) == {"small": 1}
    assert [p.name for p in first.parent.parent.iterdir()] == []  # removed whole, no debris


def test_clear_removes_entries_only(tmp_path: Path) -> None:
    cache = ContentCache(tmp_path / "c")
    cache.put(_key(1), {"a": 1})
    cache.put(_key(2), {"b": 2})
    cache.compute_dir(_key(3), lambda d: (d / "f").write_text("x"))
    (cache.root / "README").write_text("mine")
    (cache.root / "ab").mkdir(exist_ok=True)
    (cache.root / "ab" / "notakey.json").write_text("{}")
    assert cache.stats()["entries"] == 3
    assert cache.clear() == 3
    assert cache.stats()["entries"] == 0 and cache.clear() == 0
    assert (cache.root / "README").exists() and (cache.root / "ab" / "notakey.json").exists()
    assert (cache.root / ".gitignore").exists()
    assert ContentCache(tmp_path / "missing").clear() == 0


# ------------------------------------------------------------------------------------- CLI


def test_cli_info_and_clear(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "cache"
    assert main(["cache", "info", "--cache-dir", str(root)]) == 0
    assert "does not exist yet" in capsys.readouterr().out
    cache = ContentCache(root)
    cache.put(_key(1), {"a": "x" * 2000})
    cache.compute_dir(_key(2), lambda d: (d / "f").write_text("y" * 500))
    assert main(["cache", "info", "--cache-dir", str(root)]) == 0
    out = capsys.readouterr().out
    assert str(root) in out and "entries  2 (1 trial results, 1 sequences)" in out and "2.8 kB" in out
    assert main(["cache", "info", "--cache-dir", str(root), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info == {"root": str(root), "entries": 2, "results": 1, "folders": 1, "bytes": cache.stats()["bytes"]}
    manifest = cache.path(_key(2), folder=True).parent / "manifest.json"
    assert info["bytes"] == cache.path(_key(1)).stat().st_size + 500 + manifest.stat().st_size
    assert main(["cache", "clear", "--cache-dir", str(root)]) == 0
    assert f"removed 2 cache entries from {root}" in capsys.readouterr().out
    assert cache.stats()["entries"] == 0
    assert main(["cache", "clear", "--cache-dir", str(tmp_path / "typo")]) == 0  # a mistyped folder is not "0 removed"
    assert capsys.readouterr().out == f"no cache folder at {tmp_path / 'typo'}; nothing removed\n"
    assert not (tmp_path / "typo").exists()


def test_cli_default_dir_errors_and_help(tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    ContentCache(default_cache_dir()).put(_key(1), {"a": 1})
    assert main(["cache", "clear"]) == 0
    assert "removed 1 cache entries" in capsys.readouterr().out
    (tmp_path / "afile").write_text("")
    assert main(["cache", "info", "--cache-dir", "afile"]) == 2
    assert f"sal: error: {tmp_path / 'afile'}: not a folder" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:
        main(["cache", "--help"])
    assert exit_info.value.code == 0
    help_text = capsys.readouterr().out
    assert "examples:" in help_text and "sal cache clear" in help_text
