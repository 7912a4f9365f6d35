"""Generic-test parameters of the transport modules (frame_drop, bandwidth, jpeg)."""

from __future__ import annotations

from module_cases import ModuleCase

CASES = {
    # dropped frames count as full-scale differences in the generic test, so more drops = more damage
    "frame_drop": ModuleCase(params={"drop_rate": 0.5}, ladder={"drop_rate": [0.1, 0.3, 0.6]}, frames=12),
    "bandwidth": ModuleCase(params={"target_mbps": 0.5}, ladder={"target_mbps": [4.0, 1.0, 0.25]}, random=False, frames=8),
    "jpeg": ModuleCase(params={"quality": 10}, ladder={"quality": [90, 50, 10]}, random=False),
}
