"""The cache's keys: SHA-256 of the documented canonical JSON, stable across processes,
changed by any part and not by order or equal values, unhashable parts named; size parsing and
the default folder."""

from __future__ import annotations

import hashlib
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from cache_parts import BASE, REPO

from pytest_sal.store.byte_sizes import parse_size
from pytest_sal.store.cache_keys import cache_key
from pytest_sal.store.content_cache import (
    CacheError,
    content_cache_dir,
)
from sal_adapters import SalError

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


def test_content_cache_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert content_cache_dir(tmp_path) == tmp_path / ".sal" / "cache"
    monkeypatch.chdir(tmp_path)
    assert content_cache_dir() == tmp_path / ".sal" / "cache"
