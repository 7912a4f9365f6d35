"""The real EuRoC V1_01_easy excerpt the EuRoC adapter tests share (test_euroc_read.py,
test_euroc_write.py, test_euroc_errors.py) and helpers to open and compare it."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from sal_adapters import (
    Camera,
    DatasetWarning,
    FrameRecord,
    Sequence,
    Trajectory,
    open_dataset,
)

__all__ = ["SEQ", "_T_BS", "_csv_ns", "_euroc_copy", "_memory_sequence", "_open_stereo", "euroc_dir"]


SEQ = "V1_01_easy_micro"


@pytest.fixture(scope="module")
def euroc_dir(shared_data: Path) -> Path:
    path = shared_data / "euroc" / SEQ
    if not (path / "mav0").is_dir():
        pytest.skip(f"EuRoC excerpt not found at {path}")
    return path


def _T_BS(path: Path) -> np.ndarray:
    """T_BS of a sensor.yaml, parsed independently of the adapter."""
    text = path.read_text().replace("%YAML:1.0", "", 1)
    return np.array(yaml.safe_load(text)["T_BS"]["data"], dtype=float).reshape(4, 4)


def _csv_ns(path: Path) -> list[int]:
    return [int(line.split(",")[0]) for line in path.read_text().splitlines() if line and not line.startswith("#")]


def _open_stereo(path: Path, **options) -> Sequence:
    with pytest.warns(DatasetWarning, match=r"cam1/data\.csv: 4 of 99 rows skipped: 4 name image files that do not exist"):
        return open_dataset("euroc", path, stereo=True, **options)


def _euroc_copy(src: Path, dst: Path, cams: tuple[str, ...] = ("cam0", "cam1")) -> Path:
    """A EuRoC folder whose camera folders link to the real excerpt (no image copies)."""
    (dst / "mav0").mkdir(parents=True)
    for cam in cams:
        (dst / "mav0" / cam).mkdir()
        for name in ("data.csv", "sensor.yaml"):
            shutil.copy(src / "mav0" / cam / name, dst / "mav0" / cam / name)
        os.symlink(src / "mav0" / cam / "data", dst / "mav0" / cam / "data")
    return dst


def _memory_sequence(*, stereo: bool, colour: bool, n: int = 5) -> Sequence:
    """A non-EuRoC sequence built from in-memory arrays, with per-frame ground truth."""
    rng = np.random.default_rng(3)
    h, w = 24, 32
    shape = (h, w, 3)

    def image(seed: int):
        def make() -> np.ndarray:
            pixels = np.random.default_rng(seed).integers(0, 256, size=shape, dtype=np.uint8)
            return pixels if colour else np.repeat(pixels[..., :1], 3, axis=2)

        return make

    times = 0.1 + np.arange(n) / 30.0 + rng.uniform(0, 1e-4, n)
    records = [
        FrameRecord(index=i, timestamp=float(t), stem=f"{i:06d}", image=image(i), right=image(100 + i) if stereo else None)
        for i, t in enumerate(times)
    ]
    camera = Camera(fx=30.5, fy=31.25, cx=15.5, cy=11.75, width=w, height=h, distortion=(0.1, -0.01, 1e-5, 0.0))
    if stereo:
        T = np.eye(4)
        T[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
        T[:3, 3] = (0.12, 0.003, -0.001)
        camera = camera.with_stereo(T, right=Camera(fx=29.0, fy=29.5, cx=16.0, cy=12.0, width=w, height=h))
    positions = rng.normal(size=(n, 3))
    quats = rng.normal(size=(n, 4))
    return Sequence(
        kind="synthetic",
        name="synthetic/memory test",
        camera=camera,
        sensor="stereo" if stereo else "mono",
        fps=30.0,
        records=records,
        groundtruth=Trajectory(times, positions, quats),
        grayscale=not colour,
        content_key="memory",
    )
