"""The programs the ``command`` system tests run (test_command_formats.py, test_command_runs.py,
test_command_cache_key.py): a fake SLAM program that reads the staged sequence's ground truth and
writes it back (with a known offset) in each output format, programs that crash, exit(-1), hang,
write garbage or nothing, and the small synthetic sequences they run on."""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from sal_adapters import Trajectory, open_dataset
from sal_wrappers import RunResult, TrackState

__all__ = [
    "FAKE_SLAM",
    "LOST",
    "NI",
    "NOISE",
    "OK",
    "SCRIPTS",
    "assert_states",
    "expected",
    "fake",
    "indoor",
    "scripts",
    "short",
    "tiny",
    "urban",
]


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
