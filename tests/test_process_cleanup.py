"""A SLAM run and everything it starts die with the session (issue 12, point 4): a pytest
session killed by SIGTERM or SIGKILL while a ``command`` system's program runs, a parent of
``run_child`` killed by SIGKILL, and a passing run whose program double-forks a ``setsid()``
daemon leave no process behind.

Every program here carries a unique marker in its command line and its environment; a test
passes when, a few seconds after the attack, no process carries it, and it kills whatever
does in any case (a failing test leaves nothing behind either).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from sal_adapters import open_dataset
from sal_wrappers import create
from sal_wrappers.process_group import run_process_group

pytestmark = pytest.mark.skipif(not Path("/proc/self/environ").is_file(), reason="finding the processes a run leaves needs Linux's /proc")

#: ``program.py READY MARKER``: double-forks a ``setsid()`` daemon (``--daemon``), writes READY,
#: then sleeps (``--sleep``) or writes the staged sequence's ground truth as its trajectory.
PROGRAM = textwrap.dedent(
    """\
    import os, sys, time
    from pathlib import Path

    ready, marker, what = sys.argv[1], sys.argv[2], sys.argv[3:]
    if "--daemon" in what and os.fork() == 0:
        os.setsid()
        if os.fork() == 0:
            os.execv(sys.executable, [sys.executable, "-c", "import time; time.sleep(300)", marker])
        os._exit(0)
    if "--trajectory" in what:
        sequence, out = Path(what[-2]), Path(what[-1])
        rows = [r for r in (sequence / "groundtruth.txt").read_text().splitlines() if r.strip() and not r.startswith("#")]
        out.write_text("\\n".join(rows) + "\\n")
    Path(ready).write_text("running")
    if "--sleep" in what:
        time.sleep(300)
    """
)

#: The inner session's conftest: a ``command`` system running PROGRAM, a 4-frame world.
INNER_CONFTEST = textwrap.dedent(
    """\
    import sys
    from pathlib import Path

    import pytest
    from sal_wrappers import create

    HERE = Path(__file__).parent


    @pytest.fixture(scope="session")
    def sal_dataset():
        from sal_adapters import open_dataset

        return open_dataset("synthetic", scene="indoor", frames=4, sensor="rgbd")


    @pytest.fixture
    def sal_system():
        argv = [sys.executable, str(HERE / "program.py"), str(HERE / "ready"), {marker!r}, *{what!r}]
        return create("command", argv=argv, env={{"LEAK_MARKER": {marker!r}}}, layout="tum", deterministic=True)
    """
)

INNER_TEST = textwrap.dedent(
    """\
    import pytest_sal as sal
    from pytest_sal import ate_rmse
    from sal_modules import fog


    @sal.sweep(fog.visibility_m, A=30)
    @sal.require(ate_rmse < 1.0)
    def test_slam(sal_trial):
        pass
    """
)

#: ``parent.py MARKER WORKDIR READY``: ``run_child`` of ``leaky_entry:main``, which writes READY
#: and sleeps, or (``--exit``) double-forks a daemon, writes READY, writes a result and returns.
RUN_CHILD_PARENT = textwrap.dedent(
    """\
    import os, sys
    from pathlib import Path
    from sal_wrappers.child_process import run_child

    os.environ["LEAK_MARKER"] = sys.argv[1]
    outcome = run_child("leaky_entry:main", {"ready": sys.argv[3], "exit": "--exit" in sys.argv}, iter([1, 2]), Path(sys.argv[2]), timeout=60)
    print("outcome", outcome.exit_status, outcome.failure, outcome.result, flush=True)
    """
)

LEAKY_ENTRY = textwrap.dedent(
    """\
    import os, sys, time
    from pathlib import Path
    from sal_wrappers.child_process import write_result


    def main(header, frames, result_path):
        list(frames)
        if os.fork() == 0:
            os.setsid()
            if os.fork() == 0:
                os.execv(sys.executable, [sys.executable, "-c", "import time; time.sleep(300)", os.environ["LEAK_MARKER"]])
            os._exit(0)
        Path(header["ready"]).write_text("running")
        if header["exit"]:
            write_result(result_path, {"frames": 2})
            return
        time.sleep(300)
    """
)


# -- helpers ---------------------------------------------------------------------------------------
def marked(marker: str) -> list[int]:
    """Live processes whose command line or environment holds ``marker`` (zombies have neither)."""
    needle = marker.encode()
    found = []
    for name in os.listdir("/proc"):
        if not name.isdigit() or int(name) == os.getpid():
            continue
        try:
            text = Path(f"/proc/{name}/cmdline").read_bytes() + Path(f"/proc/{name}/environ").read_bytes()
        except OSError:
            continue
        if needle in text:
            found.append(int(name))
    return found


def wait_for(check, seconds: float, what: str) -> None:
    deadline = time.monotonic() + seconds
    while not check():
        if time.monotonic() > deadline:
            raise AssertionError(f"{what} within {seconds:g} s")
        time.sleep(0.05)


def running(marker: str, count: int, session: subprocess.Popen[bytes]) -> None:
    """Until ``count`` processes carry ``marker``: READY is written before a double-forked
    daemon has started, which on a loaded machine takes a while (no clock: the daemon starts,
    or ``session`` ends and the test fails)."""
    while len(marked(marker)) < count:
        assert session.poll() is None, f"the session ended with {len(marked(marker))} of {count} processes started"
        time.sleep(0.05)


def assert_none_left(marker: str, seconds: float = 5.0) -> None:
    deadline = time.monotonic() + seconds
    while (left := marked(marker)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not left, f"processes left behind: {[Path(f'/proc/{p}/cmdline').read_bytes() for p in left if Path(f'/proc/{p}').exists()]}"


@pytest.fixture
def marker() -> Iterator[str]:
    """A unique marker; whatever still carries it at the end is killed."""
    text = f"sal-leak-test-{uuid.uuid4().hex}"
    yield text
    for pid in marked(text):
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass


def start(argv: list[str], cwd: Path, log: Path) -> subprocess.Popen[bytes]:
    """``argv`` in a session of its own (so that the test can kill all of it at the end)."""
    with open(log, "wb") as out:
        return subprocess.Popen(argv, cwd=cwd, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)


def stop(process: subprocess.Popen[bytes]) -> None:
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except OSError:
        pass
    process.wait()


# -- the attacks -----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("workers", "what"),
    [([], ["--sleep"]), ([], ["--daemon", "--sleep"]), (["-n", "2"], ["--daemon", "--sleep"])],
    ids=["sleeps", "double-forks", "xdist-double-forks"],
)
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"])
def test_a_killed_pytest_session_leaves_no_slam_process(
    tmp_path: Path, marker: str, sig: signal.Signals, workers: list[str], what: list[str]
) -> None:
    """Also under ``-n 2``: the controller killed, its workers die within a poll and each run's
    watchdog kills what the run started (issue 23, item 15: they ran on for about 15 s)."""
    (tmp_path / "pytest.ini").write_text("[pytest]\nsal_timeout = 120\n")
    (tmp_path / "program.py").write_text(PROGRAM)
    (tmp_path / "conftest.py").write_text(INNER_CONFTEST.format(marker=marker, what=what))
    (tmp_path / "test_inner.py").write_text(INNER_TEST)
    argv = [
        sys.executable,
        "-m",
        "pytest",
        "-q",
        "-p",
        "no:cacheprovider",
        "-p",
        "no:hypothesispytest",
        f"--sal-cache-dir={tmp_path / 'cache'}",
        f"--sal-history-dir={tmp_path / 'history'}",
        *workers,
    ]
    session = start(argv, tmp_path, tmp_path / "pytest.log")
    try:
        wait_for(lambda: (tmp_path / "ready").exists() or session.poll() is not None, 60, "the SLAM program did not start")
        assert session.poll() is None, (tmp_path / "pytest.log").read_text()
        running(marker, len(what), session)  # the program (and its daemon) run
        os.kill(session.pid, sig)
        assert session.wait() == -sig
        assert_none_left(marker)
    finally:
        stop(session)


@pytest.mark.parametrize("outcome", ["exits", "parent-killed"])
def test_run_child_leaves_nothing(tmp_path: Path, marker: str, outcome: str) -> None:
    (tmp_path / "parent.py").write_text(RUN_CHILD_PARENT)
    (tmp_path / "leaky_entry.py").write_text(LEAKY_ENTRY)
    ready = tmp_path / "ready"
    exits = outcome == "exits"
    parent = start(
        [sys.executable, "parent.py", marker, str(tmp_path / "w"), str(ready), *(["--exit"] if exits else [])],
        tmp_path,
        tmp_path / "parent.log",
    )
    try:
        wait_for(lambda: ready.exists() or parent.poll() is not None, 30, "the child did not start")
        if exits:
            assert parent.wait(timeout=10) == 0
            assert "outcome 0 None {'frames': 2}" in (tmp_path / "parent.log").read_text()
            assert_none_left(marker, seconds=0.5)  # killed before run_child returned
        else:
            running(marker, 4, parent)  # the parent, its watchdog (the parent set the marker before it started), the child, its daemon
            os.kill(parent.pid, signal.SIGKILL)
            parent.wait(timeout=10)
            assert_none_left(marker)
    finally:
        stop(parent)


def test_a_passing_run_leaves_no_double_forked_daemon(tmp_path: Path, marker: str) -> None:
    (tmp_path / "program.py").write_text(PROGRAM)
    sequence = open_dataset("synthetic", scene="indoor", frames=4, sensor="rgbd")
    argv = [
        sys.executable,
        str(tmp_path / "program.py"),
        str(tmp_path / "ready"),
        marker,
        "--daemon",
        "--trajectory",
        "{sequence}",
        "{output}",
    ]
    result = create("command", argv=argv, layout="tum").run(sequence, tmp_path / "w", timeout=60)
    assert result.ok and result.tracked == 4, result.summary()
    assert_none_left(marker, seconds=0.5)


def test_run_process_group_kills_a_daemon_that_left_the_group(tmp_path: Path, marker: str) -> None:
    (tmp_path / "program.py").write_text(PROGRAM)
    argv = [sys.executable, str(tmp_path / "program.py"), str(tmp_path / "ready"), marker, "--daemon"]
    status, timed_out, _, error, _ = run_process_group(argv, tmp_path, dict(os.environ), tmp_path / "run.log", timeout=30)
    assert (status, timed_out, error) == (0, False, None)
    assert (tmp_path / "ready").exists()
    assert_none_left(marker, seconds=0.5)


def test_the_watchdog_goes_with_the_run(tmp_path: Path) -> None:
    """The watchdog is this process's child while the run lasts, and gone when it returns."""
    from sal_wrappers import watchdog

    def watchdogs() -> list[str]:
        found = []
        for name in os.listdir("/proc"):
            try:
                stat = Path(f"/proc/{name}/stat").read_text()
                cmdline = Path(f"/proc/{name}/cmdline").read_bytes()
            except OSError:
                continue
            if stat.rsplit(")", 1)[1].split()[1] == str(os.getpid()) and watchdog.__file__.encode() in cmdline:
                found.append(name)
        return found

    argv = [sys.executable, "-c", "import time; time.sleep(0.5)"]
    status, *_ = run_process_group(argv, tmp_path, dict(os.environ), tmp_path / "run.log", timeout=30)
    assert status == 0 and not watchdogs()
