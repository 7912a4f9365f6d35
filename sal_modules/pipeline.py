"""``perturb(sequence, modules, seed)``: a lazily perturbed copy of a sequence.

Nothing is decoded or computed until a frame's image is asked for. The chain runs step by
step: step k sees exactly the frames step k-1 produced, so a frame drop before ``bandwidth``
means the encoder never sees the dropped frames, and ``bandwidth`` encodes the output of the
steps before it (not the original images). Depth always comes from the clean frames.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable
from functools import partial
from pathlib import Path
from threading import RLock
from typing import cast

import cv2
import numpy as np

from sal_adapters.sequence import Frame, FrameRecord, Sequence
from sal_modules.base import Composite, Perturbation, SequencePerturbation
from sal_modules.context import STREAMS, ModuleContext
from sal_modules.depth import DepthProvider, select_depth_provider
from sal_modules.errors import ModuleError

__all__ = ["chain_of", "perturb"]


def chain_of(modules: Perturbation | type[Perturbation] | Iterable[Perturbation | type[Perturbation]]) -> Composite:
    """``modules`` (one module, a class, a composite or a list) as one flat composite of fresh
    copies, so a module object can be reused across sequences."""
    steps: Iterable[Perturbation | type[Perturbation]]
    if isinstance(modules, (Perturbation, type)):
        steps = [modules]
    else:  # a list or other iterable: mypy cannot rule out a module, whose __getattr__ might answer __iter__
        steps = cast(Iterable[Perturbation | type[Perturbation]], modules)
    return Composite([type(m)(**m.params) if isinstance(m, Perturbation) and not isinstance(m, Composite) else m for m in steps])


def perturb(
    sequence: Sequence,
    modules: Perturbation | type[Perturbation] | Iterable[Perturbation | type[Perturbation]],
    seed: int = 0,
    depth: str | DepthProvider = "auto",
    cache_dir: Path | None = None,
) -> Sequence:
    """The perturbed, lazily computed copy of ``sequence``.

    Args:
        sequence: the clean sequence (any dataset kind and sensor).
        modules: a module, a chain (``night() >> fog``) or a list applied in order.
        seed: every random pattern derives from it; the same seed gives identical bytes.
        depth: depth provider for depth-aware modules (see ``select_depth_provider``).
        cache_dir: root for computed depth (default: the user cache).

    Returns:
        A ``Sequence`` of the same kind, camera and sensor whose frames, timestamps and
        per-frame ground truth exclude dropped frames; ``write_sequence`` writes it in the
        dataset's own layout. Frames of a grey camera stay grey after every step.
    """
    chain = chain_of(modules)
    provider = None
    if any(step.needs_depth for step in chain.steps):
        needed_by = ", ".join(step.name for step in chain.steps if step.needs_depth)
        provider = select_depth_provider(sequence, depth, needed_by=needed_by)
    run = _ChainRun(sequence, chain, seed, provider, cache_dir)
    kept = run.kept_positions[-1]
    out = sequence.select(kept)
    streams = ["left"] + (["right"] if sequence.sensor == "stereo" else [])
    records = [
        FrameRecord(
            index=record.index,
            timestamp=record.timestamp,
            stem=record.stem,
            image=partial(run.image, position, "left"),
            right=partial(run.image, position, "right") if "right" in streams and record.right is not None else None,
            depth=record.depth,
            timestamp_ns=record.timestamp_ns,
        )
        for position, record in zip(kept, out.records)
    ]
    key = {
        "source": sequence.fingerprint,
        "chain": chain.to_dict(),
        "seed": seed,
        "depth": None if provider is None else {"provider": provider.name, "settings": provider.settings()},
    }
    content_key = "perturbed:" + hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()
    meta = dict(out.meta, perturbation=chain.to_dict())  # what was applied, for logs and test doubles
    return out.replace(records=records, name=f"{sequence.name}+{chain.label()}", content_key=content_key, meta=meta)


def as_grey(image: np.ndarray) -> np.ndarray:
    """A grey camera sees grey: an RGB result with colour (brown dirt, a warm lamp) becomes
    its luma (Rec. 601, as OpenCV), repeated in three channels; grey input is returned as is."""
    if (image[..., 0] == image[..., 1]).all() and (image[..., 1] == image[..., 2]).all():
        return image
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    return cv2.merge([grey, grey, grey])


class _ChainRun:
    """One chain set up on one sequence; computes step outputs on demand."""

    def __init__(self, sequence: Sequence, chain: Composite, seed: int, provider: DepthProvider | None, cache_dir: Path | None):
        self.sequence = sequence
        self.steps = chain.steps
        self.depth = None if provider is None else provider.lookup(sequence, cache_dir)
        context = ModuleContext(sequence=sequence, seed=int(seed), depth=self.depth)
        for step in self.steps:
            step.setup(context)
        # kept_positions[k]: positions (in ``sequence``) of the frames left after k steps
        kept = list(range(len(sequence)))
        self.kept_positions = [kept]
        for step in self.steps:
            if step.drops_frames:
                kept = [p for p in kept if step.keep_frame(sequence.records[p].index)]
            self.kept_positions.append(kept)
        self._lock = RLock()

    def image(self, position: int, stream: str) -> np.ndarray:
        """Final output of frame ``position`` (of the clean sequence) in ``stream``."""
        return self._after(len(self.steps), position, stream)

    def _after(self, count: int, position: int, stream: str) -> np.ndarray:
        """Frame ``position`` after the first ``count`` steps."""
        record = self.sequence.records[position]
        if count == 0:
            frame = Frame(record, self.sequence.camera)
            image = frame.image if stream == "left" else frame.right
            if image is None:
                raise ModuleError(f"frame {record.index} of {self.sequence.name!r} has no {stream} image")
            return image
        step = self.steps[count - 1]
        if isinstance(step, SequencePerturbation):
            self._prepare(count, stream)
            return step.result(record.index, stream)
        image = self._after(count - 1, position, stream)
        depth = self.depth(record.index, stream) if step.needs_depth and self.depth is not None else None
        out = step.apply(image, depth, record.index, stream)
        if out is None:
            raise ModuleError(
                f"{step.name} dropped frame {record.index} in apply() although keep_frame() kept it; "
                "a module that drops frames must set drops_frames = True and decide in keep_frame(index)"
            )
        return as_grey(out) if self.sequence.grayscale else out

    def _prepare(self, count: int, stream: str) -> None:
        step = self.steps[count - 1]
        assert isinstance(step, SequencePerturbation) and stream in STREAMS
        with self._lock:
            if not step.is_prepared(stream):
                inputs = self.kept_positions[count - 1]
                frames = ((self.sequence.records[p].index, self._after(count - 1, p, stream)) for p in inputs)
                step.prepare(stream, frames)
