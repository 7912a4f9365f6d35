"""The cache's entries: put/get round trip, layout and .gitignore, corrupt entries, compute
once, exceptions store nothing, folders written as sequences, LRU eviction, clear, and
``sal cache``."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest
from cache_parts import BASE, _key

from pytest_sal.cli.main import main
from pytest_sal.store.cache_keys import cache_key
from pytest_sal.store.content_cache import (
    CacheError,
    CacheWarning,
    ContentCache,
    content_cache_dir,
)
from sal_adapters import open_dataset, write_sequence

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
    assert str(root) in out and "entries  2 (1 runs, 1 sequences)" in out and "2.9 kB" in out  # each entry names its 64-digit key
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
    ContentCache(content_cache_dir()).put(_key(1), {"a": 1})
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
