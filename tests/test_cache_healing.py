"""Cache entries that heal (issue 12, point 5): each attack on a stored trial run or cached frame
(also a valid entry of another trial copied under its key, issue 23, item 6) ends in one
CacheWarning naming the entry and a recomputed, identical result; a read-only cache
serves what it holds, and a cache on a full disk costs the cache, not the verdict (issue 23,
item 5); a failure the machine decided is not stored."""

from __future__ import annotations

import hashlib
import json
import math
import signal
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from faults import fill_disk_under, refuse_writes_under, stamps

from pytest_sal import tracking_rate
from pytest_sal.engine.execution.run_job import cached_sequence
from pytest_sal.engine.execution.trial_runner import TrialRunner
from pytest_sal.engine.requirements import Requirement
from pytest_sal.store.cache_keys import cache_key
from pytest_sal.store.content_cache import CacheWarning, ContentCache
from pytest_sal.testing import FakeSlam
from sal_adapters import Sequence, open_dataset
from sal_modules import create, fog, perturb
from sal_wrappers import RunResult

QUIET = {"loadavg": [0.1, 0.1, 0.1], "cpus": 16, "usable_cpus": 16}


@pytest.fixture(autouse=True)
def quiet_machine(monkeypatch: pytest.MonkeyPatch) -> None:
    """The machine these tests run on is shared: its load average must not decide a verdict."""
    monkeypatch.setattr("pytest_sal.engine.execution.run_job.machine_load", lambda: QUIET)


def runner(tmp_path: Path, system: FakeSlam) -> TrialRunner:
    dataset = open_dataset("synthetic", scene="indoor", frames=8, sensor="rgbd")
    requirement = Requirement.build([tracking_rate >= 0.5, fog.visibility_m >= 25])
    return TrialRunner(
        dataset, fog.visibility_m.ref(), system, requirement, cache=ContentCache(tmp_path / "cache"), workdir=tmp_path / "work"
    )


