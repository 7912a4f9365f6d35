"""Feature-tracking diagnostics: detections, frame-to-frame matches and track lengths.

A *track* is a feature followed through consecutive frames: a keypoint of frame i matched to a
keypoint of frame i+1 continues its track there; an unmatched keypoint starts a new one. Unlike
the original SAL (which counted keyframe observations of triangulated map points inside a SLAM
fork), this is a plain 2-D tracking measure that needs no SLAM system and sees every frame.

>>> stats = track_features(sequence, OrbExtractor())
>>> stats.mean_track_length, stats.survival[:5]
>>> compare_features({"clean": seq, "fog": foggy}, [OrbExtractor()], Path("out/features"))
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import cv2
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from tqdm import tqdm

from pytest_sal.analysis.plots import save_png
from pytest_sal.analysis.superpoint import SuperPointExtractor
from sal_adapters.common.errors import SalError
from sal_adapters.common.textfiles import atomic_write_text
from sal_adapters.sequence import Frame, Sequence

__all__ = [
    "FEATURES",
    "FeatureExtractor",
    "OrbExtractor",
    "SuperPointExtractor",
    "TrackingStats",
    "compare_features",
    "create_extractor",
    "parse_features",
    "track_features",
]

#: feature types ``create_extractor`` knows
FEATURES = ("orb", "superpoint")
#: line styles cycled through the sequences of a plot, so that coinciding curves stay visible
LINESTYLES = ("-", "--", ":", "-.")


@runtime_checkable
class FeatureExtractor(Protocol):
    """What ``track_features`` needs: a ``name`` (used as the output folder), ``detect`` and ``match``."""

    name: str

    def detect(self, grey: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Keypoints (``N x 2`` float32 pixels, x then y) and descriptors (``N x D``) of a grey image."""
        ...

    def match(self, d1: np.ndarray, d2: np.ndarray) -> np.ndarray:
        """``M x 2`` index pairs ``(i in d1, j in d2)``, each index used at most once."""
        ...


