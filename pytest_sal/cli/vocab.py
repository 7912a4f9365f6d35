"""``sal vocab build``: train an ORB vocabulary (DBoW2 text format) for ORB-SLAM3."""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

from pytest_sal.cli.arg_types import positive_int
from sal_adapters.common.errors import SalError
from sal_adapters.datasets import DATASETS, open_dataset

__all__ = ["add_vocab_commands", "parse_source"]

BUILD_EPILOG = """\
examples:
  sal vocab build -o orbvoc.txt                        both synthetic scenes, 40 views each
  sal vocab build --from kitti:~/kitti/sequences/07 --from euroc:~/euroc/V1_01_easy -o mixed.txt
  sal vocab build --from synthetic --frames 80 --seed 3 -o orbvoc-s3.txt

KIND is a dataset kind (%(kinds)s); PATH its folder (not needed for synthetic).
Each source gives --frames images spread evenly over its sequence. Use the file with
SAL_ORB_VOCABULARY=FILE, or put the official ORBvoc.txt into $SAL_CACHE_DIR/vocabulary/.
"""


def add_vocab_commands(commands: argparse._SubParsersAction) -> None:
    """Add ``vocab build`` to the ``sal`` subcommands."""
    vocab = commands.add_parser("vocab", help="build ORB vocabularies for ORB-SLAM3", description="ORB vocabulary tools.")
    actions = vocab.add_subparsers(dest="vocab_command", metavar="ACTION", required=True)
    build = actions.add_parser(
        "build",
        help="train a k-majority ORB vocabulary tree and write it in the ORB-SLAM3 text format",
        description="Extract ORB descriptors (1000 per image) from dataset images, train a DBoW2 "
        "vocabulary tree with TF-IDF weights and write it as an ORB-SLAM3 text vocabulary.",
        epilog=BUILD_EPILOG % {"kinds": ", ".join(DATASETS.names())},
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    build.add_argument(
        "--from",
        dest="sources",
        action="append",
        metavar="KIND[:PATH]",
        help="training images from a dataset (repeatable; default: synthetic)",
    )
    build.add_argument(
        "--frames", type=positive_int, default=40, metavar="N", help="images per source, or per synthetic scene (default: %(default)s)"
    )
    build.add_argument(
        "--seed", type=int, default=0, help="k-means++ seed; synthetic views come from world SEED+100 (default: %(default)s)"
    )
    build.add_argument("--k", type=int, default=10, help="branching factor, 2..20 (default: %(default)s)")
    build.add_argument("--levels", type=int, default=6, metavar="L", help="tree depth, 1..10; ORB-SLAM3 needs >= 5 (default: %(default)s)")
    build.add_argument("-o", "--out", type=Path, required=True, metavar="FILE", help="vocabulary file to write")
    build.set_defaults(run=_run_build)


def parse_source(text: str) -> tuple[str, Path | None]:
    """``"kitti:/data/kitti"`` -> ``("kitti", Path("/data/kitti"))``; ``"synthetic"`` -> no path."""
    kind, sep, path = text.partition(":")
    if kind not in DATASETS.names():
        raise SalError(f"--from {text!r}: unknown dataset kind {kind!r}; known: {', '.join(DATASETS.names())}")
    if sep and not path:
        raise SalError(f"--from {text!r}: missing PATH after ':'")
    if not path and kind != "synthetic":
        raise SalError(f"--from {text!r}: dataset kind {kind!r} needs a folder, as {kind}:PATH")
    return kind, Path(path).expanduser() if path else None


def _run_build(args: argparse.Namespace) -> int:
    import numpy as np

    from sal_wrappers.orbslam3.vocabulary import orb_image_descriptors, sequence_images, synthetic_training_images
    from sal_wrappers.orbslam3.vocabulary_training import build_vocabulary, check_tree_shape

    check_tree_shape(args.k, args.levels)
    if args.levels < 5:
        warnings.warn(
            f"--levels {args.levels}: ORB-SLAM3 loses track with L < 5 (its FeatureVector sits 4 levels above the leaves)", stacklevel=2
        )
    sources = [parse_source(text) for text in args.sources or ["synthetic"]]
    started = time.perf_counter()
    images: list[np.ndarray] = []
    for kind, path in sources:
        if kind == "synthetic" and path is None:
            pictures = synthetic_training_images(args.seed, args.frames, progress=_say)
        else:
            sequence = open_dataset(kind, path)
            _say(f"reading {min(args.frames, len(sequence))} images of {sequence.name} ({kind})")
            pictures = sequence_images(sequence, args.frames)
        images += orb_image_descriptors(pictures)
    descriptors = np.concatenate(images)
    _say(f"training k={args.k} L={args.levels} on {len(descriptors)} descriptors from {len(images)} images")
    vocabulary = build_vocabulary(descriptors, args.k, args.levels, args.seed, images)
    out = vocabulary.write_text(args.out)
    elapsed = time.perf_counter() - started
    depth = vocabulary.depths()[vocabulary.leaf]
    print(f"{out}")
    print(f"  descriptors  {len(descriptors)} from {len(images)} images")
    print(f"  nodes        {vocabulary.n_nodes} (k {vocabulary.k}, L {vocabulary.levels}, leaf depth {depth.min()}..{depth.max()})")
    print(f"  words        {vocabulary.n_words}")
    print(f"  time         {elapsed:.1f} s")
    print(f"  file         {out.stat().st_size / 1e6:.1f} MB")
    return 0


def _say(message: str) -> None:
    print(f"sal: {message}", file=sys.stderr)
