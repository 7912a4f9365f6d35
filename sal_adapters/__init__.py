"""Datasets for pytest-sal: the sequence model, real dataset layouts and the synthetic world.

>>> from sal_adapters import open_dataset
>>> seq = open_dataset("synthetic", scene="indoor", frames=10)   # doctest: +SKIP
>>> seq[0].image.shape                                             # doctest: +SKIP
(480, 640, 3)
"""

from sal_adapters.camera import Camera
from sal_adapters.datasets import (
    DATASETS,
    DatasetKind,
    open_dataset,
    truncate,
    write_sequence,
)
from sal_adapters.errors import DatasetError, DatasetWarning, SalError
from sal_adapters.sequence import SENSORS, Frame, FrameRecord, Sensor, Sequence
from sal_adapters.trajectory import Trajectory

__all__ = [
    "Camera",
    "DATASETS",
    "DatasetError",
    "DatasetKind",
    "DatasetWarning",
    "Frame",
    "FrameRecord",
    "SENSORS",
    "SalError",
    "Sensor",
    "Sequence",
    "Trajectory",
    "open_dataset",
    "truncate",
    "write_sequence",
]
