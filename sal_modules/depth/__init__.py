"""Depth for depth-aware modules: native maps, stereo matching (SGBM), monocular ONNX.

``select_depth_provider(sequence, "auto")`` picks the first that applies, in this order:
native depth (RGB-D, synthetic), stereo semi-global matching (stereo pairs), then a
monocular network when ``SAL_DEPTH_MODEL`` names an ONNX file. When none applies the error
says what each one lacks and how to supply depth.
"""

from __future__ import annotations

import os

from sal_adapters.sequence import Sequence
from sal_modules.depth.base import CachedDepth, DepthProvider, fill_unknown
from sal_modules.depth.mono import MonoDepth
from sal_modules.depth.native import NativeDepth, left_depth_to_right
from sal_modules.depth.stereo import StereoDepth
from sal_modules.errors import DepthUnavailable

__all__ = [
    "CachedDepth",
    "DepthProvider",
    "MonoDepth",
    "NativeDepth",
    "StereoDepth",
    "fill_unknown",
    "left_depth_to_right",
    "select_depth_provider",
]

#: Environment variable naming a monocular depth ONNX model used when nothing else applies.
DEPTH_MODEL_ENV = "SAL_DEPTH_MODEL"


def select_depth_provider(sequence: Sequence, depth: str | DepthProvider = "auto", needed_by: str = "a module") -> DepthProvider:
    """The depth provider for ``sequence``.

    Args:
        depth: ``"auto"``, ``"native"``, ``"stereo"``, a path to an ``.onnx`` monocular model,
            or a ``DepthProvider``.
        needed_by: who asks (for the message), e.g. ``"fog"``.

    Raises:
        DepthUnavailable: the chosen provider does not apply, or (auto) none does.
    """
    if isinstance(depth, DepthProvider):
        candidates = [depth]
    elif depth == "native":
        candidates = [NativeDepth()]
    elif depth == "stereo":
        candidates = [StereoDepth()]
    elif depth == "auto":
        candidates = [NativeDepth(), StereoDepth()]
        if os.environ.get(DEPTH_MODEL_ENV):
            candidates.append(MonoDepth(os.environ[DEPTH_MODEL_ENV]))
    elif str(depth).endswith(".onnx"):
        candidates = [MonoDepth(depth)]
    else:
        raise DepthUnavailable(f"depth={depth!r} is not a depth provider; use 'auto', 'native', 'stereo' or a path to an .onnx model")
    reasons = []
    for provider in candidates:
        reason = provider.unavailable(sequence)
        if reason is None:
            return provider
        reasons.append(f"{provider.name}: {reason}")
    hint = "" if depth != "auto" else f"; supply a monocular depth model with depth='model.onnx' or {DEPTH_MODEL_ENV}=model.onnx"
    raise DepthUnavailable(f"{needed_by} needs depth and no depth provider applies to {sequence.name!r} ({'; '.join(reasons)}){hint}")
