"""The ``command`` system against real external programs written here: a fake SLAM program
that reads the staged sequence's ground truth and writes it back (with a known offset) in each
output format, and programs that crash, exit(-1), hang, write garbage or nothing."""

from __future__ import annotations

import os
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from sal_adapters import Trajectory, open_dataset
from sal_wrappers import RunResult, SlamSystemError, TrackState, create

OK, LOST, NI = TrackState.OK, TrackState.LOST, TrackState.NOT_INITIALISED
NOISE = 0.001  # the fake program adds NOISE * frame position to x

FAKE_SLAM = r"""
import argparse, json, math, os, sys
from pathlib import Path

p = argparse.ArgumentParser()
p.add_argument("--sequence", required=True)
p.add_argument("--gt", choices=["tum", "kitti"], default="tum")
p.add_argument("--out", required=True)
p.add_argument("--format", default="tum")
p.add_argument("--first", type=int, default=0)
p.add_argument("--stop", type=int, default=None)
p.add_argument("--skip", default="")
p.add_argument("--every", type=int, default=1)
p.add_argument("--times-out", default=None)
p.add_argument("--need-env", action="append", default=[])
p.add_argument("--need-file", action="append", default=[])
a = p.parse_args()

for item in a.need_env:
    name, _, value = item.partition("=")
    if os.environ.get(name) != value:
        print(f"fake_slam: environment {name}={os.environ.get(name)!r}, expected {value!r}", file=sys.stderr)
        sys.exit(7)
for item in a.need_file:
    if not Path(item).is_file():
        print(f"fake_slam: {item} missing", file=sys.stderr)
        sys.exit(8)

def quat_to_mat(x, y, z, w):
    n = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]

def mat_to_quat(R):
    tr = R[0][0] + R[1][1] + R[2][2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        return [(R[2][1] - R[1][2]) / s, (R[0][2] - R[2][0]) / s, (R[1][0] - R[0][1]) / s, 0.25 * s]
    if R[0][0] > R[1][1] and R[0][0] > R[2][2]:
        s = math.sqrt(1.0 + R[0][0] - R[1][1] - R[2][2]) * 2
        return [0.25 * s, (R[0][1] + R[1][0]) / s, (R[0][2] + R[2][0]) / s, (R[2][1] - R[1][2]) / s]
    if R[1][1] > R[2][2]:
        s = math.sqrt(1.0 + R[1][1] - R[0][0] - R[2][2]) * 2
        return [(R[0][1] + R[1][0]) / s, 0.25 * s, (R[1][2] + R[2][1]) / s, (R[0][2] - R[2][0]) / s]
    s = math.sqrt(1.0 + R[2][2] - R[0][0] - R[1][1]) * 2
    return [(R[0][2] + R[2][0]) / s, (R[1][2] + R[2][1]) / s, 0.25 * s, (R[1][0] - R[0][1]) / s]

seq = Path(a.sequence)
frames = []  # (t, position, quaternion)
if a.gt == "tum":
    for line in (seq / "groundtruth.txt").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            v = [float(x) for x in line.split()]
            frames.append((v[0], v[1:4], v[4:8]))
else:
    times = [float(x) for x in (seq / "times.txt").read_text().split()]
    rows = [[float(x) for x in line.split()] for line in (seq.parents[1] / "poses" / (seq.name + ".txt")).read_text().splitlines() if line.strip()]
    for t, r in zip(times, rows):
        R = [r[0:3], r[4:7], r[8:11]]
        frames.append((t, [r[3], r[7], r[11]], mat_to_quat(R)))

skip = {int(s) for s in a.skip.split(",") if s}
stop = len(frames) if a.stop is None else a.stop
keep = [i for i in range(a.first, stop, a.every) if i not in skip]
out = []
for i in keep:
    t, pos, q = frames[i]
    pos = [pos[0] + 0.001 * i, pos[1], pos[2]]
    R = quat_to_mat(*q)
    M34 = [R[0] + [pos[0]], R[1] + [pos[1]], R[2] + [pos[2]]]
    out.append((t, pos, q, M34))

f = a.format
Path(a.out).parent.mkdir(parents=True, exist_ok=True)
with open(a.out, "w") as fh:
    if f == "tum":
        fh.write("# timestamp tx ty tz qx qy qz qw\n")
        for t, pos, q, _ in out:
            fh.write(" ".join(repr(v) for v in [t, *pos, *q]) + "\n")
    elif f == "tum-ns":  # ORB-SLAM3 SaveTrajectoryEuRoC: TUM columns, time in ns
        for t, pos, q, _ in out:
            fh.write(" ".join([str(round(t * 1e9))] + [repr(v) for v in [*pos, *q]]) + "\n")
    elif f == "kitti13":
        for t, _, _, M in out:
            fh.write(" ".join(repr(v) for v in [t] + M[0] + M[1] + M[2]) + "\n")
    elif f == "kitti12":
        for t, _, _, M in out:
            fh.write(" ".join(repr(v) for v in M[0] + M[1] + M[2]) + "\n")
        if a.times_out:
            Path(a.times_out).write_text("".join(repr(t) + "\n" for t, *_ in out))
    elif f == "euroc":
        fh.write("#timestamp [ns],px,py,pz,qw,qx,qy,qz\n")
        for t, pos, q, _ in out:
            fh.write(",".join([str(round(t * 1e9))] + [repr(v) for v in [*pos, q[3], q[0], q[1], q[2]]]) + "\n")
    elif f == "json-matrix":
        json.dump([{"t": t, "pose": M + [[0.0, 0.0, 0.0, 1.0]]} for t, _, _, M in out], fh)
    elif f == "json-quat":
        json.dump([{"t": t, "pose": [*pos, *q]} for t, pos, q, _ in out], fh)
    else:
        sys.exit(f"unknown format {f}")
print(f"fake_slam: wrote {len(out)} poses to {a.out}")
"""

