"""Write a dataset excerpt as ROS bags: ROS 1 ``.bag``, ROS 2 ``sqlite3`` and MCAP folders, and a
bare ``.mcap`` file (issue 26).

The topics are those ``sal_adapters.rosbag.messages`` gives a sequence that did not come from
a bag (``/cam0/image_raw``, ``/cam0/camera_info``, ``/cam1/...`` and ``/tf_static`` for stereo,
the ground truth on ``/tf`` from ``world`` to ``cam0``), plus ``/imu0`` (``sensor_msgs/Imu``)
from ``mav0/imu0/data.csv`` when the folder is EuRoC's.

Stamps are the dataset's own: EuRoC's integer nanoseconds exactly, KITTI's seconds rounded to
the nanosecond. Nothing else is invented (no odometry, no covariances).

    .venv/bin/python tools/make_rosbags.py kitti ../shared/data/kitti -o /tmp/bags -O sequence=07 -O max_frames=60
    .venv/bin/python tools/make_rosbags.py euroc ../shared/data/euroc/V1_01_easy_micro -o /tmp/bags -O stereo=true
"""

from __future__ import annotations

import argparse
import csv
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from pytest_sal.cli.arg_types import parse_key_values
from sal_adapters import Sequence, open_dataset
from sal_adapters.rosbag.messages import header, typestore
from sal_adapters.rosbag.writer import write_bag

FORMATS = {"ros1": ".bag", "sqlite3": "_sqlite3", "mcap": "_mcap", "mcap_file": ".mcap"}


def imu_rows(folder: Path) -> Iterator[tuple[int, list[float]]]:
    """EuRoC's ``mav0/imu0/data.csv``: (ns, [wx, wy, wz, ax, ay, az]) per line, if present."""
    path = folder / "mav0" / "imu0" / "data.csv"
    if not path.is_file():
        return
    with path.open() as handle:
        for row in csv.reader(line for line in handle if not line.startswith("#")):
            yield int(row[0]), [float(v) for v in row[1:7]]


def imu_messages(types: Any, folder: Path, first: int, last: int, ros1: bool) -> Iterator[tuple[int, str, Any]]:
    """(ns, ``/imu0``, ``sensor_msgs/Imu``) of EuRoC's IMU samples from ``first`` to ``last`` ns."""
    vector, quaternion = types["geometry_msgs/msg/Vector3"], types["geometry_msgs/msg/Quaternion"]
    unknown = np.zeros(9)
    unknown[0] = -1.0  # orientation not estimated (REP 145)
    for ns, (wx, wy, wz, ax, ay, az) in imu_rows(folder):
        if first <= ns <= last:
            yield (
                ns,
                "/imu0",
                types["sensor_msgs/msg/Imu"](
                    header=header(types, ns, "imu0", ros1),
                    orientation=quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
                    orientation_covariance=unknown,
                    angular_velocity=vector(x=wx, y=wy, z=wz),
                    angular_velocity_covariance=np.zeros(9),
                    linear_acceleration=vector(x=ax, y=ay, z=az),
                    linear_acceleration_covariance=np.zeros(9),
                ),
            )


def write(seq: Sequence, folder: Path | None, out: Path, fmt: str) -> Path:
    """Write ``seq`` (and EuRoC's IMU from ``folder``) as a bag of format ``fmt`` at ``out``."""
    ros1 = fmt == "ros1"
    imu = () if folder is None else imu_messages(typestore(ros1).types, folder, seq.records[0].time_ns, seq.records[-1].time_ns, ros1)
    write_bag(seq, out, fmt, iter(seq), extra=imu)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("kind", help="dataset kind: kitti, euroc, tum, folder, synthetic")
    parser.add_argument("path", type=Path, help="the dataset folder")
    parser.add_argument("-o", "--out", type=Path, required=True, help="folder to write the bags into")
    parser.add_argument("-O", "--option", action="append", default=[], help="dataset option KEY=VALUE, JSON values (repeatable)")
    parser.add_argument("--formats", default="ros1,sqlite3,mcap,mcap_file", help="comma-separated: ros1, sqlite3, mcap (folder), mcap_file")
    args = parser.parse_args()
    seq = open_dataset(args.kind, args.path, **parse_key_values(args.option, "--option"))
    args.out.mkdir(parents=True, exist_ok=True)
    for fmt in args.formats.split(","):
        print(write(seq, args.path if args.kind == "euroc" else None, args.out / f"{args.path.name}{FORMATS[fmt]}", fmt))


if __name__ == "__main__":
    main()
