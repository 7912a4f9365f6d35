"""Reading what teams record (issue 26): a large bag and a long video, against the peers a user
would otherwise write by hand, on the same frames.

The KITTI 07 excerpt (140 grey 1226x370 frames) is repeated to ``--frames`` frames (default
2100, 0.95 GB of mono8 pixels) and written as a bare MCAP file (``write_sequence``) and as an
MP4 (lossless libx264). Each reader runs in a fresh process, which reports its peak resident
memory (``ru_maxrss``) and its time:

* ``rosbag kind``: ``open_dataset("rosbag", ...)`` then every frame's ``image`` in order;
* ``rosbags loop`` (peer): ``AnyReader.messages()`` over the image topic, ``deserialize`` and
  ``rosbags.image.message_to_cvimage(msg, "rgb8")`` per message (a hand-written export);
* ``video kind``: ``open_dataset("video", ...)`` then every frame in order;
* ``PyAV loop`` (peer): ``container.decode(video=0)`` and ``frame.to_ndarray(format="rgb24")``;
* ``folder``: the KITTI excerpt itself (``open_dataset("kitti", ...)``, 140 PNG frames) for scale;
* ``imports only``: the interpreter with the libraries loaded, the floor of peak memory.

    .venv/bin/python benchmarks/bench_recordings.py [--frames 2100] [--data ../shared/data]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from sal_adapters import open_dataset, write_sequence

#: A dataset kind's reader: open, then decode every frame in order.
KIND_READER = """
seq = open_dataset("{kind}", PATH{options})
opened = time.perf_counter()
for frame in seq:
    frame.image
"""

READERS = {
    "imports only": """
opened = time.perf_counter()
""",
    "rosbag kind": KIND_READER.format(kind="rosbag", options=""),
    "rosbags loop": """
from rosbags.highlevel import AnyReader
from rosbags.image import message_to_cvimage
with AnyReader([Path(PATH)]) as reader:
    opened = time.perf_counter()
    for connection, _, raw in reader.messages([c for c in reader.connections if c.topic == "/cam0/image_raw"]):
        message_to_cvimage(reader.deserialize(raw, connection.msgtype), "rgb8")
""",
    "video kind": KIND_READER.format(kind="video", options=""),
    "PyAV loop": """
import av
with av.open(PATH) as container:
    opened = time.perf_counter()
    for frame in container.decode(video=0):
        frame.to_ndarray(format="rgb24")
""",
    "folder": KIND_READER.format(kind="kitti", options=', sequence="07"'),
}

CHILD = """
import json, resource, sys, time
from pathlib import Path
from sal_adapters import open_dataset
PATH = sys.argv[1]
start = time.perf_counter()
{body}
done = time.perf_counter()
print(json.dumps({{"open_s": opened - start, "read_s": done - opened, "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}}))
"""


def measure(reader: str, path: Path) -> dict[str, float]:
    """One reader in a fresh interpreter: open time, read time and peak memory."""
    code = CHILD.format(body=READERS[reader])
    out = subprocess.run([sys.executable, "-c", code, str(path)], check=True, capture_output=True, text=True).stdout
    return json.loads(out.splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=2100, help="frames of the long recording (a multiple of 140)")
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared" / "data")
    args = parser.parse_args()
    kitti = open_dataset("kitti", args.data / "kitti", sequence="07")
    repeats = max(1, args.frames // len(kitti))
    period = 1.0 / kitti.fps
    records = [
        type(r)(index=k * len(kitti) + i, timestamp=(k * len(kitti) + i) * period, stem=f"{k * len(kitti) + i:06d}", image=r.image)
        for k in range(repeats)
        for i, r in enumerate(kitti.records)
    ]
    long = kitti.replace(records=records, groundtruth=None)
    with tempfile.TemporaryDirectory() as folder:
        started = time.perf_counter()
        bag = write_sequence(long, Path(folder) / "long.mcap")
        video = write_sequence(long, Path(folder) / "long.mp4")
        print(
            f"{len(long)} frames of {kitti.camera.width}x{kitti.camera.height} px: MCAP {bag.stat().st_size / 2**20:.0f} MiB, "
            f"MP4 {video.stat().st_size / 2**20:.0f} MiB, written in {time.perf_counter() - started:.0f} s"
        )
        print("| reader | frames | open (s) | read (frames/s) | peak memory (MB) |\n|---|---:|---:|---:|---:|")
        for reader, path, frames in (
            ("imports only", bag, len(long)),
            ("rosbag kind", bag, len(long)),
            ("rosbags loop", bag, len(long)),
            ("video kind", video, len(long)),
            ("PyAV loop", video, len(long)),
            ("folder", args.data / "kitti", len(kitti)),
        ):
            m = measure(reader, path)
            rate = "-" if reader == "imports only" else f"{frames / m['read_s']:.0f}"
            print(f"| {reader} | {frames} | {m['open_s']:.2f} | {rate} | {m['peak_mb']:.0f} |", flush=True)


if __name__ == "__main__":
    main()
