"""``sal report DIR``: one HTML page from an experiment folder (see ``experiment_report``)."""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["add_report_commands"]

EPILOG = """\
examples:
  sal report results/fog_rain_urban
  sal report results/fog_rain_urban -o /tmp/fog-report
  sal report example_suites/configs/fog_rain_urban.yaml     # the config's results folder
                                   # (the newest one when output.create_timestamp_dir is true)

DIR is <output.base_dir>/<experiment.name>, where sal perturb, evaluate, boundary and features
wrote their results. The page shows example frames of every perturbation at the same moment,
the ATE table and plots per SLAM system, each boundary search with its plot and trials, and the
feature-tracking curves; missing parts name the command that makes them. It is self-contained
(pictures copied to assets/ beside it, no script, no network): open it, move it, or upload it
as a CI artifact.
"""


def add_report_commands(commands: argparse._SubParsersAction) -> None:
    """Add ``report`` to the ``sal`` subcommands."""
    cmd = commands.add_parser(
        "report",
        help="one HTML page from an experiment folder: frames, ATE, boundary, features",
        description="Build one HTML page from what sal perturb, evaluate, boundary and features wrote\ninto an experiment folder.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    cmd.add_argument(
        "folder", type=Path, metavar="DIR", help="experiment folder <output.base_dir>/<experiment.name>, or the experiment's YAML config"
    )
    cmd.add_argument("-o", "--out", type=Path, metavar="OUT", help="folder for index.html and assets/ (default: DIR/report)")
    cmd.set_defaults(run=_run)


def _run(args: argparse.Namespace) -> int:
    from pytest_sal.report.experiment_page import write_experiment_report

    page = write_experiment_report(args.folder, args.out)
    print(f"wrote {page}")
    return 0
