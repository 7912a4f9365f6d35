"""``sal modules`` (the perturbation catalogue) and ``sal preview`` (one perturbed frame)."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pytest_sal.cli.arg_types import parse_key_values
from sal_adapters.common.errors import SalError
from sal_adapters.datasets import DATASETS, open_dataset

if TYPE_CHECKING:  # numpy, OpenCV and the modules load when a command runs, not for `sal --help`
    import numpy as np

    from sal_modules.base import Perturbation

__all__ = ["add_module_commands", "build_chain", "preview_image"]

PREVIEW_EPILOG = """\
examples:
  sal preview fog visibility_m=30 --dataset synthetic --frame 5 -o fog.png
  sal preview rain intensity_mm_h=50 exposure_ms=8 --dataset kitti --path ~/kitti --sequence 07 --stereo
  sal preview 'night>>fog' illuminance_lux=2 visibility_m=40 --dataset synthetic -o night_fog.png
  sal preview frame_drop drop_rate=0.3 --dataset synthetic     (shows the frame only if it is kept)

MODULE is a module name or a chain 'a>>b'; in a chain, address a parameter by its bare name when
one step has it, else as step.parameter (fog.visibility_m). Values are parsed as JSON when they
can be (atmospheric_light=[0.8,0.8,0.8]). See `sal modules` for every parameter and its unit.
"""


def add_module_commands(commands: argparse._SubParsersAction) -> None:
    """Add ``modules`` and ``preview`` to the ``sal`` subcommands."""
    listing = commands.add_parser(
        "modules",
        help="perturbation modules with their parameters, units and valid ranges",
        description="List every registered perturbation module (built-in and plug-in) with its "
        "parameters: unit, default, valid range, whether boundary search may vary it and the "
        "direction in which it gets worse.",
    )
    listing.add_argument("name", nargs="?", metavar="MODULE", help="show only this module")
    listing.add_argument("--json", action="store_true", help="machine-readable: a list of modules with their parameters")
    listing.set_defaults(run=_run_modules)

    preview = commands.add_parser(
        "preview",
        help="write one perturbed frame next to the original",
        description="Perturb one frame of a dataset and write the original and the perturbed frame "
        "side by side (stereo: both cameras) as a PNG.",
        epilog=PREVIEW_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    preview.add_argument("module", metavar="MODULE", help="module name or chain 'a>>b'")
    preview.add_argument("params", nargs="*", metavar="KEY=VALUE", help="module parameters in their units")
    preview.add_argument("--dataset", required=True, metavar="KIND", help="dataset kind: " + ", ".join(DATASETS.names()))
    preview.add_argument("--path", type=Path, metavar="P", help="dataset folder (optional for synthetic)")
    preview.add_argument("--sequence", metavar="S", help="sequence inside the dataset folder (KITTI '07')")
    preview.add_argument("--stereo", action="store_true", help="open the stereo pair (gives stereo depth to depth-aware modules)")
    preview.add_argument(
        "--dataset-option", action="append", default=[], metavar="KEY=VALUE", help="other dataset option, e.g. scene=indoor"
    )
    preview.add_argument("--frame", type=int, default=0, metavar="I", help="frame position in the dataset (default: %(default)s)")
    preview.add_argument("--seed", type=int, default=0, help="perturbation seed (default: %(default)s)")
    preview.add_argument(
        "--depth", default="auto", metavar="PROVIDER", help="depth provider: auto, native, stereo or a .onnx model (default: %(default)s)"
    )
    preview.add_argument("-o", "--out", type=Path, default=Path("preview.png"), metavar="PNG", help="output image (default: %(default)s)")
    preview.set_defaults(run=_run_preview)


def build_chain(spec: str, params: dict[str, Any]) -> Perturbation:
    """``"fog"`` or ``"night>>fog"`` with ``params`` (chain parameters by address)."""
    from sal_modules.base import Composite
    from sal_modules.registry import create, module_class

    names = [name.strip() for name in spec.split(">>")]
    if len(names) == 1:
        return create(names[0], **params)
    chain = Composite([module_class(name) for name in names])
    return chain.with_params(**params)


def preview_image(original: list[np.ndarray], perturbed: list[np.ndarray | None], title: str) -> np.ndarray:
    """Rows of (original, perturbed) per stream under a title bar; a dropped frame is grey."""
    import cv2
    import numpy as np

    rows = []
    for clean, changed in zip(original, perturbed):
        if changed is None:
            changed = np.full_like(clean, 96)
            cv2.putText(changed, "frame dropped", (20, clean.shape[0] // 2), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (255, 255, 255), 2, cv2.LINE_AA)
        rows.append(np.hstack([clean, np.zeros((clean.shape[0], 8, 3), np.uint8), changed]))
    sheet = np.vstack([np.vstack([row, np.zeros((8, row.shape[1], 3), np.uint8)]) for row in rows])[:-8]
    lines = _wrap(title, sheet.shape[1] - 16)
    bar = np.zeros((8 + 20 * len(lines), sheet.shape[1], 3), np.uint8)
    for number, line in enumerate(lines):
        cv2.putText(bar, line, (8, 20 + 20 * number), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (255, 255, 255), 1, cv2.LINE_AA)
    return np.vstack([bar, sheet])


def _wrap(text: str, width_px: int) -> list[str]:
    """``text`` broken after ", " into lines no wider than ``width_px`` when drawn."""
    import cv2

    lines, current = [], ""
    for token in text.split(", "):
        candidate = f"{current}, {token}" if current else token
        if current and cv2.getTextSize(candidate, cv2.FONT_HERSHEY_SIMPLEX, 0.55, 1)[0][0] > width_px:
            lines.append(current + ",")
            current = token
        else:
            current = candidate
    return [*lines, current]


def _run_modules(args: argparse.Namespace) -> int:
    from sal_modules.registry import PERTURBATIONS, module_class

    names = [args.name] if args.name else PERTURBATIONS.names()
    described = [module_class(name).describe() for name in names]
    if args.json:
        print(json.dumps(described, indent=2))
        return 0
    for info in described:
        print(f"{info['name']} (v{info['version']}): {info['summary']}")
        flags = [
            flag
            for flag, on in (
                ("needs depth", info["needs_depth"]),
                ("whole sequence", info["whole_sequence"]),
                ("drops frames", info["drops_frames"]),
            )
            if on
        ]
        if flags:
            print(f"  [{', '.join(flags)}]")
        for p in info["parameters"]:
            search = f"  searchable, worse when {p['worse']}" if p["searchable"] else ""
            space = p.get("search") or {}
            if space and (space["scale"] == "log" or (space["min"], space["max"]) != (p["min"], p["max"])):
                unit = f" {space['unit']}" if space["unit"] else ""
                search += f", searched {space['min']:g} .. {space['max']:g}{unit}" + (" on a log scale" if space["scale"] == "log" else "")
            print(f"  {p['name']:<22} {_range_text(p):<28} default {json.dumps(p['default'])}{search}")
            if p["doc"]:
                print(f"  {'':<22} {p['doc']}")
        print()
    return 0


def _range_text(p: dict[str, Any]) -> str:
    unit = f" {p['unit']}" if p["unit"] else ""
    if p["domain"] == "choice":
        return "one of " + "|".join(str(c) for c in p["choices"])
    if p["domain"] in ("flag", "text", "list"):
        return p["domain"]
    lo = "-inf" if p["min"] is None else f"{p['min']:g}"
    hi = "inf" if p["max"] is None else f"{p['max']:g}"
    vector = "each " if p["domain"] == "vector" else ""
    return f"{vector}{lo} .. {hi}{unit}"


def _run_preview(args: argparse.Namespace) -> int:
    from sal_adapters.images import write_image
    from sal_modules.pipeline import perturb

    module = build_chain(args.module, parse_key_values(args.params, "a module parameter"))
    options = parse_key_values(args.dataset_option, "--dataset-option")
    if args.sequence is not None:
        options["sequence"] = args.sequence
    if args.stereo:
        options["stereo"] = True
    if args.frame < 0:
        raise SalError(f"--frame must be >= 0, got {args.frame}")
    clean = open_dataset(args.dataset, args.path, max_frames=args.frame + 2, **options)
    if args.frame >= len(clean):
        raise SalError(f"--frame {args.frame} is past the end of {clean.name!r} ({len(clean)} frames)")
    started = time.perf_counter()
    perturbed = perturb(clean, module, seed=args.seed, depth=args.depth)
    index = clean.records[args.frame].index
    kept = {record.index: position for position, record in enumerate(perturbed.records)}
    frame = clean[args.frame]
    originals = [frame.image] + ([frame.right] if frame.right is not None else [])
    if index in kept:
        out = perturbed[kept[index]]
        results: list[np.ndarray | None] = [out.image, *([out.right] if out.right is not None else [])]
    else:
        results = [None] * len(originals)
    elapsed = time.perf_counter() - started
    title = f"{clean.name} frame {index}: original | {module!r}"
    write_image(args.out, preview_image(originals, results, title))
    print(f"{module!r}")
    print(
        f"frame {index} of {clean.name}: {'kept' if index in kept else 'dropped'}; {elapsed * 1000:.0f} ms (including depth and decoding)"
    )
    print(f"wrote {args.out}")
    return 0
