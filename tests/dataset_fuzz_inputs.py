"""Hostile versions of real dataset files for the dataset readers' fuzz (test_dataset_fuzz.py,
benchmarks/fuzz_dataset_readers.py): copies of the real KITTI 07, EuRoC V1_01 and TUM excerpts
(``prepare``), and ``mutate``, which edits one file's bytes with a ``random.Random``: NaN,
infinities, huge and 400-digit numbers, deep nesting, alias bombs, binary garbage, truncated,
dropped or repeated lines, and files of 200 MB (sparse: nothing is written)."""

from __future__ import annotations

import random
import re
import shutil
from dataclasses import dataclass
from pathlib import Path

from euroc_excerpt import SEQ, _euroc_copy
from experiment_fuzz_configs import alias_bomb
from kitti_excerpt import kitti_copy

__all__ = ["HUGE_BYTES", "Hostile", "Target", "mutate", "prepare"]

#: Size of the "huge file" edit (bytes): a sparse file, so nothing is written.
HUGE_BYTES = 200 * 2**20

#: Replacements for one number of a file.
NUMBERS = ["nan", "NaN", ".nan", "inf", "-inf", ".inf", "-.inf", "1e400", "1e308", "-1e308", "0", "-0", "1" + "0" * 400, "1e-400", "x", ""]
#: Text put at a random place.
INSERTS = ["[" * 5000, "{a: " * 2000, "&a ", "*a", "!!python/object:os.system ", "\t", "\x00", "\ufeff", ": : :", "---\n", "\n" * 50]
_NUMBER = re.compile(rb"[-+]?\d+(?:\.\d*)?(?:e[-+]?\d+)?", re.IGNORECASE)


@dataclass(frozen=True)
class Target:
    """One file the fuzz edits: the dataset ``kind`` and folder it opens, and the file."""

    name: str
    kind: str
    folder: Path
    file: Path


@dataclass(frozen=True)
class Hostile:
    """An edited file: its bytes, padded with zeros to ``size`` bytes when larger (sparse)."""

    data: bytes
    size: int
    edits: tuple[str, ...]

    def write(self, path: Path) -> None:
        path.write_bytes(self.data)
        if self.size > len(self.data):
            with path.open("r+b") as handle:
                handle.truncate(self.size)


def prepare(shared_data: Path, root: Path) -> list[Target]:
    """Copies of the real excerpts under ``root``, and the files of each the fuzz edits:
    KITTI ``calib.txt``, ``times.txt`` and poses; EuRoC ``sensor.yaml``, the frame list
    ``data.csv`` and the ground-truth CSV; a folder of TUM frames with ``camera.yaml``,
    ``times.txt`` and ``groundtruth.txt``."""
    kitti = kitti_copy(shared_data, root / "kitti")
    (kitti.parents[1] / "poses").mkdir()
    poses = (shared_data / "kitti" / "poses" / "07.txt").read_text().splitlines(True)[:3]
    (kitti.parents[1] / "poses" / "07.txt").write_text("".join(poses))
    euroc = _euroc_copy(shared_data / "euroc" / SEQ, root / "euroc" / SEQ, cams=("cam0",))
    gt = euroc / "mav0" / "state_groundtruth_estimate0" / "data.csv"
    gt.parent.mkdir()
    shutil.copy(shared_data / "euroc" / SEQ / "groundtruth_cam0_V101_GT_orbslam3_window.csv", gt)
    folder = root / "folder"
    shutil.copytree(shared_data / "tum_rgbd_samples" / "fr3_long_office_household_4frames_pyslam", folder)
    images = sorted(p for p in folder.rglob("*.png"))
    (folder / "camera.yaml").write_text("fx: 535.4\nfy: 539.2\ncx: 320.1\ncy: 247.6\nwidth: 640\nheight: 480\ndistortion: [0, 0, 0, 0]\n")
    (folder / "times.txt").write_text("".join(f"{1341847980.7 + 0.033 * k:.6f} {p.relative_to(folder)}\n" for k, p in enumerate(images)))
    (folder / "groundtruth.txt").write_text("".join(f"{1341847980.7 + 0.033 * k:.6f} {k * 0.01} 0 0 0 0 0 1\n" for k in range(len(images))))
    return [
        Target("kitti calib.txt", "kitti", kitti, kitti / "calib.txt"),
        Target("kitti times.txt", "kitti", kitti, kitti / "times.txt"),
        Target("kitti poses", "kitti", kitti, kitti.parents[1] / "poses" / "07.txt"),
        Target("euroc sensor.yaml", "euroc", euroc, euroc / "mav0" / "cam0" / "sensor.yaml"),
        Target("euroc data.csv", "euroc", euroc, euroc / "mav0" / "cam0" / "data.csv"),
        Target("euroc ground truth", "euroc", euroc, gt),
        Target("folder camera.yaml", "folder", folder, folder / "camera.yaml"),
        Target("folder times.txt", "folder", folder, folder / "times.txt"),
        Target("folder groundtruth.txt", "folder", folder, folder / "groundtruth.txt"),
    ]


def mutate(data: bytes, rng: random.Random) -> Hostile:
    """One to three random edits of ``data`` (a file's bytes)."""
    edits: list[str] = []
    size = 0
    for _ in range(rng.randint(1, 3)):
        edit = rng.choice(["number", "insert", "garbage", "truncate", "drop line", "repeat line", "alias bomb", "huge"])
        edits.append(edit)
        numbers = list(_NUMBER.finditer(data))
        at = rng.randint(0, len(data))
        lines = data.splitlines(True) or [b""]
        line = rng.randrange(len(lines))
        if edit == "number" and numbers:
            match = rng.choice(numbers)
            data = data[: match.start()] + rng.choice(NUMBERS).encode() + data[match.end() :]
        elif edit == "insert":
            data = data[:at] + rng.choice(INSERTS).encode("utf-8") + data[at:]
        elif edit == "garbage":
            data = data[:at] + rng.randbytes(rng.randint(1, 64)) + data[at:]
        elif edit == "truncate":
            data = data[:at]
        elif edit == "drop line":
            data = b"".join(lines[:line] + lines[line + 1 :])
        elif edit == "repeat line":
            data = b"".join(lines[:line] + [lines[line]] * rng.choice([2, 1000]) + lines[line:])
        elif edit == "alias bomb":
            data = alias_bomb(9).encode() + data
        elif edit == "huge":
            size = HUGE_BYTES
    return Hostile(data, size, tuple(edits))
