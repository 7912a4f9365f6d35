"""A program's log keeps its beginning and its end, 4 MiB in all, however much it prints
(issue 23, item 9): the ``command`` system's ``run.log`` and the ORB-SLAM3 child's log."""

from __future__ import annotations

import os
import re
import sys
import textwrap
from pathlib import Path

import pytest

from sal_wrappers import create
from sal_wrappers.child_process import run_child

#: the shared fixtures (tiny)
pytest_plugins = ["command_programs"]

#: The most a log keeps of a program's output (bytes), as the README states.
LOG_LIMIT = 4 * 1024 * 1024
#: What the programs below print between their first and last lines: 50 MiB, in 1 MiB writes.
BULK_MIB = 50

#: Prints a first line, BULK_MIB MiB and a last line (on stderr); ``print_much`` does it too.
PRINT_MUCH = textwrap.dedent(
    f"""\
    import sys


    def print_much():
        out = sys.stdout.buffer
        out.write(b"FIRST LINE\\n")
        chunk = (b"x" * 1023 + b"\\n") * 1024
        for _ in range({BULK_MIB}):
            out.write(chunk)
        out.flush()
        sys.stderr.write("LAST LINE\\n")
        sys.stderr.flush()


    def main(header, frames, result_path):
        list(frames)
        print_much()


    if __name__ == "__main__":
        print_much()
    """
)
#: Bytes the program prints.
PRINTED = len("FIRST LINE\n") + BULK_MIB * 1024 * 1024 + len("LAST LINE\n")


def assert_capped(log: Path, before: int, tail: str) -> None:
    """``log`` holds the first half of the limit, one cut marker naming the bytes left out of
    the ``before`` bytes written ahead of the program's and of its ``PRINTED``, and the end."""
    data = log.read_bytes()
    marker = re.search(rb"\n\[\.\.\. (\d+) bytes cut \.\.\.\]\n", data)
    assert marker is not None and len(re.findall(rb"bytes cut", data)) == 1
    assert len(data) - len(marker.group(0)) == LOG_LIMIT
    assert int(marker.group(1)) == before + PRINTED - LOG_LIMIT
    assert data.index(b"FIRST LINE\n") == before and data.endswith(b"x\nLAST LINE\n")
    assert tail.endswith("LAST LINE")


def test_a_command_program_printing_50_mib_leaves_a_4_mib_run_log(tiny, tmp_path: Path) -> None:
    (tmp_path / "print_much.py").write_text(PRINT_MUCH)
    system = create("command", argv=[sys.executable, str(tmp_path / "print_much.py")], sensor="mono", layout="folder")
    result = system.run(tiny, tmp_path / "w", timeout=None)
    assert result.exit_status == 0 and result.failure.startswith("no trajectory written")
    assert result.log_path is not None
    command_line = result.log_path.read_bytes().split(b"\n", 1)[0] + b"\n"
    assert command_line.startswith(b"$ ") and b"print_much.py" in command_line
    assert_capped(result.log_path, len(command_line), result.log_tail)


def test_the_child_log_of_a_run_child_printing_50_mib_is_4_mib(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "print_much.py").write_text(PRINT_MUCH)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(tmp_path), *filter(None, [os.environ.get("PYTHONPATH")])]))
    outcome = run_child("print_much:main", {}, iter([1, 2]), tmp_path / "w")
    assert outcome.exit_status == 0 and outcome.failure == "the child exited without writing a result"
    assert_capped(outcome.log_path, 0, outcome.log_tail)