SCRIPTS = {
    "fake_slam.py": FAKE_SLAM,
    "segfault.py": "import os, signal\nprint('about to crash', flush=True)\nos.kill(os.getpid(), signal.SIGSEGV)\n",
    "exit255.py": "import sys\nprint('Failed to open settings file at: nowhere.yaml', file=sys.stderr)\nsys.exit(255)\n",
    "hang.py": textwrap.dedent(
        """\
        import subprocess, sys, time
        child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
        open(sys.argv[1], "w").write(str(child.pid))
        print("tracking forever", flush=True)
        time.sleep(60)
        """
    ),
    "leave_child.py": textwrap.dedent(
        """\
        import subprocess, sys
        child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
        open(sys.argv[1], "w").write(str(child.pid))
        open(sys.argv[2], "w").write("")
        """
    ),
    "garbage.py": "import sys\nopen(sys.argv[1], 'w').write('# header\\n0.0 1.0 2.0 abc\\n')\n",
    "nothing.py": "print('done, wrote nothing')\n",
}


@pytest.fixture(scope="module")
def scripts(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("programs")
    for name, text in SCRIPTS.items():
        (folder / name).write_text(text)
    return folder


@pytest.fixture(scope="module")
def indoor():
    return open_dataset("synthetic", scene="indoor", frames=20, sensor="rgbd")


@pytest.fixture(scope="module")
def tiny(indoor):
    """Two frames: enough for the programs that crash, hang or write nothing."""
    return indoor.select(range(2))


@pytest.fixture(scope="module")
def short(indoor):
    """Six frames: enough to read every format back (staging costs time per frame)."""
    return indoor.select(range(6))


@pytest.fixture(scope="module")
def urban():
    return open_dataset("synthetic", scene="urban", frames=20, sensor="mono").select(range(10))


def fake(scripts: Path, *args: str) -> list[str]:
    return [sys.executable, str(scripts / "fake_slam.py"), "--sequence", "{sequence}", "--out", "{output}", *args]


def expected(seq, positions: list[int]) -> Trajectory:
    """What the fake program writes for ``positions``: ground truth, x shifted by NOISE * i."""
    gt = seq.groundtruth
    assert seq.groundtruth_is_per_frame
    p = gt.positions[positions].copy()
    p[:, 0] += NOISE * np.asarray(positions)
    return Trajectory(seq.timestamps[positions], p, gt.quaternions[positions])


def assert_states(result: RunResult, states: list[int]) -> None:
    assert result.states.tolist() == [int(s) for s in states], result.summary()


# -- each output format reads back what the program wrote --------------------------------------------
@pytest.mark.parametrize(
    ("fmt", "options", "extra"),
    [
        ("tum", {"output_format": "tum", "layout": "tum"}, []),
        ("tum-ns", {"output_format": "tum", "time_unit": "ns", "layout": "tum"}, []),
        ("euroc", {"output_format": "euroc", "layout": "tum"}, []),
        ("json-matrix", {"output_format": "json"}, []),  # default layout: the synthetic one
        ("json-quat", {"output_format": "json", "layout": "tum"}, []),
    ],
)
def test_formats_read_back(scripts, short, tmp_path, fmt, options, extra):
    system = create("command", argv=fake(scripts, "--format", fmt, *extra), sensor="mono", **options)
    result = system.run(short, tmp_path / "w", timeout=60)
    assert result.ok, (result.failure, result.log_tail)
    assert result.exit_status == 0 and result.maps == 1 and result.tracking_rate == 1.0
    assert result.trajectory.allclose(expected(short, list(range(6))), atol=1e-6)
    assert result.final_trajectory is not None and len(result.final_trajectory) == 6
    assert result.scored == "final" and result.sensor == "mono"
    assert result.info["output_format"] == options["output_format"]
    assert result.info["staged"] in result.info["argv"]
    assert RunResult.from_json(result.to_json()).trajectory.allclose(result.trajectory)


@pytest.mark.parametrize(
    ("fmt", "extra", "positions"),
    [
        ("kitti13", [], list(range(10))),
        ("kitti12", [], list(range(10))),  # no times: one pose per frame given
        ("kitti12", ["--first", "3", "--times-out", "{output_times}"], list(range(3, 10))),
    ],
)
def test_kitti_formats(scripts, urban, tmp_path, fmt, extra, positions):
    system = create("command", argv=fake(scripts, "--gt", "kitti", "--format", fmt, *extra), output_format="kitti", layout="kitti")
    result = system.run(urban, tmp_path / "w", timeout=60)
    assert result.ok, (result.failure, result.log_tail)
    assert result.info["staged"].endswith("sequences/00")
    assert result.trajectory.allclose(expected(urban, positions), atol=1e-6)
    assert result.tracked == len(positions)


def test_kitti_without_times_for_part_of_the_frames_is_unparsable(scripts, urban, tmp_path):
    system = create(
        "command", argv=fake(scripts, "--gt", "kitti", "--format", "kitti12", "--first", "3"), output_format="kitti", layout="kitti"
    )
    result = system.run(urban, tmp_path / "w", timeout=60)
    assert not result.ok and result.exit_status == 0
    assert "unparsable output" in result.failure and "7 poses" in result.failure and "{output_times}" in result.failure
    assert result.tracked == 0 and result.trajectory is None


def test_dropped_frames_keep_their_times(scripts, urban, tmp_path):
    kept = [0, 1, 2, 5, 6, 8, 9]
    dropped = urban.select(kept)
    system = create("command", argv=fake(scripts, "--gt", "kitti", "--format", "kitti12"), output_format="kitti", layout="kitti")
    result = system.run(dropped, tmp_path / "w", timeout=60)
    assert result.ok, result.failure
    np.testing.assert_allclose(result.timestamps, urban.timestamps[kept])
    gt = dropped.groundtruth
    assert np.allclose(result.trajectory.positions[:, 1:], gt.positions[:, 1:]) and result.tracking_rate == 1.0


# -- tracking states ---------------------------------------------------------------------------------
def test_poses_for_part_of_the_frames(scripts, indoor, tmp_path):
    system = create("command", argv=fake(scripts, "--first", "5", "--stop", "15", "--skip", "9,10"), sensor="mono", layout="tum")
    result = system.run(indoor, tmp_path / "w", timeout=60)
    assert result.ok
    assert_states(result, [NI] * 5 + [OK] * 4 + [LOST] * 2 + [OK] * 4 + [LOST] * 5)
    assert result.tracked == 8 and result.tracking_rate == pytest.approx(0.4) and result.first_tracked == 5
    assert result.trajectory.allclose(expected(indoor, [5, 6, 7, 8, 11, 12, 13, 14]), atol=1e-6)


def test_keyframe_trajectory(scripts, indoor, tmp_path):
    system = create("command", argv=fake(scripts, "--first", "2", "--every", "4"), keyframes=True, sensor="mono", layout="tum")
    result = system.run(indoor, tmp_path / "w", timeout=60)
    assert result.ok
    assert_states(result, [NI] * 2 + [OK] * 17 + [LOST])  # keyframes at 2, 6, 10, 14, 18
    assert len(result.trajectory) == 5


def test_wrong_time_unit_matches_no_frame(scripts, short, tmp_path):
    system = create("command", argv=fake(scripts, "--format", "tum-ns", "--first", "1"), sensor="mono", layout="tum")
    result = system.run(short, tmp_path / "w", timeout=60)
    assert not result.ok and result.maps == 0 and result.trajectory is None
    assert result.failure.startswith("none of the 5 poses")
    assert "time_unit" in result.failure


# -- failures of the program come back in words --------------------------------------------------------
def test_segfault(scripts, tiny, tmp_path):
    result = create("command", argv=[sys.executable, str(scripts / "segfault.py")], sensor="mono", layout="folder").run(
        tiny, tmp_path / "w", timeout=60
    )
    assert result.exit_status == -11
    assert "SIGSEGV" in result.failure and "segmentation fault" in result.failure
    assert "about to crash" in result.log_tail
    assert_states(result, [NI] * 2)


def test_exit_255(scripts, tiny, tmp_path):
    result = create("command", argv=[sys.executable, str(scripts / "exit255.py")], sensor="mono", layout="folder").run(
        tiny, tmp_path / "w", timeout=60
    )
    assert result.exit_status == 255 and result.failure.startswith("exit status 255")
    assert "Failed to open settings file" in result.log_tail
    assert result.log_path == tmp_path / "w" / "run.log"


def test_timeout_kills_the_process_group(scripts, tiny, tmp_path):
    pid_file = tmp_path / "child.pid"
    system = create("command", argv=[sys.executable, str(scripts / "hang.py"), str(pid_file)], sensor="mono", layout="folder")
    result = system.run(tiny, tmp_path / "w", timeout=1.0)
    assert result.failure == "timed out after 1 s and was killed"  # seconds to the result: benchmarks/bench_time_limits.py
    assert "tracking forever" in result.log_tail
    assert_gone(int(pid_file.read_text()))


def test_children_left_behind_are_killed(scripts, tiny, tmp_path):
    pid_file = tmp_path / "child.pid"
    argv = [sys.executable, str(scripts / "leave_child.py"), str(pid_file), "{output}"]
    result = create("command", argv=argv, sensor="mono", layout="folder").run(tiny, tmp_path / "w", timeout=30)
    assert result.exit_status == 0
    assert "no pose in the trajectory" in result.failure  # an empty file: nothing tracked
    assert_gone(int(pid_file.read_text()))


def assert_gone(pid: int) -> None:
    """``pid`` is dead (gone, or a zombie of a parent that does not reap); SIGKILL lands at once
    but the kernel may take a moment to act on it."""
    status = Path(f"/proc/{pid}/status")
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
            text = status.read_text()
        except (ProcessLookupError, FileNotFoundError):
            return
        if "\nState:\tZ" in text:
            return
        time.sleep(0.02)
    raise AssertionError(f"process {pid} still runs")


def test_garbage_output(scripts, tiny, tmp_path):
    result = create("command", argv=[sys.executable, str(scripts / "garbage.py"), "{output}"], sensor="mono", layout="folder").run(
        tiny, tmp_path / "w", timeout=30
    )
    out = tmp_path.resolve() / "w" / "trajectory.txt"
    assert result.exit_status == 0
    assert result.failure.startswith(f"unparsable output: {out}:2: expected 8 values")


def test_garbage_json(scripts, tiny, tmp_path):
    system = create(
        "command",
        argv=[sys.executable, str(scripts / "garbage.py"), "{output}"],
        output="out.json",
        output_format="json",
        sensor="mono",
        layout="folder",
    )
    result = system.run(tiny, tmp_path / "w", timeout=30)
    assert "unparsable output" in result.failure and "out.json:1: not valid JSON" in result.failure


def test_missing_output(scripts, tiny, tmp_path):
    result = create("command", argv=[sys.executable, str(scripts / "nothing.py")], sensor="mono", layout="folder").run(
        tiny, tmp_path / "w", timeout=30
    )
    assert result.exit_status == 0
    assert result.failure.startswith("no trajectory written:") and "trajectory.txt not found" in result.failure


def test_stale_output_outside_workdir_is_not_taken(scripts, tiny, tmp_path):
    cwd = tmp_path / "checkout"
    cwd.mkdir()
    (cwd / "CameraTrajectory.txt").write_text("0.0 0 0 0 0 0 0 1\n")
    system = create(
        "command",
        argv=[sys.executable, str(scripts / "nothing.py")],
        cwd=str(cwd),
        output="CameraTrajectory.txt",
        sensor="mono",
        layout="folder",
    )
    result = system.run(tiny, tmp_path / "w", timeout=30)
    assert "is left from before this run" in result.failure
    assert result.info["cwd"] == str(cwd)


@pytest.mark.parametrize(("argv0", "words"), [("/no/such/slam", "no such file"), ("no-such-slam-program-xyz", "not on PATH")])
def test_executable_not_found(tiny, tmp_path, argv0, words):
    result = create("command", argv=[argv0, "{sequence}"], sensor="mono", layout="folder").run(tiny, tmp_path / "w", timeout=30)
    assert result.failure == f"executable not found: {argv0!r} ({words})"
    assert result.exit_status is None and result.tracked == 0


# -- prefix, env, settings, glob output ------------------------------------------------------------
def test_prefix_and_env(scripts, short, tmp_path):
    workdir = tmp_path / "w"
    argv = fake(scripts, "--need-env", "FOO=1", "--need-env", f"WHERE={workdir.resolve()}")
    without = create("command", argv=argv, env={"WHERE": "{workdir}"}, sensor="mono", layout="tum").run(short, workdir, timeout=60)
    assert without.exit_status == 7 and "environment FOO=None" in without.log_tail
    system = create("command", argv=argv, prefix=["env", "FOO=1"], env={"WHERE": "{workdir}"}, sensor="mono", layout="tum")
    result = system.run(short, workdir, timeout=60)
    assert result.ok, (result.failure, result.log_tail)
    assert result.info["argv"][:2] == ["env", "FOO=1"]


def test_settings_template_is_rendered(scripts, short, tmp_path):
    template = tmp_path / "Synthetic.yaml"
    template.write_text(
        "%YAML:1.0\nCamera.fx: {camera_fx}\nCamera.fps: {fps}\nsize: {camera_width}x{camera_height}\nbf: {camera_bf}\nliteral: {{x}}\n"
    )
    system = create("command", argv=fake(scripts, "--need-file", "{settings}"), settings=str(template), sensor="mono", layout="tum")
    result = system.run(short, tmp_path / "w", timeout=60)
    assert result.ok, result.failure
    rendered = Path(result.info["settings"])
    assert rendered.parent == tmp_path.resolve() / "w" / "settings"
    assert rendered.read_text() == "%YAML:1.0\nCamera.fx: 525.0\nCamera.fps: 30\nsize: 640x480\nbf: 0.0\nliteral: {x}\n"


def test_glob_output_and_helper_files(scripts, short, tmp_path):
    argv = [*fake(scripts, "--need-file", "{timestamps}", "--need-file", "{associations}")]
    argv[argv.index("{output}")] = "{workdir}/logs/run/short.txt"
    system = create("command", argv=argv, output="logs/*/*.txt", layout="tum")
    result = system.run(short, tmp_path / "w", timeout=60)
    assert result.ok, (result.failure, result.log_tail)
    assert result.info["output"] == str(tmp_path.resolve() / "w" / "logs" / "run" / "short.txt")
    assert result.sensor == "rgbd"
    pairs = (tmp_path / "w" / "associations.txt").read_text().splitlines()
    assert len(pairs) == 6 and pairs[0].split()[1] == "rgb/000000.png" and pairs[0].split()[3] == "depth/000000.png"
    ns = (tmp_path / "w" / "timestamps_ns.txt").read_text().split()
    assert ns[:2] == ["0", "33333333"]


def test_mono_mode_stages_no_depth(scripts, short, tmp_path):
    system = create("command", argv=fake(scripts), sensor="mono", layout="tum", stage_dir="data/tum/fr3")
    result = system.run(short, tmp_path / "w", timeout=60)
    staged = Path(result.info["staged"])
    assert staged == tmp_path.resolve() / "w" / "data" / "tum" / "fr3"
    assert (staged / "rgb.txt").is_file() and not (staged / "depth.txt").exists()


def test_exit_127_from_a_prefix(tiny, tmp_path):
    system = create("command", argv=["no-such-slam-program-xyz"], prefix=["env", "FOO=1"], sensor="mono", layout="folder")
    result = system.run(tiny, tmp_path / "w", timeout=30)
    assert result.failure == "exit status 127 (command not found by the shell or prefix)"
    assert "no-such-slam-program-xyz" in result.log_tail


# -- bad use is an error at construction --------------------------------------------------------------
@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"argv": ["slam", "{sequnce}"]}, r"unknown placeholder \{sequnce\} in argv\[1\].*known: \{sequence\}, \{workdir\}"),
        ({"argv": ["slam"], "prefix": ["docker", "-v", "{wrkdir}:/w"]}, r"unknown placeholder \{wrkdir\} in prefix\[2\]"),
        (
            {"argv": "slam {sequence} {output}"},
            r"argv must be a list of strings, not a shell string: pass \['slam', '\{sequence\}', '\{output\}'\]",
        ),
        ({"argv": []}, "argv is empty"),
        ({}, "argv is required"),
        ({"argv": ["slam", 3]}, r"argv\[1\] must be a string"),
        ({"argv": ["slam", "{settings}"]}, "no settings template was given"),
        ({"argv": ["slam"], "settings": "/no/such.yaml"}, "settings template not found: /no/such.yaml"),
        ({"argv": ["slam"], "output_format": "csv"}, "output_format 'csv' is not known; allowed: tum, kitti, euroc, json"),
        ({"argv": ["slam"], "time_unit": "min"}, "time_unit 'min' is not known"),
        ({"argv": ["slam"], "layout": "kiti"}, "layout 'kiti' is not a dataset layout; allowed: euroc, folder, kitti, synthetic, tum"),
        ({"argv": ["slam"], "layout": "kitti", "sensor": "rgbd"}, "the kitti layout cannot hold rgbd data"),
        ({"argv": ["slam"], "sensor": "lidar"}, "sensor 'lidar' is not known"),
        ({"argv": ["slam", "{output}"], "output": "logs/*.txt"}, "is a glob pattern"),
        ({"argv": ["slam"], "features": 2000}, "unknown option 'features'; allowed: argv, prefix, output"),
        ({"argv": ["slam"], "env": {"A": 1}}, "env must map variable names to strings"),
        ({"argv": ["slam"], "output": "{output_times}"}, r"output cannot use \{output_times\}"),
        ({"argv": ["slam"], "stage_dir": "../elsewhere"}, "stage_dir must be a relative folder"),
        ({"argv": ["slam"], "stage_dir": "settings"}, "stage_dir must be a relative folder"),
    ],
)
def test_bad_options(options, match):
    with pytest.raises(SlamSystemError, match=match):
        create("command", **options)


