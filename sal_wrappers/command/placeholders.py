"""Placeholders of the ``command`` system: ``{sequence}``, ``{output}``, ``{camera_fx}`` and the rest.

They work in ``argv``, ``prefix``, ``env`` values, ``cwd``, ``output`` and in the ``settings``
template; ``{{`` and ``}}`` are literal braces. ``PLACEHOLDERS`` says what each one becomes,
``placeholder_values`` computes them for one run (paths absolute), ``render`` substitutes them.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path

from sal_adapters import Sequence
from sal_adapters.common.textfiles import format_float

__all__ = ["PLACEHOLDERS", "placeholder_values", "placeholders_in", "render"]

#: Every placeholder and what it becomes (paths are absolute).
PLACEHOLDERS: dict[str, str] = {
    "sequence": "the staged sequence: the path open_dataset(layout, path) reads (KITTI: .../sequences/00, EuRoC: the folder holding mav0/)",
    "workdir": "the run's work folder",
    "output": "the file the program must write its trajectory to (the output option, resolved against cwd)",
    "output_times": "workdir/output_times.txt: where a program writing 12-value KITTI poses may write one time per pose",
    "settings": "the settings template rendered into workdir/settings/ (option settings)",
    "timestamps": "workdir/timestamps.txt: one frame time per line (s), no header",
    "timestamps_ns": "workdir/timestamps_ns.txt: one frame time per line (integer ns, the EuRoC image names), no header",
    "associations": "workdir/associations.txt: TUM 't rgb/... t depth/...' pairs without comment lines (RGB-D in the tum layout)",
    "fps": "nominal frame rate (Hz); an integer when it is one (ORB-SLAM3 insists on an int Camera.fps)",
    "frames": "number of frames staged",
    "sensor": "mono, stereo or rgbd: the mode the program runs in",
    "camera_fx": "focal length x (px); every camera_* value but width and height is written as a real (525.0)",
    "camera_fy": "focal length y (px)",
    "camera_cx": "principal point x (px)",
    "camera_cy": "principal point y (px)",
    "camera_width": "image width (px)",
    "camera_height": "image height (px)",
    "camera_k1": "radial distortion k1 (0 when none)",
    "camera_k2": "radial distortion k2 (0 when none)",
    "camera_p1": "tangential distortion p1 (0 when none)",
    "camera_p2": "tangential distortion p2 (0 when none)",
    "camera_k3": "radial distortion k3 (0 when none)",
    "camera_baseline": "stereo baseline (m; 0 for a single camera)",
    "camera_bf": "camera_fx * camera_baseline (ORB-SLAM's Camera.bf)",
}

_TOKEN = re.compile(r"\{\{|\}\}|\{([A-Za-z_][A-Za-z0-9_]*)\}")


def placeholders_in(text: str) -> list[str]:
    """The ``{name}`` placeholders in ``text`` (``{{`` / ``}}`` are escapes)."""
    return [m.group(1) for m in _TOKEN.finditer(text) if m.group(1)]


def render(text: str, values: Mapping[str, str]) -> str:
    """``text`` with each ``{name}`` replaced by ``values[name]`` and ``{{``/``}}`` by braces."""

    def one(match: re.Match[str]) -> str:
        token = match.group(0)
        if token == "{{":
            return "{"
        if token == "}}":
            return "}"
        return values[match.group(1)]

    return _TOKEN.sub(one, text)


def placeholder_values(sequence: Sequence, mode: str, workdir: Path, staged: Path, settings: Path | None) -> dict[str, str]:
    """Every placeholder's text for one run but ``output`` (known once ``cwd`` is): the
    sequence staged at ``staged`` in ``mode``, and the settings template rendered into
    ``workdir/settings/`` when there is one."""
    cam = sequence.camera
    dist = [*cam.distortion, 0.0, 0.0, 0.0, 0.0, 0.0][:5]
    baseline = cam.baseline_m or 0.0
    values = {
        "sequence": str(staged),
        "workdir": str(workdir),
        "output_times": str(workdir / "output_times.txt"),
        "timestamps": str(workdir / "timestamps.txt"),
        "timestamps_ns": str(workdir / "timestamps_ns.txt"),
        "associations": str(workdir / "associations.txt"),
        "fps": str(int(sequence.fps)) if float(sequence.fps).is_integer() else format_float(sequence.fps),
        "frames": str(len(sequence)),
        "sensor": mode,
        "camera_fx": format_float(cam.fx),
        "camera_fy": format_float(cam.fy),
        "camera_cx": format_float(cam.cx),
        "camera_cy": format_float(cam.cy),
        "camera_width": str(int(cam.width)),
        "camera_height": str(int(cam.height)),
        "camera_k1": format_float(dist[0]),
        "camera_k2": format_float(dist[1]),
        "camera_p1": format_float(dist[2]),
        "camera_p2": format_float(dist[3]),
        "camera_k3": format_float(dist[4]),
        "camera_baseline": format_float(baseline),
        "camera_bf": format_float(cam.fx * baseline),
    }
    if settings is not None:
        values["settings"] = str(workdir / "settings" / settings.name)
    return values
