"""The ``rosbag`` dataset kind: ROS 1 bags, ROS 2 sqlite3 and MCAP bags read and written back
with the pure-Python ``rosbags`` library (extra ``ros``)."""

from __future__ import annotations

from sal_adapters.rosbag.kind import ROSBAG, RosbagDataset

__all__ = ["ROSBAG", "RosbagDataset"]