def test_unknown_placeholder_in_settings_names_file_and_line(tmp_path):
    template = tmp_path / "s.yaml"
    template.write_text("a: 1\nb: {camera_fz}\n")
    with pytest.raises(SlamSystemError, match=rf"{template}:2: unknown placeholder \{{camera_fz\}}"):
        create("command", argv=["slam", "{settings}"], settings=str(template))


def test_stereo_mode_on_a_mono_sequence_is_bad_use(indoor, tmp_path):
    with pytest.raises(SlamSystemError, match="cannot run in 'stereo' mode"):
        create("command", argv=["slam"], sensor="stereo").run(indoor, tmp_path / "w")


# -- name, version, depends and the cache key ------------------------------------------------------
DRIFT_SLAM = textwrap.dedent(
    """\
    import sys
    from pathlib import Path

    DRIFT = {drift}  # metres of x error added per frame
    sequence, out = Path(sys.argv[1]), Path(sys.argv[2])
    rows = [line.split() for line in (sequence / "groundtruth.txt").read_text().splitlines() if line.strip() and not line.startswith("#")]
    with out.open("w") as fh:
        for i, r in enumerate(rows):
            fh.write(" ".join([r[0], repr(float(r[1]) + DRIFT * i * i), *r[2:8]]) + "\\n")
    """
)


