"""Run a SLAM entry point in a child process that may crash, exit or hang.

The parent starts ``python -m sal_wrappers.child_process ENTRY RESULT`` with the child's stdout and
stderr going to a log file, and streams pickled messages into its stdin: first a header
(a dict of settings), then one frame at a time, then ``None``. The child imports ``ENTRY``
(``package.module:function``), calls ``function(header, frames, result_path)`` with an iterator
over the frames, and the function writes its result (JSON) to ``result_path`` atomically.

Whatever the child does - segfault, ``exit(-1)``, an exception, a hang past the deadline - the
parent returns a ``ChildOutcome`` with the exit status, a reason in words and the tail of the
log, and nothing raises. The parent produces the next frame (decoding, perturbing) while the
child tracks the previous one.
"""

from __future__ import annotations

import importlib
import json
import os
import pickle
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sal_wrappers.capped_log import CappedLog
from sal_wrappers.process_group import RunGuard, wait_unreaped

__all__ = ["ChildOutcome", "describe_exit", "log_tail", "run_child", "write_result"]

#: Exit statuses with a known meaning, for messages.
KNOWN_EXITS = {255: "exit(-1): ORB-SLAM3 does this on a bad settings file or vocabulary"}


@dataclass(frozen=True)
class ChildOutcome:
    """What became of a child run.

    Attributes:
        result: the JSON the entry point wrote, or ``None`` when it wrote none.
        exit_status: the child's exit status (negative: killed by that signal).
        failure: the reason in words when the child did not finish cleanly, else ``None``.
        wall_time_s: from start to exit (s).
        log_path: the child's stdout and stderr.
        log_tail: the last lines of that log.
        timed_out: the child was killed at the deadline.
        cpu_at_timeout_s: CPU time (s) the run's processes had had when the deadline killed
            them (``RunGuard.cpu_seconds``), else ``None``.
    """

    result: dict[str, Any] | None
    exit_status: int | None
    failure: str | None
    wall_time_s: float
    log_path: Path
    log_tail: str
    timed_out: bool = False
    cpu_at_timeout_s: float | None = None


def describe_exit(status: int) -> str:
    """Words for an exit status: ``killed by SIGSEGV (segmentation fault)``, ``exit status 255 ...``."""
    if status < 0:
        try:
            sig = signal.Signals(-status)
        except ValueError:
            return f"killed by signal {-status}"
        words = {signal.SIGSEGV: "segmentation fault", signal.SIGABRT: "abort", signal.SIGKILL: "killed", signal.SIGBUS: "bus error"}
        return f"killed by {sig.name}" + (f" ({words[sig]})" if sig in words else "")
    return f"exit status {status}" + (f" ({KNOWN_EXITS[status]})" if status in KNOWN_EXITS else "")


def log_tail(path: Path, lines: int = 15) -> str:
    """The last ``lines`` lines of a log file ("" when it is missing)."""
    try:
        with open(path, "rb") as handle:
            handle.seek(0, os.SEEK_END)
            handle.seek(max(0, handle.tell() - 64 * 1024))
            text = handle.read().decode("utf-8", "replace")
    except OSError:
        return ""
    return "\n".join(text.splitlines()[-lines:])


