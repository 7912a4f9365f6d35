"""``sal features CONFIG --features orb[,superpoint]``: feature-tracking diagnostics on the
clean sequence and on each perturbation of an experiment config (``pytest_sal.experiment.features``),
with detections, matches and track length per sequence printed."""

from __future__ import annotations

import argparse
from pathlib import Path

from pytest_sal.experiment.config import load_config
from pytest_sal.experiment.features import track_features

__all__ = ["add_features_commands"]

EPILOG = """\
examples:
  sal features example_suites/configs/indoor_camera.yaml --features orb
  sal features exp.yaml --features orb,superpoint --superpoint-model superpoint.onnx --max-frames 50

Writes <base_dir>/<name>/features/<FEATURE>/summary.json (detections and matches per frame,
mean track length, survival curve per sequence), track_survival.png and detections.png; each
<FEATURE> folder is replaced whole once complete.
"""


def add_features_commands(commands: argparse._SubParsersAction) -> None:
    """Add ``features`` to the ``sal`` subcommands."""
    cmd = commands.add_parser(
        "features",
        help="feature tracking (ORB, SuperPoint) on the clean and each perturbed sequence",
        description="Track features frame to frame on the clean sequence and on each enabled perturbation of\n"
        "the experiment config: detections, matches, track lengths and the track survival curve.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    cmd.add_argument("config", type=Path, metavar="CONFIG", help="experiment YAML")
    cmd.add_argument("--features", default="orb", metavar="LIST", help="comma-separated: orb, superpoint (default: %(default)s)")
    cmd.add_argument("--superpoint-model", type=Path, metavar="ONNX", help="SuperPoint ONNX model file (needed for superpoint)")
    cmd.add_argument("--max-keypoints", type=int, default=1000, metavar="N", help="keypoints per frame (default: %(default)s)")
    cmd.add_argument("--max-frames", type=int, metavar="N", help="track at most N frames of each sequence")
    cmd.set_defaults(run=_run)


def _run(args: argparse.Namespace) -> int:
    config = load_config(args.config)
    results = track_features(
        config, args.features, model=args.superpoint_model, max_keypoints=args.max_keypoints, max_frames=args.max_frames
    )
    for feature, result in results.items():
        print(f"{feature}:")
        for name, stats in result["stats"].items():
            print(
                f"  {name:20s} detections/frame {stats.detections.mean():7.1f}  matches/frame "
                f"{stats.matches.mean() if len(stats.matches) else 0.0:7.1f}  mean track {stats.mean_track_length:5.2f} frames"
            )
        print(f"  wrote {result['summary']}, {result['track_survival']}")
    return 0