def drift_script(path: Path, drift: float) -> Path:
    path.write_text(DRIFT_SLAM.format(drift=drift))
    return path


def trial_runner(tmp_path: Path, system):
    from pytest_sal import ate_rmse
    from pytest_sal.engine.requirements import Requirement
    from pytest_sal.engine.trial_runner import TrialRunner
    from pytest_sal.store.trial_cache import ContentCache
    from sal_modules import fog

    dataset = open_dataset("synthetic", scene="indoor", frames=8, sensor="rgbd")
    requirement = Requirement.build([ate_rmse < 0.5, fog.visibility_m >= 25])
    return TrialRunner(
        dataset,
        fog.visibility_m.ref(),
        system,
        requirement,
        runs=1,
        cache=ContentCache(tmp_path / "cache"),
        workdir=tmp_path / "work",
        timeout=60,
    )


def test_editing_the_script_invalidates_cached_trials(tmp_path):
    script = drift_script(tmp_path / "myslam.py", 0.0001)
    argv = [sys.executable, str(script), "{sequence}", "{output}"]
    first = trial_runner(tmp_path, create("command", argv=argv, layout="tum")).evaluate(30.0)
    assert not first.cached and first.runs[0]["failure"] is None, first.runs
    again = trial_runner(tmp_path, create("command", argv=argv, layout="tum")).evaluate(30.0)
    assert again.cached and again.metrics == first.metrics
    drift_script(script, 0.01)  # a worse SLAM program under the same argv
    edited = trial_runner(tmp_path, create("command", argv=argv, layout="tum")).evaluate(30.0)
    assert not edited.cached
    assert edited.metrics["ate_rmse"] > 10 * first.metrics["ate_rmse"]


