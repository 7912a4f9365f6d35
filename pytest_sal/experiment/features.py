"""The features workflow (``sal features``): frame-to-frame feature tracking (ORB, SuperPoint) on
the clean sequence and on each enabled perturbation of an experiment config, written under
``<output_dir>/features/<FEATURE>/`` (``summary.json``, ``track_survival.png``,
``detections.png``); each feature type's folder is replaced whole once complete."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pytest_sal.experiment.config import build_sequence, perturbed_sequences
from pytest_sal.experiment.schema import ExperimentConfig
from sal_adapters.common.atomic import Replacement

__all__ = ["track_features"]


def track_features(
    config: ExperimentConfig,
    features: str,
    *,
    model: Path | None = None,
    max_keypoints: int = 1000,
    max_frames: int | None = None,
    progress: bool = True,
) -> dict[str, dict[str, Any]]:
    """Build the extractors of ``features`` (comma-separated: ``orb``, ``superpoint``; a missing
    SuperPoint ``model`` is an error before any work, ``max_keypoints`` per frame), then track
    every feature type through the clean and every perturbed sequence (at most ``max_frames``
    frames each; ``progress``: a bar per sequence). Returns, per feature type, its ``stats``
    (``TrackingStats`` by sequence name) and the paths of its ``summary``, ``track_survival``
    and ``detections`` files."""
    from pytest_sal.analysis.feature_tracking import compare_features, parse_features

    extractors = parse_features(features, model=model, max_keypoints=max_keypoints)
    sequences = perturbed_sequences(config, build_sequence(config))
    out_dir = config.output_dir() / "features"
    with Replacement() as outputs:  # each feature type's folder is replaced whole, the others stay
        staging = outputs.entries(out_dir)
        results = compare_features(sequences, extractors, staging, max_frames=max_frames, progress=progress)
        for result in results.values():
            result.update({key: outputs.final(result[key]) for key in ("summary", "track_survival", "detections")})
    return results
