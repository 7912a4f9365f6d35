"""The ``sal`` command: datasets, the synthetic world demo, and (later) the experiment workflow.

Every bad input ends as one ``sal: error: ...`` line naming the file, key or option, with exit
status 2 and no traceback; so does an output that cannot be written (``sal: error: cannot write
PATH: No space left on device``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import warnings
from collections.abc import Sequence as ArgList
from pathlib import Path
from typing import Any

from pytest_sal.cli.arg_types import parse_key_values, positive_int
from pytest_sal.cli.boundary import add_boundary_commands
from pytest_sal.cli.cache import add_cache_commands
from pytest_sal.cli.compare import add_compare_commands
from pytest_sal.cli.evaluate import add_evaluate_commands
from pytest_sal.cli.features import add_features_commands
from pytest_sal.cli.history import add_history_commands
from pytest_sal.cli.modules import add_module_commands
from pytest_sal.cli.perturb import add_experiment_commands
from pytest_sal.cli.report import add_report_commands
from pytest_sal.cli.vocab import add_vocab_commands
from sal_adapters import DATASETS, SalError, open_dataset

__all__ = ["build_parser", "main"]

EPILOG = """\
examples:
  sal demo                                   render the synthetic world and write a preview
  sal dataset list                           dataset kinds you can open
  sal dataset info kitti /data/kitti --sequence 07 --stereo
  sal dataset info euroc /data/V1_01_easy --json
  sal dataset info synthetic --option scene=indoor --option frames=30
  sal modules                                perturbation modules, parameters, units, ranges
  sal preview fog visibility_m=30 --dataset synthetic --frame 5 -o fog.png

the paper's workflow, one YAML experiment (example_suites/configs/ has the table of severities):
  sal perturb  example_suites/configs/urban_rain.yaml --dry-run   validate, print the plan
  sal perturb  example_suites/configs/urban_rain.yaml             perturbed sequences on disk
  sal evaluate example_suites/configs/urban_rain.yaml --system orbslam3 --runs 3
  sal boundary example_suites/configs/urban_rain.yaml --system reference_vo
  sal features example_suites/configs/urban_rain.yaml --features orb
  sal report   example_suites/configs/urban_rain.yaml             one HTML page of all of it

the regression gate, on the run history that pytest sessions write (.sal/history):
  sal history                                every test: latest boundary, change since the run before
  sal compare main                           the last run against the baseline named main; exit 1 on a regression that fails
  sal history prune --keep 50                remove old runs (baselines are kept)

Datasets are read in their own layouts (KITTI odometry, TUM RGB-D, EuRoC MAV, a folder of
images) or rendered (the synthetic world: urban street canyon or indoor room). Rendered frames
are cached in $SAL_CACHE_DIR (default ~/.cache/sal).
"""


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``sal`` with all subcommands."""
    parser = argparse.ArgumentParser(
        prog="sal",
        description="pytest-sal: test what weather, optics and video transport a visual SLAM system survives.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    demo = commands.add_parser(
        "demo",
        help="render the synthetic world (urban stereo + indoor RGB-D) and write a preview image",
        description="Render both synthetic scenes, print what was made and write a contact sheet of frames and depth maps.",
    )
    demo.add_argument("--frames", type=positive_int, default=20, metavar="N", help="frames per scene (default: %(default)s)")
    demo.add_argument("--seed", type=int, default=0, help="world seed (default: %(default)s)")
    demo.add_argument("--out", type=Path, default=Path("sal-demo"), metavar="DIR", help="output folder (default: %(default)s)")
    demo.set_defaults(run=_run_demo)

    dataset = commands.add_parser("dataset", help="list dataset kinds, or summarise a dataset", description="Dataset tools.")
    dataset_commands = dataset.add_subparsers(dest="dataset_command", metavar="ACTION", required=True)
    listing = dataset_commands.add_parser("list", help="dataset kinds and their options")
    listing.set_defaults(run=_run_dataset_list)
    info = dataset_commands.add_parser(
        "info",
        help="frames, sensor, fps, camera and ground truth of a dataset",
        description="Open a dataset and print frames, sensor, fps, camera (fx, fy, cx, cy, width, "
        "height, baseline_m) and the number of ground-truth poses.",
        epilog="example: sal dataset info kitti ~/data/kitti --sequence 07 --stereo --json",
    )
    info.add_argument("kind", metavar="KIND", help="dataset kind: " + ", ".join(DATASETS.names()))
    info.add_argument("path", metavar="PATH", nargs="?", type=Path, help="dataset folder (optional for synthetic)")
    info.add_argument("--sequence", metavar="S", help="sequence inside PATH (KITTI '07', TUM or EuRoC folder name)")
    info.add_argument("--stereo", action="store_true", help="open the stereo pair")
    info.add_argument("--start", type=int, default=0, metavar="N", help="first frame (default: %(default)s)")
    info.add_argument("--max-frames", type=positive_int, metavar="N", help="keep at most N frames")
    info.add_argument(
        "--option",
        "-o",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="other option of the dataset kind, e.g. -o scene=indoor (values parsed as JSON when they can be)",
    )
    info.add_argument("--json", action="store_true", help="print exactly the keys frames, sensor, fps, camera, groundtruth_poses as JSON")
    info.set_defaults(run=_run_dataset_info)
    add_module_commands(commands)
    add_vocab_commands(commands)
    add_history_commands(commands)
    add_compare_commands(commands)
    add_experiment_commands(commands)
    add_features_commands(commands)
    add_evaluate_commands(commands)
    add_boundary_commands(commands)
    add_report_commands(commands)
    add_cache_commands(commands)
    return parser