@pytest.mark.parametrize(
    ("crash", "words"),
    [
        pytest.param("import os, signal; os.kill(os.getpid(), signal.SIGSEGV)", "killed by SIGSEGV (segmentation fault)", id="segfault"),
        pytest.param("import sys; sys.exit(139)", "exit status 139", id="exit-139"),
    ],
)
def test_a_crash_after_writing_the_trajectory_keeps_it_and_its_ate(tmp_path, crash, words):
    """Issue 12 point 8: the README's promise, end to end through a trial."""
    clean = drift_script(tmp_path / "clean.py", 0.0001)
    crashing = drift_script(tmp_path / "crashing.py", 0.0001)
    crashing.write_text(crashing.read_text() + crash + "\n")

    def trial(script: Path):
        system = create("command", argv=[sys.executable, str(script), "{sequence}", "{output}"], layout="tum", deterministic=True)
        return trial_runner(tmp_path / script.stem, system).evaluate(30.0)

    good, crashed = trial(clean), trial(crashing)
    run = crashed.runs[0]
    assert run["failure"] == f"{words} after writing its trajectory (8 poses: kept and scored)"
    assert run["ate_rmse"] is not None and run["ate_rmse"] == pytest.approx(good.runs[0]["ate_rmse"])
    assert run["tracking_rate"] == 1.0 and run["passed"]
    assert crashed.passed and crashed.metrics["ate_rmse"] == pytest.approx(good.metrics["ate_rmse"])
    assert crashed.metrics["failures"] == [run["failure"]] and good.metrics["failures"] == []