class OrbExtractor:
    """ORB (OpenCV) keypoints; matched by brute-force Hamming distance with cross-check,
    rejecting pairs farther apart than ``max_distance`` bits (of 256). Deterministic."""

    name = "orb"

    def __init__(self, features: int = 1000, max_distance: int = 64):
        if features < 1:
            raise SalError(f"ORB needs at least 1 feature per frame, got {features}")
        self.features = int(features)
        self.max_distance = int(max_distance)
        self._orb = cv2.ORB.create(nfeatures=self.features)
        self._matcher = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True)

    def __repr__(self) -> str:
        return f"OrbExtractor(features={self.features}, max_distance={self.max_distance})"

    def detect(self, grey: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        image = _grey(grey)
        if image.dtype != np.uint8:
            image = np.clip(np.rint(image.astype(np.float32) * 255.0), 0, 255).astype(np.uint8)
        keypoints, descriptors = self._orb.detectAndCompute(image, None)
        points = np.array([k.pt for k in keypoints], dtype=np.float32).reshape(-1, 2)
        if descriptors is None:
            descriptors = np.zeros((0, 32), dtype=np.uint8)
        return points, descriptors

    def match(self, d1: np.ndarray, d2: np.ndarray) -> np.ndarray:
        if not len(d1) or not len(d2):
            return np.zeros((0, 2), dtype=np.int64)
        pairs = [(m.queryIdx, m.trainIdx) for m in self._matcher.match(d1, d2) if m.distance <= self.max_distance]
        return np.array(pairs, dtype=np.int64).reshape(-1, 2)


def create_extractor(name: str, *, model: str | Path | None = None, max_keypoints: int = 1000) -> FeatureExtractor:
    """The extractor called ``name`` (``orb`` or ``superpoint``; ``superpoint`` needs ``model``,
    the ONNX file). ``max_keypoints`` caps the keypoints per frame of either."""
    key = name.strip().lower()
    if key == "orb":
        return OrbExtractor(features=max_keypoints)
    if key == "superpoint":
        if model is None:
            raise SalError("feature type 'superpoint' needs a SuperPoint ONNX model file (none was given)")
        return SuperPointExtractor(model, max_keypoints=max_keypoints)
    raise SalError(f"unknown feature type {name!r}; choose from {', '.join(FEATURES)}")


def parse_features(spec: str, *, model: str | Path | None = None, max_keypoints: int = 1000) -> list[FeatureExtractor]:
    """Extractors for a comma-separated list such as ``"orb,superpoint"`` (duplicates dropped)."""
    names = list(dict.fromkeys(n.strip().lower() for n in spec.split(",") if n.strip()))
    if not names:
        raise SalError(f"no feature type given in {spec!r}; choose from {', '.join(FEATURES)}")
    return [create_extractor(n, model=model, max_keypoints=max_keypoints) for n in names]


@dataclass(frozen=True)
class TrackingStats:
    """Frame-to-frame tracking of one feature type through one sequence.

    Attributes:
        feature: the extractor's name.
        detections: keypoints per frame (``n`` ints).
        matches: matches between frame i and i+1 (``n - 1`` ints).
        track_lengths: frames each track lasted (a track still alive in the last frame counts
            the frames seen so far), one entry per track, in order of birth.
    """

    feature: str
    detections: np.ndarray
    matches: np.ndarray
    track_lengths: np.ndarray

    @property
    def frames(self) -> int:
        return len(self.detections)

    @property
    def mean_track_length(self) -> float:
        return float(self.track_lengths.mean()) if len(self.track_lengths) else 0.0

    @property
    def median_track_length(self) -> float:
        return float(np.median(self.track_lengths)) if len(self.track_lengths) else 0.0

    @property
    def match_ratio(self) -> np.ndarray:
        """Matches between frame i and i+1 as a share of the detections in frame i."""
        return self.matches / np.maximum(self.detections[:-1], 1)

    @property
    def survival(self) -> np.ndarray:
        """``S(t)``, t = 1..longest track: the share of tracks lasting at least t frames
        (1 at t = 1, non-increasing; empty without tracks)."""
        if not len(self.track_lengths):
            return np.zeros(0)
        counts = np.bincount(self.track_lengths)  # counts[k] = tracks of length k
        at_least = np.cumsum(counts[::-1])[::-1]  # at_least[k] = tracks of length >= k
        return at_least[1:] / len(self.track_lengths)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary: per-frame statistics, the track statistics and the curves."""
        lengths = self.track_lengths
        return {
            "feature": self.feature,
            "frames": self.frames,
            "detections_per_frame": _summary(self.detections),
            "matches_per_frame": _summary(self.matches),
            "match_ratio": _summary(self.match_ratio),
            "tracks": len(lengths),
            "mean_track_length": round(self.mean_track_length, 6),
            "median_track_length": self.median_track_length,
            "max_track_length": int(lengths.max()) if len(lengths) else 0,
            "tracks_spanning_sequence": int(np.sum(lengths == self.frames)) if self.frames else 0,
            "survival": [round(float(s), 6) for s in self.survival],
        }


def track_features(sequence: Iterable[Frame | np.ndarray], extractor: FeatureExtractor, max_frames: int | None = None) -> TrackingStats:
    """Detect in every frame of ``sequence`` (its left images, or any iterable of images) and
    match each frame to the next; the first ``max_frames`` frames only when given."""
    detections: list[int] = []
    matches: list[int] = []
    lengths = np.zeros(1024, dtype=np.int64)  # frames each track lasted, grown by doubling
    tracks = 0
    previous: tuple[np.ndarray, np.ndarray] | None = None  # (descriptors, track id per keypoint)
    for position, item in enumerate(sequence):
        if max_frames is not None and position >= max_frames:
            break
        image = item.image if isinstance(item, Frame) else item
        keypoints, descriptors = extractor.detect(_grey(image))
        ids = np.full(len(keypoints), -1, dtype=np.int64)
        if previous is not None:
            pairs = np.asarray(extractor.match(previous[0], descriptors), dtype=np.int64).reshape(-1, 2)
            matches.append(len(pairs))
            ids[pairs[:, 1]] = previous[1][pairs[:, 0]]
            lengths[ids[pairs[:, 1]]] += 1  # matches are one-to-one: each track id at most once
        new = ids < 0
        started = int(new.sum())
        while tracks + started > len(lengths):
            lengths = np.concatenate([lengths, np.zeros_like(lengths)])
        ids[new] = np.arange(tracks, tracks + started)
        lengths[tracks : tracks + started] = 1
        tracks += started
        detections.append(len(keypoints))
        previous = (descriptors, ids)
    if not detections:
        raise SalError("feature tracking needs at least one frame; the sequence is empty")
    return TrackingStats(extractor.name, np.array(detections, dtype=np.int64), np.array(matches, dtype=np.int64), lengths[:tracks].copy())


def compare_features(
    sequences: dict[str, Sequence],
    extractors: list[FeatureExtractor],
    out_dir: str | Path,
    max_frames: int | None = None,
    *,
    progress: bool = False,
) -> dict[str, dict[str, Any]]:
    """Track every feature type through every sequence (``progress``: a bar per sequence) and
    write, per feature type, ``out_dir/<feature>/summary.json`` (per sequence:
    ``TrackingStats.to_dict()``), ``track_survival.png`` and ``detections.png``.

    Returns ``{feature: {"stats": {sequence name: TrackingStats}, "summary": path,
    "track_survival": path, "detections": path}}``.
    """
    if not sequences:
        raise SalError("no sequence to compare features on")
    names = [e.name for e in extractors]
    if not names:
        raise SalError(f"no feature type given; choose from {', '.join(FEATURES)}")
    if len(set(names)) != len(names):
        raise SalError(f"each feature type may appear once, got {', '.join(names)}")
    out_dir = Path(out_dir)
    results: dict[str, dict[str, Any]] = {}
    for extractor in extractors:
        stats = {}
        for name, seq in sequences.items():
            total = len(seq) if max_frames is None else min(len(seq), max_frames)
            frames = tqdm(seq, total=total, desc=f"{extractor.name} {name}", unit="frame", disable=not progress, leave=False)
            stats[name] = track_features(frames, extractor, max_frames)
        folder = out_dir / extractor.name
        summary = {"feature": extractor.name, "extractor": repr(extractor), "sequences": {n: s.to_dict() for n, s in stats.items()}}
        summary_path = atomic_write_text(folder / "summary.json", json.dumps(summary, indent=2, allow_nan=False) + "\n")
        results[extractor.name] = {
            "stats": stats,
            "summary": summary_path,
            "track_survival": save_png(survival_figure(stats, title=f"Track survival ({extractor.name})"), folder / "track_survival.png"),
            "detections": save_png(
                detections_figure(stats, title=f"Detections and matches per frame ({extractor.name})"), folder / "detections.png"
            ),
        }
    return results


def survival_figure(stats: dict[str, TrackingStats], *, title: str = "Track survival") -> Figure:
    """``S(t)`` (percent of tracks lasting at least t frames) per sequence, as steps; log x
    once the longest track exceeds 30 frames."""
    fig = Figure(figsize=(8.0, 5.5), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    longest = 1
    for k, (name, s) in enumerate(stats.items()):
        curve = s.survival
        if not len(curve):
            ax.plot([], [], label=f"{name}: no tracks")
            continue
        t = np.arange(1, len(curve) + 2)
        ax.step(
            t,
            np.append(curve, 0.0) * 100.0,
            where="post",
            linewidth=1.6,
            linestyle=LINESTYLES[k % len(LINESTYLES)],
            label=f"{name}: {len(s.track_lengths)} tracks, mean {s.mean_track_length:.2f} frames",
        )
        longest = max(longest, len(curve) + 1)
    if longest > 30:
        ax.set_xscale("log")
    else:
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlim(1, longest)
    ax.set_ylim(0, 102)
    ax.set_xlabel("track length t [frames]")
    ax.set_ylabel("tracks lasting at least t frames [%]")
    ax.set_title(title)
    ax.grid(True, color="0.88", linewidth=0.8)
    ax.legend(loc="upper right", fontsize="small", framealpha=0.9)
    return fig


def detections_figure(stats: dict[str, TrackingStats], *, title: str = "Detections and matches per frame") -> Figure:
    """Two panels against the frame number: keypoints detected, and matches to the previous frame."""
    fig = Figure(figsize=(8.0, 6.5), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    top, bottom = fig.subplots(2, 1, sharex=True)
    for k, (name, s) in enumerate(stats.items()):
        style = {"linewidth": 1.5, "linestyle": LINESTYLES[k % len(LINESTYLES)], "marker": "o" if s.frames <= 40 else None, "markersize": 3}
        (line,) = top.plot(np.arange(s.frames), s.detections, label=name, **style)
        bottom.plot(np.arange(1, s.frames), s.matches, color=line.get_color(), label=name, **style)
    top.set_ylabel("keypoints detected")
    bottom.set_ylabel("matches to previous frame")
    bottom.set_xlabel("frame")
    bottom.xaxis.set_major_locator(MaxNLocator(integer=True))
    for ax in (top, bottom):
        ax.set_ylim(bottom=0)
        ax.grid(True, color="0.88", linewidth=0.8)
    top.legend(loc="best", fontsize="small", framealpha=0.9)
    fig.suptitle(title)
    return fig


def _grey(image: np.ndarray) -> np.ndarray:
    """A single-channel image: RGB is converted; float images in [0, 1] are kept as float."""
    image = np.asarray(image)
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    if image.ndim == 3 and image.shape[2] == 1:
        return image[:, :, 0]
    return image


def _summary(values: np.ndarray) -> dict[str, Any]:
    values = np.asarray(values, dtype=np.float64)
    if not len(values):
        return {"mean": None, "median": None, "min": None, "max": None, "values": []}
    as_int = bool(np.all(values == np.round(values)))
    listed = [int(v) for v in values] if as_int else [round(float(v), 6) for v in values]
    return {
        "mean": round(float(values.mean()), 6),
        "median": float(np.median(values)),
        "min": listed[int(values.argmin())],
        "max": listed[int(values.argmax())],
        "values": listed,
    }
