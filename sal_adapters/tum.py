"""TUM RGB-D layout: ``rgb.txt``, ``depth.txt`` (lines ``timestamp filename``), optional
``associations.txt`` (``t_rgb rgb_file t_depth depth_file``), ``groundtruth.txt``
(``t tx ty tz qx qy qz qw``, the optical centre's pose in the world), ``rgb/*.png`` and
``depth/*.png`` (uint16, 5000 units per metre).

Colour and depth are paired as TUM's ``associate.py`` does: candidate pairs closer than
``max_time_diff`` seconds, taken greedily by smallest time difference, each image used once.

Intrinsics, in priority: the ``intrinsics=`` option, ``camera.yaml`` in the sequence folder (see
``sal_adapters.layout_io``; the writer always leaves one), the Freiburg camera named in the
folder name (``freiburg1``/``fr1`` .. ``freiburg3``/``fr3``), else the ROS default (warned).
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterable
from dataclasses import replace
from functools import partial
from pathlib import Path, PurePosixPath

import numpy as np

from sal_adapters.camera import Camera
from sal_adapters.common.errors import DatasetError, DatasetWarning
from sal_adapters.common.textfiles import atomic_write_text, format_float
from sal_adapters.datasets import DatasetKind
from sal_adapters.images import probe_image, write_depth, write_image
from sal_adapters.layout_io import (
    CAMERA_FILE,
    checked_image,
    fps_from_timestamps,
    frame_file_stem,
    read_list,
    select_camera,
    write_camera_yaml,
)
from sal_adapters.sequence import Frame, FrameRecord, Sequence
from sal_adapters.trajectory import Trajectory

__all__ = ["DEPTH_SCALE", "FREIBURG_CAMERAS", "ROS_DEFAULT_INTRINSICS", "TUM", "TumDataset", "associate", "freiburg_camera"]

#: Freiburg camera -> ((fx, fy, cx, cy) px, OpenCV distortion k1 k2 p1 p2 k3), from the TUM site.
FREIBURG_CAMERAS: dict[int, tuple[tuple[float, float, float, float], tuple[float, ...]]] = {
    1: ((517.3, 516.5, 318.6, 255.3), (0.2624, -0.9531, -0.0054, 0.0026, 1.1633)),
    2: ((520.9, 521.0, 325.1, 249.7), (0.2312, -0.7849, -0.0033, -0.0001, 0.9172)),
    3: ((535.4, 539.2, 320.1, 247.6), ()),
}
#: Intrinsics (px) of the ROS default calibration, used when the camera is unknown.
ROS_DEFAULT_INTRINSICS = (525.0, 525.0, 319.5, 239.5)
#: Raw depth units per metre in TUM depth images.
DEPTH_SCALE = 5000.0
#: Nominal TUM frame rate (Hz), used for a single-frame sequence.
TUM_FPS = 30.0

_LIST_HEADERS = {
    "rgb.txt": "# color images\n# timestamp filename\n",
    "depth.txt": "# depth maps\n# timestamp filename\n",
    "associations.txt": "# timestamp_rgb rgb_filename timestamp_depth depth_filename\n",
}


class TumDataset(DatasetKind):
    """TUM RGB-D sequences (RGB-D or colour only)."""

    name = "tum"
    description = "TUM RGB-D: rgb.txt, depth.txt, groundtruth.txt, rgb/, depth/ (depth x5000)"

    def open(
        self,
        path: Path | None,
        *,
        sequence: str | None = None,
        stereo: bool = False,
        intrinsics: tuple[float, float, float, float] | str | None = None,
        distortion: tuple[float, ...] | str | None = None,
        depth: bool | None = None,
        max_time_diff: float = 0.02,
    ) -> Sequence:
        """Open a TUM RGB-D sequence.

        Args:
            path: the sequence folder (holding ``rgb.txt``), or a folder of sequences.
            sequence: a sequence folder under ``path``: ``rgbd_dataset_freiburg1_xyz``, or the
                short ``freiburg1_xyz`` / ``fr1_xyz``.
            stereo: must be False (TUM RGB-D has no stereo camera).
            intrinsics: ``(fx, fy, cx, cy)`` (px) replacing camera.yaml / the Freiburg values;
                no distortion unless ``distortion`` is given too.
            distortion: OpenCV coefficients ``(k1, k2, p1, p2[, k3])`` replacing the known ones.
            depth: True: RGB-D (``depth.txt`` or ``associations.txt`` required); False: colour
                only; None (default): RGB-D when either file exists, else colour only.
            max_time_diff: largest colour-depth time difference (s) of an associated pair.
        """
        if stereo:
            raise DatasetError("TUM RGB-D has no stereo camera; open it with stereo=False (sensor rgbd or mono)")
        if not max_time_diff > 0:
            raise DatasetError(f"option max_time_diff must be > 0 s, got {max_time_diff!r}")
        folder = _sequence_folder(path, sequence)
        rgb_path = folder / "rgb.txt"
        rgb_rows = read_list(rgb_path, "tf", "timestamp filename")
        rgb_times = np.array([row[1][0] for row in rgb_rows], dtype=np.float64)
        rgb_names = [str(row[1][1]) for row in rgb_rows]
        has_depth = (folder / "depth.txt").is_file() or (folder / "associations.txt").is_file()
        use_depth = has_depth if depth is None else bool(depth)
        if use_depth:
            pairs = _depth_pairs(folder, rgb_times, rgb_names, max_time_diff)
        else:
            pairs = [(i, None) for i in range(len(rgb_names))]

        records = [
            FrameRecord(
                index=i,
                timestamp=float(rgb_times[i]),
                stem=PurePosixPath(rgb_names[i]).stem,
                image=folder / rgb_names[i],
                depth=None if depth_name is None else folder / depth_name,
            )
            for i, depth_name in pairs
        ]
        first, first_depth = pairs[0]
        width, height, grey = probe_image(folder / rgb_names[first])
        if first_depth is not None and not (folder / first_depth).is_file():
            raise DatasetError("depth image not found", folder / first_depth)
        fallback = partial(_default_camera, folder, width, height)
        camera = select_camera(folder, width, height, intrinsics, distortion, fallback)
        camera = replace(camera, depth_scale=(camera.depth_scale or DEPTH_SCALE) if use_depth else None)
        gt_path = folder / "groundtruth.txt"
        groundtruth = Trajectory.read_tum(gt_path) if gt_path.is_file() else None
        return Sequence(
            kind=self.name,
            name=f"tum/{folder.name}",
            camera=camera,
            sensor="rgbd" if use_depth else "mono",
            fps=fps_from_timestamps(np.array([r.timestamp for r in records]), TUM_FPS),
            records=records,
            groundtruth=groundtruth,
            grayscale=grey,
            source=folder,
        )

    def write(self, sequence: Sequence, out_dir: Path, frames: Iterable[Frame]) -> Path:
        """Write the TUM layout into ``out_dir`` and return it.

        Colour goes to ``rgb/<stem>.png``; for RGB-D, depth to ``depth/<stem>.png`` (uint16,
        5000 per metre) at the colour time, listed in ``depth.txt`` and paired in
        ``associations.txt``. Every list names exactly the written frames; ``camera.yaml`` keeps
        the intrinsics and ``groundtruth.txt`` the ground truth (when known).
        """
        out_dir = Path(out_dir)
        rgbd = sequence.sensor == "rgbd"
        camera = sequence.camera
        rgb_lines: list[str] = []
        depth_lines: list[str] = []
        used: set[str] = set()
        for position, frame in enumerate(frames):
            stem = frame_file_stem(frame.record.stem, position, used)
            t = format_float(frame.timestamp)
            image = checked_image(frame, camera, sequence.name)
            write_image(out_dir / "rgb" / f"{stem}.png", image, grey=sequence.grayscale)
            rgb_lines.append(f"{t} rgb/{stem}.png\n")
            if rgbd:
                write_depth(out_dir / "depth" / f"{stem}.png", frame.require("depth"), DEPTH_SCALE)
                depth_lines.append(f"{t} depth/{stem}.png\n")
        if not rgb_lines:
            raise DatasetError(f"{sequence.name}: no frames to write")
        atomic_write_text(out_dir / "rgb.txt", _LIST_HEADERS["rgb.txt"] + "".join(rgb_lines))
        if rgbd:
            atomic_write_text(out_dir / "depth.txt", _LIST_HEADERS["depth.txt"] + "".join(depth_lines))
            pairs = "".join(r.rstrip("\n") + " " + d for r, d in zip(rgb_lines, depth_lines))
            atomic_write_text(out_dir / "associations.txt", _LIST_HEADERS["associations.txt"] + pairs)
        write_camera_yaml(out_dir / CAMERA_FILE, camera, DEPTH_SCALE if rgbd else None)
        if sequence.groundtruth is not None:
            sequence.groundtruth.write_tum(out_dir / "groundtruth.txt")
        return out_dir


def associate(first: np.ndarray, second: np.ndarray, max_difference: float) -> np.ndarray:
    """Pair two timestamp lists (s) as TUM's ``associate.py``: every pair closer than
    ``max_difference`` is a candidate; candidates are taken by increasing ``|dt|`` (ties by the
    first time, then the second), each time used at most once.

    Returns:
        ``K x 2`` int array of ``(index in first, index in second)``, sorted by the first index.
    """
    a = np.asarray(first, dtype=np.float64)
    b = np.asarray(second, dtype=np.float64)
    order = np.argsort(b, kind="stable")
    b_sorted = b[order]
    slack = 1e-9 * max(1.0, float(np.max(np.abs(b), initial=0.0)))  # candidates decided by |a - b| below
    lo = np.searchsorted(b_sorted, a - max_difference - slack, side="left")
    hi = np.searchsorted(b_sorted, a + max_difference + slack, side="right")
    counts = hi - lo
    i = np.repeat(np.arange(len(a)), counts)
    offsets = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
    j = order[np.repeat(lo, counts) + offsets]
    diff = np.abs(a[i] - b[j])
    keep = diff < max_difference
    i, j, diff = i[keep], j[keep], diff[keep]
    ranked = np.lexsort((b[j], a[i], diff))
    used_a = np.zeros(len(a), dtype=bool)
    used_b = np.zeros(len(b), dtype=bool)
    pairs: list[tuple[int, int]] = []
    for k in ranked.tolist():  # one pass over candidate pairs (a few per frame)
        ia, jb = int(i[k]), int(j[k])
        if not used_a[ia] and not used_b[jb]:
            used_a[ia] = used_b[jb] = True
            pairs.append((ia, jb))
    pairs.sort()
    return np.array(pairs, dtype=np.int64).reshape(-1, 2)


def freiburg_camera(folder_name: str) -> int | None:
    """The Freiburg camera (1, 2 or 3) a TUM folder name mentions (``freiburg2``, ``fr2``), or None."""
    match = re.search(r"freiburg([123])|(?<![a-z0-9])fr([123])(?![0-9])", folder_name.lower())
    return None if match is None else int(match.group(1) or match.group(2))


def _sequence_folder(path: Path | None, sequence: str | None) -> Path:
    if path is None:
        raise DatasetError("the tum dataset needs a path (the sequence folder, or its parent with sequence=)")
    path = Path(path).expanduser()
    if not path.is_dir():
        raise DatasetError("TUM dataset folder not found", path)
    if sequence is not None:
        names = _sequence_names(str(sequence))
        for name in names:
            if (path / name).is_dir():
                return path / name
        if path.name in names:
            return path
        raise DatasetError(f"TUM sequence {sequence!r} not found (looked for {', '.join(n + '/' for n in names)})", path)
    if (path / "rgb.txt").is_file():
        return path
    found = sorted(p.name for p in path.iterdir() if (p / "rgb.txt").is_file())
    if len(found) == 1:
        return path / found[0]
    if found:
        raise DatasetError(f"several TUM sequences found ({', '.join(found)}); pass sequence=", path)
    raise DatasetError(
        "file not found: not a TUM RGB-D sequence folder (expected rgb.txt, depth.txt, groundtruth.txt, rgb/, depth/)",
        path / "rgb.txt",
    )


def _sequence_names(sequence: str) -> list[str]:
    """Folder names ``sequence`` may stand for: ``fr1_xyz`` -> ``rgbd_dataset_freiburg1_xyz``."""
    long = re.sub(r"^fr([123])_", r"freiburg\1_", sequence)
    names = [sequence, long]
    if not long.startswith("rgbd_dataset_"):
        names.append("rgbd_dataset_" + long)
    return list(dict.fromkeys(names))


def _default_camera(folder: Path, width: int, height: int) -> Camera:
    """The Freiburg camera named in the folder name, else the ROS default (warned): the
    camera of a sequence without ``camera.yaml`` and without an ``intrinsics=`` option."""
    camera_id = freiburg_camera(folder.name)
    if camera_id is None:
        fx, fy, cx, cy = ROS_DEFAULT_INTRINSICS
        warnings.warn(
            f"{folder}: no Freiburg camera (freiburg1/fr1 .. freiburg3/fr3) in the folder name and no "
            f"{CAMERA_FILE}; assuming the ROS default intrinsics fx={fx} fy={fy} cx={cx} cy={cy} px without "
            f"distortion. Pass intrinsics=(fx, fy, cx, cy) or add {CAMERA_FILE} to override.",
            DatasetWarning,
            stacklevel=4,  # called by select_camera, called by open: the warning names open's caller
        )
        return Camera(fx=fx, fy=fy, cx=cx, cy=cy, width=width, height=height)
    (fx, fy, cx, cy), coeffs = FREIBURG_CAMERAS[camera_id]
    return Camera(fx=fx, fy=fy, cx=cx, cy=cy, width=width, height=height, distortion=coeffs)


def _depth_pairs(folder: Path, rgb_times: np.ndarray, rgb_names: list[str], max_time_diff: float) -> list[tuple[int, str | None]]:
    """``(rgb position, depth file)`` for every colour frame with a depth map, in rgb.txt order."""
    assoc_path = folder / "associations.txt"
    if assoc_path.is_file():
        position = {_normal(name): i for i, name in enumerate(rgb_names)}
        pairs: list[tuple[int, str | None]] = []
        for number, (_, rgb_name, _, depth_name) in read_list(assoc_path, "tftf", "t_rgb rgb_file t_depth depth_file"):
            i = position.get(_normal(str(rgb_name)))
            if i is None:
                raise DatasetError(f"colour image {rgb_name} is not listed in rgb.txt", assoc_path, number)
            pairs.append((i, str(depth_name)))
        return pairs
    depth_path = folder / "depth.txt"
    if not depth_path.is_file():
        raise DatasetError("file not found (open with depth=False for colour frames only)", depth_path)
    depth_rows = read_list(depth_path, "tf", "timestamp filename", increasing=False)  # order does not matter
    depth_times = np.array([row[1][0] for row in depth_rows], dtype=np.float64)
    matches = associate(rgb_times, depth_times, max_time_diff)
    if len(matches) == 0:
        raise DatasetError(f"no colour frame of rgb.txt has a depth map within {max_time_diff} s", depth_path)
    dropped = len(rgb_times) - len(matches)
    if dropped:
        warnings.warn(
            f"{folder}: {dropped} of {len(rgb_times)} colour frames have no depth map within {max_time_diff} s in "
            "depth.txt and are left out (raise max_time_diff, or open with depth=False to keep them)",
            DatasetWarning,
            stacklevel=4,
        )
    return [(int(i), str(depth_rows[j][1][1])) for i, j in matches]


def _normal(name: str) -> str:
    return str(PurePosixPath(name))


TUM = TumDataset()
