"""Clean frames of the synthetic urban street against real KITTI 07: the image statistics that
decide feature tracking under night, sensor noise, soiling and video coding (issue 25, step 1).

Prints a Markdown table, one row per statistic, the median over the frames of each sequence
(grey levels 0-255 on the left camera; colour frames converted with OpenCV's BGR->grey):

* grey level: mean, 1st and 99th percentile, their spread (dynamic range), the share of pixels
  below 16 (what a darker exposure pushes under the noise floor) and at or above 250;
* contrast: RMS contrast (std / mean), the median of 8x8-block standard deviations (local
  contrast), the share of 16x16 blocks with std < 2 (flat: sky, road without texture);
* gradients: mean and 90th percentile of the Sobel magnitude (per pixel, so resolution matters);
* spectrum: the share of the image's power (mean removed) above a quarter of the Nyquist
  frequency, radially (what JPEG and H.264 quantise away first);
* ORB (OpenCV, 2000 features, FAST threshold 20): keypoints, median response, the share of
  8x8 grid cells holding one at least (spread);
* repetitiveness: the share of ORB descriptors whose nearest other descriptor of the same frame
  is within 40 of 256 bits (a repeated texture gives look-alike corners that mismatch);
* bright and flat: the share of 16x16 blocks with std < 2 and mean >= 180 (sky);
* motion: mean absolute grey-level change between consecutive frames; the camera's median
  translation (m) and rotation (deg) per frame from the ground truth.

    .venv/bin/python benchmarks/frame_statistics.py --frames 60
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from sal_adapters import Sequence, open_dataset

KITTI = Path(__file__).resolve().parents[2] / "shared" / "data" / "kitti"


def grey(image: np.ndarray) -> np.ndarray:
    """The frame as 8-bit grey (colour frames are BGR)."""
    return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


def blocks(g: np.ndarray, size: int) -> np.ndarray:
    """The ``size`` x ``size`` blocks of ``g`` (cropped to whole blocks), as float64 of shape
    ``(rows, size, columns, size)``: reduce over axes (1, 3) for a value per block."""
    h, w = (g.shape[0] // size) * size, (g.shape[1] // size) * size
    return g[:h, :w].astype(np.float64).reshape(h // size, size, w // size, size)


def look_alike_share(g: np.ndarray, orb: cv2.ORB) -> float:
    """Share of ORB descriptors whose nearest other descriptor in the frame is within 40 bits."""
    _, descriptors = orb.detectAndCompute(g, None)
    if descriptors is None or len(descriptors) < 3:
        return 0.0
    pairs = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(descriptors, descriptors, k=2)  # the first is itself
    return float(np.mean([len(p) > 1 and p[1].distance <= 40 for p in pairs]))


def camera_motion(seq: Sequence, frames: int) -> tuple[float, float]:
    """Median translation (m) and rotation (deg) between consecutive ground-truth poses."""
    truth = seq.groundtruth
    if truth is None or len(truth) < 2:
        return float("nan"), float("nan")
    poses = truth.matrices[: frames + 1]
    steps = np.linalg.inv(poses[:-1]) @ poses[1:]
    angles = np.degrees(np.arccos(np.clip((np.trace(steps[:, :3, :3], axis1=1, axis2=2) - 1) / 2, -1, 1)))
    return float(np.median(np.linalg.norm(steps[:, :3, 3], axis=1))), float(np.median(angles))


def bright_flat_share(g: np.ndarray) -> float:
    """Share of 16x16 blocks that are flat (std < 2) and bright (mean >= 180): sky."""
    b = blocks(g, 16)
    return float(((b.std(axis=(1, 3)) < 2) & (b.mean(axis=(1, 3)) >= 180)).mean())


def high_frequency_share(g: np.ndarray) -> float:
    """Share of the power spectrum (mean removed) above a quarter of the Nyquist frequency."""
    f = np.fft.fftshift(np.abs(np.fft.fft2(g.astype(np.float64) - g.mean())) ** 2)
    fy = np.fft.fftshift(np.fft.fftfreq(g.shape[0]))[:, None]
    fx = np.fft.fftshift(np.fft.fftfreq(g.shape[1]))[None, :]
    radius = np.hypot(fx, fy)  # cycles per pixel; Nyquist is 0.5
    return float(f[radius > 0.125].sum() / f.sum())


def orb_stats(g: np.ndarray, orb: cv2.ORB) -> tuple[float, float, float]:
    """ORB keypoints, their median response and the share of 8x8 grid cells holding one."""
    points = orb.detect(g, None)
    if not points:
        return 0.0, 0.0, 0.0
    xy = np.array([p.pt for p in points])
    cells = {(int(8 * y / g.shape[0]), int(8 * x / g.shape[1])) for x, y in xy}
    return float(len(points)), float(np.median([p.response for p in points])), len(cells) / 64


STATISTICS: dict[str, Callable[[np.ndarray], float]] = {
    "grey mean": lambda g: float(g.mean()),
    "grey p1": lambda g: float(np.percentile(g, 1)),
    "grey p99": lambda g: float(np.percentile(g, 99)),
    "dynamic range p99 - p1": lambda g: float(np.percentile(g, 99) - np.percentile(g, 1)),
    "share < 16": lambda g: float((g < 16).mean()),
    "share >= 250": lambda g: float((g >= 250).mean()),
    "RMS contrast (std / mean)": lambda g: float(g.std() / max(g.mean(), 1e-9)),
    "local contrast (median 8x8 std)": lambda g: float(np.median(blocks(g, 8).std(axis=(1, 3)))),
    "flat 16x16 blocks (std < 2)": lambda g: float((blocks(g, 16).std(axis=(1, 3)) < 2).mean()),
    "power above Nyquist / 4": high_frequency_share,
    "bright flat 16x16 blocks (sky)": bright_flat_share,
}


def sequence_statistics(seq: Sequence, frames: int) -> dict[str, float]:
    """The median over the first ``frames`` frames of each statistic."""
    orb = cv2.ORB_create(nfeatures=2000, fastThreshold=20)
    names = [
        *STATISTICS,
        "Sobel magnitude mean",
        "Sobel magnitude p90",
        "ORB keypoints",
        "ORB median response",
        "ORB grid cells (8x8) hit",
        "ORB look-alikes (<= 40 bits)",
    ]
    rows: dict[str, list[float]] = {name: [] for name in [*names, "frame-to-frame change"]}
    previous = None
    for i in range(min(frames, len(seq))):
        g = grey(seq[i].image)
        for name, statistic in STATISTICS.items():
            rows[name].append(statistic(g))
        magnitude = np.hypot(cv2.Sobel(g, cv2.CV_32F, 1, 0), cv2.Sobel(g, cv2.CV_32F, 0, 1))
        rows["Sobel magnitude mean"].append(float(magnitude.mean()))
        rows["Sobel magnitude p90"].append(float(np.percentile(magnitude, 90)))
        count, response, spread = orb_stats(g, orb)
        rows["ORB keypoints"].append(count)
        rows["ORB median response"].append(response)
        rows["ORB grid cells (8x8) hit"].append(spread)
        rows["ORB look-alikes (<= 40 bits)"].append(look_alike_share(g, orb))
        if previous is not None and previous.shape == g.shape:
            rows["frame-to-frame change"].append(float(np.abs(g.astype(np.int16) - previous).mean()))
        previous = g.astype(np.int16)
    found = {name: float(np.median(values)) if values else float("nan") for name, values in rows.items()}
    found["translation per frame (m)"], found["rotation per frame (deg)"] = camera_motion(seq, frames)
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60, help="frames of each sequence (default 60, as the issue's runs)")
    args = parser.parse_args()
    synthetic = open_dataset("synthetic", scene="urban", frames=args.frames, sensor="stereo")
    kitti = open_dataset("kitti", str(KITTI), sequence="07")
    stats = {name: sequence_statistics(seq, args.frames) for name, seq in (("synthetic urban", synthetic), ("KITTI 07", kitti))}
    print(
        f"{args.frames} frames each; synthetic {synthetic[0].image.shape[1]}x{synthetic[0].image.shape[0]} at {synthetic.fps:g} Hz, "
        f"KITTI {kitti[0].image.shape[1]}x{kitti[0].image.shape[0]} at {kitti.fps:g} Hz\n"
    )
    print("| statistic | synthetic urban | KITTI 07 | KITTI / synthetic |\n|---|---:|---:|---:|")
    for name in stats["KITTI 07"]:
        a, b = stats["synthetic urban"][name], stats["KITTI 07"][name]
        ratio = f"{b / a:.2f}" if a else "-"
        print(f"| {name} | {a:.4g} | {b:.4g} | {ratio} |")


if __name__ == "__main__":
    main()