def test_a_crash_after_writing_an_unreadable_trajectory_is_not_scored(scripts, short, tmp_path):
    """Only a trajectory that this run wrote, that reads back and that matches the frames is scored."""
    from pytest_sal.analysis.metrics import evaluate

    argv = ["sh", "-c", f'"{sys.executable}" "$0" "$1"; kill -SEGV $$', str(scripts / "garbage.py"), "{output}"]
    result = create("command", argv=argv, sensor="mono", layout="folder").run(short, tmp_path / "w", timeout=30)
    assert result.exit_status == -11 and result.failure == "killed by SIGSEGV (segmentation fault)"
    assert "written_before_failure" not in result.info and result.info["output_error"].startswith("unparsable output")
    assert evaluate(result, short.groundtruth).ate_rmse is None


def test_depends_files_and_folders_are_part_of_the_key(tmp_path):
    script = drift_script(tmp_path / "myslam.py", 0.0)
    lib = tmp_path / "lib"
    (lib / "sub").mkdir(parents=True)
    (lib / "sub" / "model.py").write_text("A = 1\n")
    (lib / "__pycache__").mkdir()
    config = tmp_path / "config.yaml"
    config.write_text("a: 1\n")
    system = create("command", argv=[sys.executable, str(script), "{sequence}", "{output}"], depends=[str(lib), config])
    before = system.identity()
    assert set(before["files"]) == {sys.executable, str(script), str(lib.resolve()), str(config.resolve())}
    assert "{sequence}" not in before["files"]
    (lib / "__pycache__" / "model.cpython-311.pyc").write_bytes(b"\0")  # running the program writes caches
    assert system.identity() == before
    (lib / "sub" / "model.py").write_text("A = 2\n")
    after_lib = system.identity()
    assert after_lib["files"][str(lib.resolve())] != before["files"][str(lib.resolve())]
    config.write_text("a: 2\n")
    assert system.identity()["files"][str(config.resolve())] != after_lib["files"][str(config.resolve())]


