"""Datasets for pytest-sal: the sequence model, real dataset layouts and the synthetic world.

>>> from sal_adapters import open_dataset
>>> seq = open_dataset("synthetic", scene="indoor", frames=10)   # doctest: +SKIP
>>> seq[0].image.shape                                             # doctest: +SKIP
(480, 640, 3)

Each name loads its module on first use (``sal_adapters.common.lazy``): importing the package pulls
neither numpy nor scipy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sal_adapters.common.lazy import lazy_exports

if TYPE_CHECKING:  # what type checkers see; at run time each name loads on first use
    from sal_adapters.camera import Camera
    from sal_adapters.common.errors import DatasetError, DatasetWarning, SalError
    from sal_adapters.datasets import DATASETS, DatasetKind, open_dataset, truncate, write_sequence
    from sal_adapters.sequence import SENSORS, Frame, FrameRecord, Sensor, Sequence
    from sal_adapters.trajectory import Trajectory

__all__ = [
    "DATASETS",
    "SENSORS",
    "Camera",
    "DatasetError",
    "DatasetKind",
    "DatasetWarning",
    "Frame",
    "FrameRecord",
    "SalError",
    "Sensor",
    "Sequence",
    "Trajectory",
    "open_dataset",
    "truncate",
    "write_sequence",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "sal_adapters.camera": ["Camera"],
        "sal_adapters.datasets": ["DATASETS", "DatasetKind", "open_dataset", "truncate", "write_sequence"],
        "sal_adapters.common.errors": ["DatasetError", "DatasetWarning", "SalError"],
        "sal_adapters.sequence": ["SENSORS", "Frame", "FrameRecord", "Sensor", "Sequence"],
        "sal_adapters.trajectory": ["Trajectory"],
    },
)