def run_child(
    entry: str,
    header: dict[str, Any],
    frames: Iterable[Any],
    workdir: Path,
    timeout: float | None = None,
    log_name: str = "run.log",
) -> ChildOutcome:
    """Run ``entry`` in a child process fed ``header`` and ``frames`` (see the module text).

    ``timeout`` (s) covers the whole run; past it the child is killed. The log is
    ``workdir/log_name`` (at most ``sal_wrappers.capped_log.MAX_LOG_BYTES``: the beginning and
    the end); the result file ``workdir/<log stem>.result.json``. What the child
    leaves behind when it exits is killed, and all of it when the calling process dies first
    (``sal_wrappers.process_group.RunGuard``).
    """
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    log_path = workdir / log_name
    result_path = workdir / f"{Path(log_name).stem}.result.json"
    result_path.unlink(missing_ok=True)
    start = time.monotonic()
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    with CappedLog(log_path) as log, RunGuard() as guard:
        process = subprocess.Popen(
            [sys.executable, "-m", "sal_wrappers.child_process", entry, str(result_path)],
            stdin=subprocess.PIPE,
            stdout=log.fd,
            stderr=subprocess.STDOUT,
            env=guard.environ(env),
            start_new_session=True,
        )
        log.detach()
        guard.watch(process.pid)
        status, timed_out, feed_error, cpu = _feed(process, header, frames, timeout, guard.cpu_seconds)
    wall = time.monotonic() - start
    result = None
    if result_path.is_file():
        try:
            result = json.loads(result_path.read_text())
        except ValueError:
            result = None
    failure = None
    if feed_error is not None:
        raise feed_error
    if timed_out:
        failure = f"timed out after {timeout:g} s and was killed"
    elif status != 0:
        failure = describe_exit(status)
    elif result is None:
        failure = "the child exited without writing a result"
    return ChildOutcome(result, status, failure, wall, log_path, log_tail(log_path), timed_out, cpu)


def write_result(path: Path, data: dict[str, Any]) -> None:
    """Write the child's result JSON atomically (for entry points)."""
    from sal_adapters.common.textfiles import atomic_write_text

    atomic_write_text(Path(path), json.dumps(data))


def _feed(
    process: subprocess.Popen[bytes],
    header: dict[str, Any],
    frames: Iterable[Any],
    timeout: float | None,
    cpu_seconds: Callable[[], float | None],
) -> tuple[int, bool, BaseException | None, float | None]:
    """Stream the messages into the child and wait for it; ``(exit status, timed out, error
    producing a frame, cpu_seconds() at the deadline)``. The child's process group is killed
    when it timed out, when a frame could not be produced, and whatever is left of it when the
    child exits."""
    stdin = process.stdin
    assert stdin is not None  # started with stdin=PIPE
    timed_out = threading.Event()
    cpu_at_timeout: list[float | None] = [None]

    def kill() -> None:
        cpu_at_timeout[0] = cpu_seconds()
        timed_out.set()
        _kill(process)

    watchdog = threading.Timer(timeout, kill) if timeout else None
    if watchdog:
        watchdog.daemon = True
        watchdog.start()
    feed_error: BaseException | None = None
    try:
        try:
            for message in _messages(header, frames):
                pickle.dump(message, stdin, protocol=pickle.HIGHEST_PROTOCOL)
            stdin.close()
        except (BrokenPipeError, OSError):
            pass  # the child died or closed its input: its exit status says why
        except BaseException as exc:  # producing a frame failed (bad image): stop the child
            feed_error = exc
            _kill(process)
        wait_unreaped(process)
    finally:
        if watchdog:
            watchdog.cancel()
        try:
            stdin.close()  # also when the child died mid-stream (no leaked pipe)
        except OSError:
            pass
        _kill(process)  # before reaping: the group id stays reserved until then
        status = process.wait()
    return status, timed_out.is_set(), feed_error, cpu_at_timeout[0]


def _messages(header: dict[str, Any], frames: Iterable[Any]) -> Iterator[Any]:
    yield header
    yield from frames
    yield None


def _kill(process: subprocess.Popen) -> None:
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def _read_frames(stream: Any) -> Iterator[Any]:
    while True:
        try:
            message = pickle.load(stream)
        except EOFError:
            return
        if message is None:
            return
        yield message


def _child_main(argv: list[str]) -> int:
    entry, result_path = argv
    module_name, _, function_name = entry.partition(":")
    function = getattr(importlib.import_module(module_name), function_name)
    stream = sys.stdin.buffer
    header = pickle.load(stream)
    function(header, _read_frames(stream), Path(result_path))
    sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(_child_main(sys.argv[1:]))