def test_the_executable_is_found_on_path_and_hashed(tmp_path):
    program = tmp_path / "bin" / "myslam"
    program.parent.mkdir()
    program.write_text("#!/bin/sh\nexit 0\n")
    program.chmod(0o755)
    system = create("command", argv=["myslam", "{sequence}"], env={"PATH": str(program.parent)})
    first = system.identity()["files"]["myslam"]
    assert first is not None and len(first) == 64
    program.write_text("#!/bin/sh\nexit 1\n")
    assert system.identity()["files"]["myslam"] != first
    assert create("command", argv=["no-such-slam-program-xyz"]).identity()["files"] == {"no-such-slam-program-xyz": None}


def test_name_is_shown_in_results_and_outcomes(scripts, tmp_path):
    from pytest_sal.engine.requirement_runner import single_outcome

    system = create(
        "command", argv=[sys.executable, str(drift_script(tmp_path / "s.py", 0.0)), "{sequence}", "{output}"], name="myslam", layout="tum"
    )
    assert system.name == "myslam" and type(system).name == "command"
    runner = trial_runner(tmp_path, system)
    result = system.run(runner.dataset.select(range(4)), tmp_path / "w", timeout=60)
    assert result.ok and result.system == "myslam"
    outcome = single_outcome(runner, runner.requirement, "test_x", 30.0)
    assert outcome.system == "myslam" and outcome.trials[0].runs[0]["system"] == "myslam"
    assert create("command", argv=["slam"]).name == "command"
    assert system.identity()["name"] == "myslam"


