"""What the cache tests share (test_cache_keys.py, test_cache_entries.py,
test_cache_processes.py): the repository root, the key parts they start from and ``_key``, a key per number."""

from __future__ import annotations

from pathlib import Path

from pytest_sal.store.cache_keys import cache_key

__all__ = ["BASE", "REPO", "_key"]


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