def cache_warnings(fn: Callable[[], Any]) -> tuple[Any, list[str]]:
    """``fn()`` and the messages of the CacheWarnings it gave."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        value = fn()
    return value, [str(w.message) for w in caught if issubclass(w.category, CacheWarning)]


def calls(path: Path) -> int:
    return len(path.read_text().splitlines()) if path.exists() else 0


def repacked(raw: bytes, data: dict[str, Any]) -> bytes:
    """The entry ``raw`` holding ``data`` instead, with a checksum that matches (a forger's edit)."""
    key = json.loads(raw)["key"]
    signed = json.dumps({"data": data, "key": key}, sort_keys=True, separators=(",", ":"), ensure_ascii=False)
    return json.dumps({"sha256": hashlib.sha256(signed.encode()).hexdigest(), "key": key, "data": data}).encode()


def keyless(raw: bytes) -> bytes:
    """The entry ``raw`` in the format before entries named their key: its checksum covers only its data."""
    data = json.loads(raw)["data"]
    payload = json.dumps(data, sort_keys=True, separators=(",", ":"), ensure_ascii=False)
    return json.dumps({"sha256": hashlib.sha256(payload.encode()).hexdigest(), "data": data}).encode()


def edited(field: str, value: float) -> Callable[[bytes], bytes]:
    def edit(raw: bytes) -> bytes:
        entry = json.loads(raw)
        entry["data"]["metrics"][field] = value  # the checksum is left as it was
        return json.dumps(entry).encode()

    return edit


def forged(field: str, value: Any) -> Callable[[bytes], bytes]:
    def edit(raw: bytes) -> bytes:
        data = json.loads(raw)["data"]
        data["metrics"][field] = value
        return repacked(raw, data)

    return edit


ATTACKS: dict[str, tuple[Callable[[bytes], bytes], str]] = {
    "byte 0xff": (lambda raw: raw[:40] + b"\xff" + raw[41:], "not UTF-8 (byte 0xff at offset 40)"),
    "{}": (lambda raw: b"{}", "no checksum: keys (none)"),
    "truncated": (lambda raw: raw[: len(raw) // 2], "not JSON ("),
    "empty": (lambda raw: b"", ": empty"),
    "ATE edited to 99": (edited("ate_rmse", 99.0), "checksum mismatch"),
    "ATE edited to NaN": (edited("ate_rmse", math.nan), "checksum mismatch"),
    "tracking rate edited to 1": (edited("tracking_rate", 1.0), "checksum mismatch"),
    "{} with its checksum": (lambda raw: repacked(raw, {}), "no 'metrics' object"),
    "NaN with its checksum": (forged("ate_rmse", math.nan), "metrics.ate_rmse is nan, not a finite number or null"),
    "text with its checksum": (forged("tracking_rate", "0.9"), "metrics.tracking_rate is '0.9'"),
    "metric dropped, with its checksum": (
        lambda raw: repacked(raw, {**json.loads(raw)["data"], "metrics": {}}),
        "metrics.ate_rmse is missing",
    ),
    "starved as text, with its checksum": (forged("starved", "no"), "metrics.starved is not true or false"),
    "key edited": (lambda raw: raw.replace(json.loads(raw)["key"].encode(), b"0" * 64), "checksum mismatch"),
    "no key (the format before issue 23)": (keyless, "names no key (written before pytest-sal entries named their key"),
}


@pytest.mark.parametrize("attack", list(ATTACKS))
def test_an_attacked_trial_entry_is_discarded_and_run_again(tmp_path: Path, attack: str) -> None:
    damage, expected = ATTACKS[attack]
    log = tmp_path / "calls.jsonl"
    first = runner(tmp_path, FakeSlam(calls_file=str(log))).run_trial(20.0)
    session = runner(tmp_path, FakeSlam(calls_file=str(log)))
    entry = session.cache.path(session.key(20.0, 0))
    entry.write_bytes(damage(entry.read_bytes()))
    again, messages = cache_warnings(lambda: session.run_trial(20.0))
    assert len(messages) == 1 and messages[0].startswith(f"{entry}: bad cache entry, removed and computed again: ")
    assert expected in messages[0] and "\n" not in messages[0]
    assert calls(log) == 2 and not again.cached and again.metrics == first.metrics and again.passed == first.passed
    healed, messages = cache_warnings(lambda: runner(tmp_path, FakeSlam(calls_file=str(log))).run_trial(20.0))
    assert messages == [] and healed.cached and healed.metrics == first.metrics and calls(log) == 2


def test_a_valid_entry_copied_under_another_key_is_not_served(tmp_path: Path) -> None:
    log = tmp_path / "calls.jsonl"
    first = runner(tmp_path, FakeSlam(calls_file=str(log)))
    holds, fails = first.run_trial(40.0), first.run_trial(10.0)
    assert holds.passed and not fails.passed
    entry = first.cache.path(first.key(10.0, 0))
    entry.write_bytes(first.cache.path(first.key(40.0, 0)).read_bytes())  # the passing trial's entry, checksum and all
    again, messages = cache_warnings(lambda: runner(tmp_path, FakeSlam(calls_file=str(log))).run_trial(10.0))
    assert not again.passed and not again.cached and again.metrics == fails.metrics and calls(log) == 3
    assert len(messages) == 1 and messages[0].startswith(f"{entry}: bad cache entry, removed and computed again: it is the entry of key ")
    assert f"not of {first.key(10.0, 0)[:12]}... (copied from another entry)" in messages[0]


def foggy_room() -> Sequence:
    return perturb(open_dataset("synthetic", scene="indoor", frames=6, sensor="rgbd"), create("fog", visibility_m=4.0), seed=3)


def assert_same_frames(copy: Sequence, fresh: Sequence) -> None:
    assert len(copy) == len(fresh)
    for k in range(len(fresh)):
        np.testing.assert_array_equal(copy[k].image, fresh[k].image)
        np.testing.assert_allclose(copy[k].depth, fresh[k].depth, atol=1e-6)


@pytest.mark.parametrize("damage", ["truncated", "same size, other bytes", "removed", "added", "no manifest"])
def test_a_damaged_cached_frame_is_rendered_again(tmp_path: Path, damage: str) -> None:
    foggy = foggy_room()
    cache = ContentCache(tmp_path / "cache")
    cached_sequence(foggy, cache)
    files = cache.path(cache_key(frames=foggy.fingerprint), folder=True)
    manifest = (files.parent / "manifest.json").read_bytes()
    frame = sorted(p for p in files.rglob("*.png"))[3]
    raw = frame.read_bytes()
    if damage == "truncated":
        frame.write_bytes(raw[: len(raw) // 3])
    elif damage == "same size, other bytes":
        frame.write_bytes(raw[:100] + bytes(b ^ 0x5A for b in raw[100:200]) + raw[200:])
    elif damage == "removed":
        frame.unlink()
    elif damage == "added":
        (files / "stray.png").write_bytes(raw)
    else:  # an entry from before manifests
        (files.parent / "manifest.json").unlink()
    copy, messages = cache_warnings(lambda: cached_sequence(foggy, ContentCache(tmp_path / "cache")))  # the next session
    assert len(messages) == 1 and messages[0].startswith(f"{files.parent}: bad cache entry, removed and computed again: ")
    expected = {
        "truncated": "bytes, manifest.json says",
        "same size, other bytes": "content differs from its SHA-256",
        "removed": "is missing",
        "added": "data/stray.png is not in manifest.json",
        "no manifest": "no manifest.json",
    }[damage]
    assert expected in messages[0]
    assert_same_frames(copy, foggy)
    assert (files.parent / "manifest.json").read_bytes() == manifest  # the same files, byte for byte
    _, messages = cache_warnings(lambda: cached_sequence(foggy, ContentCache(tmp_path / "cache")))
    assert messages == []


@pytest.fixture
def read_only(monkeypatch: pytest.MonkeyPatch) -> Callable[[Path], None]:
    """``read_only(root)``: from now on every write under ``root`` fails with EROFS, as on a
    read-only mount (the tests run as root, which ignores file modes)."""
    return lambda root: refuse_writes_under(root, monkeypatch.setattr)


def test_a_read_only_cache_serves_its_entries_and_stores_nothing(tmp_path: Path, read_only: Callable[[Path], None]) -> None:
    root = tmp_path / "cache"
    writer = ContentCache(root)
    writer.put(cache_key(n=1), {"ate": 0.5})
    writer.put(cache_key(n=9), {"ate": 0.9})
    writer.compute_dir(cache_key(n=2), lambda folder: (folder / "f.png").write_bytes(b"png"))
    writer.path(cache_key(n=9)).write_bytes(b"\xff")
    before = stamps(root)
    read_only(root)
    cache = ContentCache(root)

    def session() -> list[Any]:
        return [
            cache.compute(cache_key(n=1), lambda: {"ate": 7.0}),
            cache.compute_dir(cache_key(n=2), lambda folder: None),
            cache.compute(cache_key(n=3), lambda: {"ate": 0.3}),
            cache.compute(cache_key(n=4), lambda: {"ate": 0.4}),
            cache.compute_dir(cache_key(n=5), lambda folder: (folder / "g.png").write_bytes(b"new")),
            cache.compute(cache_key(n=9), lambda: {"ate": 0.95}),
        ]

    (hit, folder_hit, miss, other_miss, folder_miss, bad), messages = cache_warnings(session)
    assert hit == ({"ate": 0.5}, True) and folder_hit == (cache.path(cache_key(n=2), folder=True), True)
    assert miss == ({"ate": 0.3}, False) and other_miss == ({"ate": 0.4}, False) and bad == ({"ate": 0.95}, False)
    assert folder_miss[1] is False and (folder_miss[0] / "g.png").read_bytes() == b"new" and root not in folder_miss[0].parents
    assert (
        messages[0]
        == f"the cache at {root} cannot be written (Read-only file system): the entries it holds are used, new results are computed and not stored"
    )
    assert len(messages) == 2 and messages[1].startswith(
        f"{cache.path(cache_key(n=9))}: bad cache entry, ignored (the cache cannot be written)"
    )
    assert cache.unwritable == "Read-only file system" and cache.get(cache_key(n=1)) == {"ate": 0.5}
    assert stamps(root) == before  # nothing written, removed or touched


FULL = "cannot be written (No space left on device): the entries it holds are used, new results are computed and not stored"


def leftovers(root: Path) -> list[Path]:
    """Temporary files and folders of writes that failed."""
    return [p for p in root.rglob("*") if p.name.startswith(".tmp-") or ".tmp" in p.suffixes or ".sal-tmp" in p.name]


def test_a_new_cache_on_a_full_disk_costs_the_cache_not_the_verdict(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    log = tmp_path / "calls.jsonl"
    root = tmp_path / "cache"
    fill_disk_under(root, monkeypatch.setattr)
    session = runner(tmp_path, FakeSlam(calls_file=str(log)))
    (holds, fails), messages = cache_warnings(lambda: (session.run_trial(40.0), session.run_trial(10.0)))
    assert holds.passed and not fails.passed and not holds.cached and not fails.cached
    assert messages == [f"the cache at {root} {FULL}"]
    assert not [p for p in root.rglob("*") if p.is_file()]  # no entry, no .gitignore, nothing half-written
    assert session.cache is not None and session.cache.unwritable == "No space left on device"

    monkeypatch.undo()  # room again: the next session stores its results
    again, messages = cache_warnings(lambda: runner(tmp_path, FakeSlam(calls_file=str(log))).run_trial(10.0))
    assert messages == [] and not again.passed and calls(log) == 3
    assert (root / ".gitignore").is_file() and runner(tmp_path, FakeSlam(calls_file=str(log))).run_trial(10.0).cached


def test_a_cache_that_fills_up_serves_what_it_holds_and_stores_nothing_more(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    root = tmp_path / "cache"
    cache = ContentCache(root)
    cache.put(cache_key(n=1), {"ate": 0.5})
    fill_disk_under(root, monkeypatch.setattr)

    def rest_of_session() -> list[object]:
        return [
            cache.compute(cache_key(n=2), lambda: {"ate": 0.2}),
            cache.put(cache_key(n=3), {"ate": 0.3}),
            cache.compute_dir(cache_key(n=4), lambda folder: (folder / "f.png").write_bytes(b"png")),
            cache.compute(cache_key(n=1), lambda: {"ate": 7.0}),
        ]

    (miss, _, (folder, folder_cached), hit), messages = cache_warnings(rest_of_session)
    assert miss == ({"ate": 0.2}, False) and hit == ({"ate": 0.5}, True)
    assert not folder_cached and (folder / "f.png").read_bytes() == b"png" and root not in folder.parents
    assert messages == [f"the cache at {root} {FULL}"]
    assert cache.stats()["entries"] == 1 and not leftovers(root)


class Failing(FakeSlam):
    """Tracks nothing and fails as ``how`` says (or raises MemoryError)."""

    def __init__(self, how: dict[str, Any] | None, **options: Any):
        super().__init__(**options)
        self.how = how

    def run(self, sequence: Sequence, workdir: Path, timeout: float | None = None) -> RunResult:
        result = super().run(sequence, workdir, timeout)
        if self.how is None:
            raise MemoryError
        data = result.to_dict()
        data.update(states=["lost"] * len(result.states), trajectory=None, **self.how)
        return RunResult.from_dict(data)


TIMEOUT = "timed out after 60 s and was killed"
BUSY = {"loadavg": [7.9, 6.0, 4.0], "cpus": 2, "usable_cpus": 2}
FAILURES: dict[str, tuple[dict[str, Any] | None, dict[str, Any], str | None]] = {
    "timeout, starved": (
        {"failure": TIMEOUT, "exit_status": -9, "fell_behind": True},
        QUIET,
        "timed out while starved: it fell behind the sensor clock",
    ),
    "timeout, busy machine": (
        {"failure": TIMEOUT, "exit_status": -9},
        BUSY,
        "timed out on a busy machine: load average 7.9 on 2 cores when it started",
    ),
    "timeout, quiet machine": ({"failure": TIMEOUT, "exit_status": -9}, QUIET, None),
    "SIGKILL, no timeout": (
        {"failure": "killed by SIGKILL (killed)", "exit_status": -signal.SIGKILL},
        QUIET,
        "killed by SIGKILL without a timeout",
    ),
    "MemoryError in the child": (
        {"failure": "exit status 1", "exit_status": 1, "log_tail": "  ...\nMemoryError"},
        QUIET,
        "ran out of memory",
    ),
    "MemoryError in process": (None, QUIET, "ran out of memory"),
    "segfault": ({"failure": "killed by SIGSEGV (segmentation fault)", "exit_status": -signal.SIGSEGV}, QUIET, None),
}


@pytest.mark.parametrize("case", list(FAILURES))
def test_a_failure_the_machine_decided_is_not_cached(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, case: str) -> None:
    how, load, reason = FAILURES[case]
    monkeypatch.setattr("pytest_sal.engine.execution.run_job.machine_load", lambda: load)
    log = tmp_path / "calls.jsonl"
    first = runner(tmp_path, Failing(how, calls_file=str(log)))
    trial = first.run_trial(40.0)
    assert not trial.passed and trial.metrics["tracking_rate"] == 0.0  # this session's verdict stands
    if reason is None:
        assert "not_cached" not in trial.runs[0]
    else:
        assert trial.runs[0]["not_cached"].startswith(reason)
    assert first.cache.path(first.key(40.0, 0)).exists() == (reason is None)
    again = runner(tmp_path, Failing(how, calls_file=str(log))).run_trial(40.0)
    assert calls(log) == (2 if reason else 1) and again.cached == (reason is None)  # the next session runs it again