def test_name_and_version_change_the_key(tmp_path):
    from pytest_sal.store.cache_keys import cache_key

    def key(**options):
        return cache_key(system=create("command", argv=["slam", "{sequence}"], **options).identity())

    assert key() == key() != key(version="2.1") != key(version="2.2")
    assert key(version="2.1") == key(version="2.1")
    assert key(name="myslam") != key()
    assert create("command", argv=["slam"], version="2.1").options()["version"] == "2.1"


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"name": ""}, "option name='' is not allowed: give 1 to 64 letters, digits"),
        ({"name": "my slam"}, "option name='my slam' is not allowed"),
        ({"name": "a/b"}, "option name='a/b' is not allowed"),
        ({"name": "x" * 65}, "is not allowed: give 1 to 64"),
        ({"name": 3}, "option name=3 is not allowed"),
        ({"version": ""}, "option version='' is not allowed"),
        ({"version": ["1"]}, "option version=\\['1'\\] is not allowed"),
        ({"depends": ["/no/such/lib"]}, "depends: /no/such/lib does not exist"),
        ({"depends": "lib.py"}, "depends must be a list of strings"),
    ],
)
def test_bad_name_version_depends(options, match):
    with pytest.raises(SlamSystemError, match=match):
        create("command", argv=["slam"], **options)


def test_a_depends_file_removed_after_creation_is_a_clear_error(tmp_path):
    lib = tmp_path / "lib.py"
    lib.write_text("A = 1\n")
    system = create("command", argv=["slam"], depends=[str(lib)])
    lib.unlink()
    with pytest.raises(SlamSystemError, match=r"cannot read the depends file .*lib\.py to hash it for the cache key"):
        system.identity()


def test_a_too_big_depends_folder_is_a_clear_error(tmp_path, monkeypatch):
    import sal_wrappers.command_files as command_files

    lib = tmp_path / "lib"
    lib.mkdir()
    for i in range(3):
        (lib / f"m{i}.py").write_text("x\n")
    monkeypatch.setattr(command_files, "DEPENDS_MAX_FILES", 2)
    with pytest.raises(SlamSystemError, match="depends folder .* holds more than 2 files"):
        create("command", argv=["slam"], depends=[str(lib)]).identity()


def test_a_command_system_is_noisy_unless_it_says_it_is_deterministic() -> None:
    from pytest_sal.engine.trial_runner import VotePolicy

    noisy = create("command", argv=["true"])
    steady = create("command", argv=["true"], deterministic=True)
    assert VotePolicy.for_system(noisy, None).max_runs == 5 and VotePolicy.for_system(steady, None).max_runs == 1
    assert steady.options()["deterministic"] and steady.identity() != noisy.identity()
    with pytest.raises(SlamSystemError, match="deterministic must be True or False, got 'yes'"):
        create("command", argv=["true"], deterministic="yes")
