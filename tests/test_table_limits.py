"""Trajectory and time files are read line by line within stated limits (issue 23, item 9): a file
past a limit is refused with one error naming it, the limit and its unit, before its memory is
spent. Memory is measured with tracemalloc (peak Python and numpy allocation), never a clock."""

from __future__ import annotations

import tracemalloc
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from sal_adapters import DatasetError, Trajectory
from sal_adapters.common import textfiles
from sal_adapters.trajectory import read_times
from sal_wrappers.command.output import read_output
from sal_wrappers.orbslam3.states import read_final_trajectory

#: Every reader of a trajectory or time file: datasets' ground truth, ``sal evaluate``, the
#: ``command`` system's output formats and ORB-SLAM3's saved trajectory.
READERS: dict[str, Callable[[Path], object]] = {
    "tum": Trajectory.read_tum,
    "kitti": Trajectory.read_kitti,
    "euroc": Trajectory.read_euroc,
    "times": read_times,
    "orbslam3-final": lambda path: read_final_trajectory(path, np.zeros(0)),
    "command-tum": lambda path: read_output(path, "tum", "s", np.zeros(0), None),
    "command-kitti": lambda path: read_output(path, "kitti", "s", np.zeros(1), None),
    "command-euroc": lambda path: read_output(path, "euroc", "s", np.zeros(0), None),
    "command-json": lambda path: read_output(path, "json", "s", np.zeros(0), None),
}
#: A valid row of each reader's format.
ROWS = {
    "tum": "0 1 2 3 0 0 0 1",
    "kitti": "1 0 0 0 0 1 0 0 0 0 1 0",
    "euroc": "1,0,0,0,1,0,0,0",
    "times": "0.1",
    "orbslam3-final": "0 1 2 3 0 0 0 1",
    "command-tum": "0 1 2 3 0 0 0 1",
    "command-kitti": "1 0 0 0 0 1 0 0 0 0 1 0",
    "command-euroc": "1,0,0,0,1,0,0,0",
}
#: Peak allocation (bytes) a refused file may cost: far below the files refused here.
SMALL = 1 << 20


def refused(read: Callable[[Path], object], path: Path) -> tuple[DatasetError, int]:
    """The error ``read(path)`` raises and the peak allocation (bytes) while it ran."""
    tracemalloc.start()
    try:
        with pytest.raises(DatasetError) as info:
            read(path)
        return info.value, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("reader", list(READERS))
def test_a_file_over_the_byte_limit_is_refused_before_it_is_read(tmp_path: Path, reader: str) -> None:
    path = tmp_path / "huge.txt"
    limit = getattr(textfiles, "MAX_TABLE_BYTES", 256 << 20)
    with open(path, "wb") as handle:  # sparse: no disk spent
        handle.write(b"0 0 0 0 0 0 0 1\n")
        handle.truncate(limit + 1)
    error, peak = refused(READERS[reader], path)
    assert str(error) == f"{path}: {limit + 1} bytes, over the limit of {limit} bytes (256 MiB) for a table file: not read"
    assert peak < SMALL


@pytest.mark.parametrize("reader", list(ROWS))
def test_a_file_past_the_row_limit_is_refused_at_that_row(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, reader: str) -> None:
    """The JSON output format is read whole, within the byte limit alone."""
    monkeypatch.setattr(textfiles, "MAX_TABLE_ROWS", 1000, raising=False)
    path = tmp_path / "long.txt"
    path.write_text("# a header line\n" + f"{ROWS[reader]}\n" * 200_000)  # 200 times the limit: MBs
    error, peak = refused(READERS[reader], path)
    assert str(error) == f"{path}:1002: more than the limit of 1000 rows (poses, frames or times) for a table: not read further"
    assert peak < SMALL


@pytest.mark.parametrize("reader", ["tum", "euroc", "command-kitti"])
def test_a_line_over_the_line_limit_is_refused(tmp_path: Path, reader: str) -> None:
    path = tmp_path / "one_line.txt"
    path.write_bytes(b"# fine\n" + b"1" * (4 << 20))  # 4 MiB without a line break
    error, peak = refused(READERS[reader], path)
    assert str(error) == f"{path}:2: line longer than the limit of 65536 bytes for a table: not read"
    assert peak < SMALL


def test_line_numbers_count_every_kind_of_line_break(tmp_path: Path) -> None:
    """Streamed, lines are numbered as ``str.splitlines`` numbers them in the whole text."""
    path = tmp_path / "breaks.txt"
    path.write_bytes(b"# header\r\n\n0 0 0 0 0 0 0 1\r1 0 0 0 0 0 0 1\r\n2 0 0 x 0 0 0 1\n")
    assert [number for number, _ in textfiles.read_rows(path)][:2] == [3, 4]
    with pytest.raises(DatasetError, match=r"breaks\.txt:5: expected numbers, got 'x'$"):
        Trajectory.read_tum(path)
