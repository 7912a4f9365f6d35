"""What night.illuminance_lux >= 5 runs at: the edge module's value and the frame mean of real
KITTI 07 frames at several illuminances (the old log10-lx edge, 10^5 lx, left them unchanged).
Usage: python night_frame_mean.py"""

import os
from pathlib import Path

import numpy as np

from pytest_sal import ate_rmse
from pytest_sal.engine.requirements import Requirement
from sal_adapters import open_dataset
from sal_modules import night, perturb

DATA = Path(os.environ.get("SAL_TEST_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
seq = open_dataset("kitti", str(DATA / "kitti"), sequence="07", max_frames=60)
requirement = Requirement.build([ate_rmse < 1.0, night.illuminance_lux >= 5])
edge = requirement.envelope.ref.module(requirement.envelope.value)
print(f"{requirement} | the edge trial's module: night(illuminance_lux={edge.illuminance_lux:g}) lx")
for lux in (100_000, 1250, 100, 20, 5, 1):
    dark = perturb(seq, night(illuminance_lux=lux), seed=0)
    frames = (0, 30, 59)
    mean = np.mean([dark[i].image.mean() for i in frames])
    clean = np.mean([seq[i].image.mean() for i in frames])
    change = np.mean([np.abs(dark[i].image.astype(int) - seq[i].image.astype(int)).mean() for i in frames])
    print(f"{lux:>7} lx: frame mean {mean:6.1f} (clean {clean:6.1f}), mean |change| {change:5.1f} grey levels")
