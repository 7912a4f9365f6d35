"""Where a run was made: the machine (``machine_info``, in words ``machine_text``) and the git
commit of the work tree (``commit_info``), recorded with every run of the history."""

from __future__ import annotations

import os
import platform
import subprocess
from pathlib import Path
from typing import Any

__all__ = ["commit_info", "cpu_model", "machine_info", "machine_text"]


def machine_info() -> dict[str, Any]:
    """``hostname``, ``platform``, ``machine`` (CPU architecture), ``cpu_model``, ``cpu_count``,
    ``usable_cpus`` (this process's CPU affinity), ``load_avg`` (1, 5, 15 min run-queue
    averages now), ``python``."""
    return {
        "hostname": platform.node(),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "cpu_model": cpu_model(),
        "cpu_count": os.cpu_count(),
        "usable_cpus": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
        "load_avg": [round(x, 2) for x in os.getloadavg()] if hasattr(os, "getloadavg") else None,
        "python": f"{platform.python_implementation()} {platform.python_version()}",
    }


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``'s first ``model name``; ``platform.processor()``
    elsewhere), or ``""``."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as info:
            for line in info:
                key, _, value = line.partition(":")
                if key.strip() in ("model name", "Model", "cpu model"):
                    return " ".join(value.split())
    except OSError:
        pass
    return platform.processor() or ""


def machine_text(info: dict[str, Any]) -> str:
    """The machine as results depend on it: ``Intel Xeon Gold 6230 (2 cores)``."""
    cores = info.get("usable_cpus") or info.get("cpu_count")
    model = info.get("cpu_model") or info.get("machine") or "unknown CPU"
    return f"{model} ({cores} cores)" if cores else str(model)


def commit_info(cwd: str | Path | None = None) -> tuple[str, bool]:
    """``(short commit, dirty)`` of the git work tree at ``cwd`` (default: the working directory).

    ``dirty``: tracked files differ from the commit (``git status --porcelain
    --untracked-files=no``; untracked files, the history itself among them, do not count).
    Without git, outside a repository, or before the first commit: ``("", False)``, no error.
    """

    def git(*args: str) -> str | None:
        try:
            done = subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, timeout=20, check=False)
        except (OSError, subprocess.SubprocessError):
            return None
        return done.stdout if done.returncode == 0 else None

    commit = git("rev-parse", "--short", "HEAD")
    if not commit or not commit.strip():
        return "", False
    status = git("status", "--porcelain", "--untracked-files=no")
    return commit.strip(), bool(status and status.strip())
