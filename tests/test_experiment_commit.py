"""The outputs of ``sal perturb`` switch as one generation (issue 23, item 13): a rerun killed
before any file system step of its write (fault injection: SIGKILL in a forked child just
before its Nth mkdir, link, rename, unlink, ... or folder exchange, for every N until the
rerun completes) leaves the previous output or the new one, never ``images/fog`` new beside
``images/drop`` old, and the next run cleans up what it left."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
from pathlib import Path
from typing import Any

import pytest
import yaml
from output_leftovers import LEFTOVER, leftovers

from pytest_sal.experiment.config import load_config
from pytest_sal.experiment.perturb import PIPELINE_RESULTS, PerturbPlan, plan_perturbations, write_perturbations
from sal_adapters.common import atomic

#: the os functions a kill is injected before (every step that changes a folder's entries)
STEPS = ("mkdir", "rename", "replace", "link", "symlink", "unlink", "rmdir")


def _config(tmp_path: Path, seed: int) -> Path:
    config = {
        "experiment": {"name": "exp", "seed": seed},
        "dataset": {"type": "synthetic", "options": {"scene": "urban", "frames": 3, "sensor": "mono"}},
        "perturbations": [
            {"name": "fog", "type": "fog", "parameters": {"visibility_m": 40}},
            {"name": "drop", "type": "frame_drop", "parameters": {"drop_rate": 0.4}},
            {"name": "rain", "type": "rain", "parameters": {"intensity_mm_h": 30}},
        ],
        "output": {"base_dir": str(tmp_path / "results")},
    }
    path = tmp_path / f"seed{seed}.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


def _content(path: Path) -> bytes:
    """What identifies a generation's file: its bytes (``pipeline_results.json``: less each
    perturbation's ``seconds`` and ``cached``, which differ between two writes of one plan)."""
    if path.name != PIPELINE_RESULTS:
        return path.read_bytes()
    results = json.loads(path.read_text())
    for entry in results["perturbations"].values():
        del entry["seconds"], entry["cached"]
    return json.dumps(results, sort_keys=True).encode()


def snapshot(root: Path) -> dict[str, str]:
    """Every visible file and folder under ``root``: relative path -> SHA-256 (``dir``);
    staging and old copies a killed run left are not part of the output."""
    return {
        p.relative_to(root).as_posix(): "dir" if p.is_dir() else hashlib.sha256(_content(p)).hexdigest()
        for p in sorted(root.rglob("*"))
        if not any(mark in p.relative_to(root).as_posix() for mark in LEFTOVER)
    }


def _killed_at(step: int, plan: PerturbPlan, cache: Path) -> bool:
    """Write ``plan`` in a forked child that SIGKILLs itself just before its ``step``-th file
    system step; whether it was killed (False: it completed first)."""
    pid = os.fork()
    if pid == 0:  # the child: never returns into pytest
        count = [0]

        def counted(real: Any) -> Any:
            def step_then(*args: Any, **kwargs: Any) -> Any:
                count[0] += 1
                if count[0] == step:
                    os.kill(os.getpid(), signal.SIGKILL)
                return real(*args, **kwargs)

            return step_then

        for name in STEPS:
            setattr(os, name, counted(getattr(os, name)))
        atomic._exchange = counted(atomic._exchange)  # type: ignore[attr-defined]
        try:
            write_perturbations(plan, cache_dir=cache, progress=False)
        finally:
            os._exit(0)
    _, status = os.waitpid(pid, 0)
    return os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL


@pytest.mark.parametrize("exchange", [True, False], ids=["renameat2", "two-renames"])
def test_a_kill_at_any_step_leaves_the_old_or_the_new_generation(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, exchange: bool) -> None:
    if not exchange:
        monkeypatch.setattr(atomic, "_exchange", lambda a, b: False)
    cache = tmp_path / "cache"
    old_plan, new_plan = (plan_perturbations(load_config(_config(tmp_path, seed))) for seed in (1, 2))
    root = old_plan.root
    (root / "slam_results").mkdir(parents=True)
    (root / "slam_results" / "kept.txt").write_text("another command's output")
    write_perturbations(old_plan, cache_dir=cache, progress=False)
    old = snapshot(root)
    kept = shutil.copytree(root, tmp_path / "kept", symlinks=True)
    write_perturbations(new_plan, cache_dir=cache, progress=False)  # its frames cached
    new = snapshot(root)
    assert {"images/fog", "images/drop", "images/rain", "config.yaml", "pipeline_results.json", "slam_results/kept.txt"} <= set(old)
    changed = {k.split("/")[1] for k in old if k.startswith("images/") and old[k] != new.get(k)}
    assert changed == {"fog", "drop", "rain"} and old["config.yaml"] != new["config.yaml"]  # any mix is visible
    shutil.rmtree(root)
    shutil.copytree(kept, root, symlinks=True)

    step = 0
    while True:
        step += 1
        assert step < 10_000, "the rerun never completed"
        if not _killed_at(step, new_plan, cache):
            break
        seen = snapshot(root) if root.exists() else None
        assert seen in (old, new) or (seen is None and not exchange), f"a kill before step {step} left a mix: {seen}"
        for folder in [root.parent, root, *(p for p in root.rglob("*") if p.is_dir())]:
            atomic.recover(folder)  # what the next run does first in each folder it writes to
        after = snapshot(root)
        assert after in (old, new), f"after a kill before step {step}, recovery left a mix"
        assert leftovers(tmp_path / "results") == [], f"step {step}"
        shutil.rmtree(root)
        shutil.copytree(kept, root, symlinks=True)

    assert step > 10  # every step of the write was tried
    assert snapshot(root) == new and leftovers(tmp_path / "results") == []