def main(argv: ArgList[str] | None = None) -> int:
    """Entry point of the ``sal`` console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = _show_warning
        try:
            return int(args.run(args) or 0)
        except SalError as exc:
            print(f"sal: error: {exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            print("sal: interrupted", file=sys.stderr)
            return 130
        except BrokenPipeError:  # the reader went away (sal modules | head): stop quietly
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 0
        except OSError as exc:  # not named by a writer (a full disk, a file where a folder belongs)
            where = f"{exc.filename}: " if exc.filename is not None else ""
            print(f"sal: error: {where}{exc.strerror or exc}", file=sys.stderr)
            return 2


def _show_warning(message: Warning | str, category: type[Warning], *_: Any, **__: Any) -> None:
    print(f"sal: warning: {message}", file=sys.stderr)


def _run_dataset_list(args: argparse.Namespace) -> int:
    for name, kind in DATASETS.items():
        options = ", ".join(["start", "max_frames", *kind.option_names()])
        print(f"{name:10s} {kind.description}\n{'':10s} options: {options}")
    return 0


def _run_dataset_info(args: argparse.Namespace) -> int:
    options = parse_key_values(args.option)
    if args.sequence is not None:
        options["sequence"] = args.sequence
    if args.stereo:
        options["stereo"] = True
    sequence = open_dataset(args.kind, args.path, start=args.start, max_frames=args.max_frames, **options)
    info = sequence.info()
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    cam = info["camera"]
    baseline = "-" if cam["baseline_m"] is None else f"{cam['baseline_m']:.4f} m"
    duration = sequence.timestamps[-1] - sequence.timestamps[0]
    print(f"{sequence.name} ({args.kind})")
    print(f"  frames       {info['frames']} over {duration:.2f} s")
    print(f"  sensor       {info['sensor']}")
    print(f"  fps          {info['fps']:.3f} Hz")
    print(f"  camera       fx {cam['fx']:.4f}  fy {cam['fy']:.4f}  cx {cam['cx']:.4f}  cy {cam['cy']:.4f} px")
    print(f"  image        {cam['width']} x {cam['height']} px")
    print(f"  baseline     {baseline}")
    gt = sequence.groundtruth
    gt_text = "none" if gt is None else f"{len(gt)} poses, path {gt.path_length():.2f} m"
    print(f"  groundtruth  {gt_text}")
    for label, text in DATASETS.get(args.kind).details(sequence):
        print(f"  {label:12s} {text}")
    return 0


def _run_demo(args: argparse.Namespace) -> int:
    from pytest_sal.cli.demo import run_demo

    run_demo(frames=args.frames, seed=args.seed, out_dir=args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
