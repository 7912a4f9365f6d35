"""Frame times are checked when a dataset is opened (issue 12 point 6): a time that is not
finite, or not after the previous line's, is one ``DatasetError`` naming the file and line, for
every adapter that reads times from a file; ``sal`` and the plugin show it as one line. Each
layout is a small copy of a real excerpt (images symlinked from the shared data) with its times
file rewritten; the real excerpts still open."""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from pathlib import Path

import pytest

from pytest_sal.cli.main import main
from sal_adapters import DatasetError, open_dataset, write_sequence
from sal_adapters.common.textfiles import check_times
from sal_adapters.layout_io import read_list

#: EuRoC time of the first frame of the excerpt (ns); the cases' seconds are added to it
EUROC_T0_NS = 1403715273262142976

#: name -> (frame times (s) of 4 frames, 0-based position of the offending row)
CASES = {
    "nan": ([0.0, 0.1, math.nan, 0.3], 2),
    "inf": ([0.0, math.inf, 0.2, 0.3], 1),
    "all equal": ([0.5, 0.5, 0.5, 0.5], 1),
    "decreasing pair": ([0.0, 0.2, 0.1, 0.3], 2),
    "duplicate": ([0.0, 0.1, 0.1, 0.2], 2),
}


def link(source: Path, target: Path) -> None:
    """Symlink ``target`` -> ``source`` (parents created)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    os.symlink(source, target)


def seconds(t: float) -> str:
    """A time (s) as the KITTI, TUM and folder files write it."""
    return repr(t)


class Layout:
    """A small dataset copy: ``build(root, times)`` writes it with those times (s) and returns
    ``(path to open, times file)``; ``header`` comment lines precede the rows; ``shown(t)`` is
    a time as written (and quoted in messages) in ``unit``."""

    def __init__(
        self,
        kind: str,
        build: Callable[[Path, list[float]], tuple[Path, Path]],
        header: int = 0,
        unit: str = "s",
        shown: Callable[[float], str] = seconds,
        **options: object,
    ):
        self.kind, self.build, self.header, self.unit, self.shown, self.options = kind, build, header, unit, shown, options


def kitti(shared: Path) -> Callable[[Path, list[float]], tuple[Path, Path]]:
    def build(root: Path, times: list[float]) -> tuple[Path, Path]:
        source = shared / "kitti" / "sequences" / "07"
        for i in range(len(times)):
            link(source / "image_0" / f"{i:06d}.png", root / "image_0" / f"{i:06d}.png")
        link(source / "calib.txt", root / "calib.txt")
        (root / "times.txt").write_text("".join(seconds(t) + "\n" for t in times))
        return root, root / "times.txt"

    return build


def euroc_ns(t: float) -> str:
    return f"{EUROC_T0_NS + round(t * 1e9)}" if math.isfinite(t) else repr(t)


def euroc(shared: Path) -> Callable[[Path, list[float]], tuple[Path, Path]]:
    def build(root: Path, times: list[float]) -> tuple[Path, Path]:
        cam0 = shared / "euroc" / "V1_01_easy_micro" / "mav0" / "cam0"
        names = sorted(p.name for p in (cam0 / "data").iterdir())[: len(times)]
        for name in names:
            link(cam0 / "data" / name, root / "mav0" / "cam0" / "data" / name)
        link(cam0 / "sensor.yaml", root / "mav0" / "cam0" / "sensor.yaml")
        rows = "".join(f"{euroc_ns(t)},{name}\n" for t, name in zip(times, names))
        (root / "mav0" / "cam0" / "data.csv").write_text("#timestamp [ns],filename\n" + rows)
        return root, root / "mav0" / "cam0" / "data.csv"

    return build


def fr3_images(shared: Path) -> list[Path]:
    """The 4 colour frames of fr3_long_office_household (named by their time, s)."""
    return sorted((shared / "tum_rgbd_samples" / "fr3_long_office_household_4frames_pyslam").glob("*.png"))


def tum(shared: Path) -> Callable[[Path, list[float]], tuple[Path, Path]]:
    def build(root: Path, times: list[float]) -> tuple[Path, Path]:
        folder = root / "rgbd_dataset_freiburg3_long_office_household"
        images = fr3_images(shared)
        for image in images:
            link(image, folder / "rgb" / image.name)
        rows = "".join(f"{seconds(t)} rgb/{image.name}\n" for t, image in zip(times, images))
        (folder / "rgb.txt").write_text("# color images\n# file: 'fr3_long_office_household'\n# timestamp filename\n" + rows)
        return folder, folder / "rgb.txt"

    return build


def folder_times(shared: Path, listed: bool) -> Callable[[Path, list[float]], tuple[Path, Path]]:
    """A folder of images with ``times.txt`` (one time per line) or ``timestamps.txt``
    (``# timestamp filename`` header, then ``time name`` per line)."""

    def build(root: Path, times: list[float]) -> tuple[Path, Path]:
        names = [f"frame{i}.png" for i in range(len(times))]
        for i, name in enumerate(names):
            link(shared / "kitti" / "sequences" / "07" / "image_0" / f"{i:06d}.png", root / name)
        if listed:
            text = "# timestamp filename\n" + "".join(f"{seconds(t)} {name}\n" for t, name in zip(times, names))
            path = root / "timestamps.txt"
        else:
            text = "".join(seconds(t) + "\n" for t in times)
            path = root / "times.txt"
        path.write_text(text)
        return root, path

    return build


def synthetic_layout(shared: Path) -> Callable[[Path, list[float]], tuple[Path, Path]]:
    """A KITTI copy written in the synthetic layout, its ``times.txt`` then rewritten."""

    def build(root: Path, times: list[float]) -> tuple[Path, Path]:
        source, _ = kitti(shared)(root / "kitti", [0.1 * i for i in range(len(times))])
        out = write_sequence(open_dataset("kitti", source), root / "synthetic", layout="synthetic")
        rows = [line.split() for line in (out / "times.txt").read_text().splitlines()[1:]]
        text = "".join(f"{stem} {index} {seconds(t)}\n" for (stem, index, *_), t in zip(rows, times))
        (out / "times.txt").write_text("# stem index timestamp_s [timestamp_ns]\n" + text)
        return out, out / "times.txt"

    return build


@pytest.fixture(scope="module")
def layouts(shared_data: Path) -> dict[str, Layout]:
    return {
        "kitti": Layout("kitti", kitti(shared_data)),
        "euroc": Layout("euroc", euroc(shared_data), header=1, unit="ns", shown=euroc_ns),
        "tum": Layout("tum", tum(shared_data), header=3),
        "folder times.txt": Layout("folder", folder_times(shared_data, listed=False), intrinsics="700 700 613 185"),
        "folder timestamps.txt": Layout("folder", folder_times(shared_data, listed=True), header=1, intrinsics="700 700 613 185"),
        "synthetic layout": Layout("synthetic", synthetic_layout(shared_data), header=1),
    }


LAYOUTS = ["kitti", "euroc", "tum", "folder times.txt", "folder timestamps.txt", "synthetic layout"]


def expected_message(layout: Layout, times: list[float], bad: int) -> str:
    """What is wrong with row ``bad`` (0-based), as the adapters say it."""
    t = times[bad]
    if not math.isfinite(t):
        if layout.unit == "ns":  # EuRoC times are integers: 'nan' is not one
            return f"expected an integer timestamp in ns, got {repr(t)!r}"
        return f"time {layout.shown(t)} s is not a finite number"
    line = layout.header + bad
    return f"time {layout.shown(t)} {layout.unit} is not after line {line}'s {layout.shown(times[bad - 1])} {layout.unit} (frame times must increase)"


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("name", LAYOUTS)
def test_bad_frame_times_are_one_error_naming_file_and_line(
    layouts: dict[str, Layout], tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str, case: str
) -> None:
    layout = layouts[name]
    times, bad = CASES[case]
    path, times_file = layout.build(tmp_path / "data", times)
    expected = f"{times_file}:{layout.header + bad + 1}: {expected_message(layout, times, bad)}"
    with pytest.raises(DatasetError) as info:
        open_dataset(layout.kind, path, **layout.options)
    assert str(info.value) == expected
    options = [arg for key, value in layout.options.items() for arg in ("-o", f"{key}={value}")]
    assert main(["dataset", "info", layout.kind, str(path), *options]) == 2
    assert capsys.readouterr().err == f"sal: error: {expected}\n"


@pytest.mark.parametrize("name", LAYOUTS)
def test_increasing_times_open_with_their_rate(layouts: dict[str, Layout], tmp_path: Path, name: str) -> None:
    layout = layouts[name]
    path, _ = layout.build(tmp_path / "data", [0.0, 0.1, 0.2, 0.3])
    sequence = open_dataset(layout.kind, path, **layout.options)
    assert len(sequence) == 4
    if layout.kind != "euroc":  # EuRoC's rate is sensor.yaml's rate_hz
        assert sequence.fps == pytest.approx(10.0)


def test_a_step_too_large_for_a_period_is_refused(layouts: dict[str, Layout], tmp_path: Path) -> None:
    path, times_file = layouts["kitti"].build(tmp_path / "data", [-1e308, 1e308, 1.5e308, 1.6e308])
    with pytest.raises(DatasetError) as info:
        open_dataset("kitti", path)
    assert str(info.value) == f"{times_file}:2: time 1e+308 s is inf s after line 1's: no usable frame period"


def test_depth_times_must_be_finite_but_not_ordered(tmp_path: Path) -> None:
    depth = tmp_path / "depth.txt"
    depth.write_text("# depth maps\n0.2 depth/b.png\n0.1 depth/a.png\n")
    assert [row[0] for row in read_list(depth, "tf", "timestamp filename", increasing=False)] == [2, 3]
    depth.write_text("# depth maps\n0.2 depth/b.png\nnan depth/a.png\n")
    with pytest.raises(DatasetError, match=rf"^{depth}:3: time nan s is not a finite number$"):
        read_list(depth, "tf", "timestamp filename", increasing=False)


def test_ns_times_beyond_a_float_are_refused_briefly(tmp_path: Path) -> None:
    path = tmp_path / "data.csv"
    with pytest.raises(DatasetError) as info:
        check_times([(2, 1), (3, 10**400)], path, unit="ns")
    assert str(info.value) == f"{path}:3: time 10000000000000000000...(401 digits) ns is too large"


def test_real_excerpts_still_open(shared_data: Path) -> None:
    assert len(open_dataset("kitti", shared_data / "kitti" / "sequences" / "07")) == 140
    with pytest.warns(UserWarning, match="rows skipped"):  # cam1 lists 4 missing files
        assert len(open_dataset("euroc", shared_data / "euroc" / "V1_01_easy_micro", stereo=True)) == 95
    tum_txt = shared_data / "trajectories" / "tum_fr1_xyz_txt"
    for name in ("rgb.txt", "depth.txt"):
        assert len(read_list(tum_txt / name, "tf", "timestamp filename")) > 700
    folder = shared_data / "tum_rgbd_samples" / "fr3_long_office_household_4frames_pyslam"
    assert len(open_dataset("folder", folder, intrinsics="535.4 539.2 320.1 247.6")) == 4


def test_the_plugin_shows_a_bad_times_file_as_one_line(layouts: dict[str, Layout], tmp_path: Path, pytester: pytest.Pytester) -> None:
    path, times_file = layouts["kitti"].build(tmp_path / "data", CASES["nan"][0])
    pytester.makeconftest(f"import pytest_sal as sal\n\nsal_dataset = sal.dataset_fixture('kitti', {str(path)!r})\n")
    pytester.makepyfile(test_suite="def test_x(sal_dataset):\n    pass\n")
    result = pytester.runpytest("-p", "no:cacheprovider")
    result.assert_outcomes(errors=1)
    message = f"{times_file}:3: time nan s is not a finite number"
    result.stdout.fnmatch_lines(["*_ ERROR at setup of test_x _*", message, "*short test summary info*"], consecutive=True)
    assert "Traceback" not in result.stdout.str() and "common/textfiles.py" not in result.stdout.str()
