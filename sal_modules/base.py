"""The perturbation module contract: declared parameters, a per-sequence life cycle, JSON.

Life cycle for one sequence (``sal_modules.perturb`` drives it)::

    module.setup(context)                          # once: random patterns, masks, models
    module.apply(image, depth, index, stream)      # per frame and stream ("left" / "right")
    module.cleanup()                               # release what setup made

``apply`` takes and returns an HxWx3 uint8 RGB image (``None`` = frame dropped) and never
modifies its input. ``index`` is the frame's dataset index, stable under frame drops, so
per-frame randomness keyed by it is the same whatever else the chain does.

Randomness comes only from ``self.rng(...)``: a generator derived from the sequence seed, the
module name and the keys given, never from the parameter values. A stronger setting therefore
reuses the same random pattern (common random numbers), which keeps boundary search sound.
"""

from __future__ import annotations

import json
import zlib
from abc import ABCMeta, abstractmethod
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from sal_adapters.camera import Camera
from sal_adapters.sequence import Sequence
from sal_adapters.suggest import suggestion
from sal_modules.errors import ModuleError, ParameterError
from sal_modules.params import Param

if TYPE_CHECKING:
    from sal_modules.chain import Composite
    from sal_modules.param_refs import ParamRef

__all__ = ["STREAMS", "DepthLookup", "ModuleContext", "Perturbation", "SequencePerturbation"]

#: Image streams of a sequence: the (left) camera and, for stereo, the right camera.
STREAMS: tuple[str, ...] = ("left", "right")

#: ``depth(index, stream) -> float32 HxW metres (0 = invalid)`` of the clean sequence.
DepthLookup = Callable[[int, str], np.ndarray]


@dataclass(frozen=True)
class ModuleContext:
    """What a module may know about the sequence it perturbs.

    Attributes:
        sequence: the clean input sequence (camera, fps, timestamps, ground truth, frames).
        seed: the perturbation seed; every random pattern derives from it.
        depth: depth of the clean frames by dataset index and stream, or ``None`` when the
            chain needs none.
    """

    sequence: Sequence
    seed: int = 0
    depth: DepthLookup | None = None
    _positions: dict[int, int] = field(default_factory=dict, repr=False, compare=False)

    @property
    def camera(self) -> Camera:
        return self.sequence.camera

    @property
    def fps(self) -> float:
        return self.sequence.fps

    @property
    def frame_count(self) -> int:
        return len(self.sequence)

    def camera_for(self, stream: str) -> Camera:
        """Intrinsics of ``stream`` (the right camera's when the sequence has one)."""
        if stream == "right" and self.camera.right is not None:
            return self.camera.right
        return self.camera

    def position(self, index: int) -> int:
        """Position in ``sequence`` of the frame with dataset index ``index``."""
        if not self._positions:
            self._positions.update({r.index: p for p, r in enumerate(self.sequence.records)})
        try:
            return self._positions[index]
        except KeyError:
            raise ModuleError(f"frame index {index} is not in sequence {self.sequence.name!r}") from None

    def pose(self, index: int) -> np.ndarray | None:
        """Camera-to-world 4x4 pose (m) of frame ``index`` from per-frame ground truth, else ``None``."""
        gt = self.sequence.groundtruth
        if gt is None or not self.sequence.groundtruth_is_per_frame:
            return None
        return gt.select([self.position(index)]).matrices[0]

    def rng(self, *keys: str | int) -> np.random.Generator:
        """A generator that depends only on ``seed`` and ``keys`` (strings hashed with CRC-32)."""
        words = [self.seed & 0xFFFFFFFF] + [zlib.crc32(k.encode()) if isinstance(k, str) else int(k) & 0xFFFFFFFF for k in keys]
        return np.random.default_rng(np.random.SeedSequence(words))


class _ModuleClass(ABCMeta):
    """The type of module classes: ``fog.visibilty_m`` (a typo on the class, where parameters
    are looked up for bounds) is an ``AttributeError`` naming the closest parameter."""

    def __getattr__(cls, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        raise AttributeError(cls.unknown_parameter(name))


class Perturbation(metaclass=_ModuleClass):
    """Base class of every perturbation module.

    Subclasses set ``name`` (registry name), ``version`` (bump when the output for the same
    parameters changes; part of cache keys), ``summary``, declare ``Param`` attributes and
    implement ``apply``. ``needs_depth`` asks the pipeline for depth of the clean frames.

    Modules are immutable values: ``with_params`` returns a changed copy, equal parameters
    compare equal, and ``to_dict``/``from_dict`` round-trip through JSON.
    """

    name: ClassVar[str] = ""
    version: ClassVar[int] = 1
    summary: ClassVar[str] = ""
    needs_depth: ClassVar[bool] = False
    drops_frames: ClassVar[bool] = False
    whole_sequence: ClassVar[bool] = False

    def __init__(self, **params: Any):
        specs = self.parameters()
        for key in params:
            if key not in specs:
                raise ParameterError(self.unknown_parameter(key))
        values = {key: spec.default for key, spec in specs.items()}
        values.update({key: specs[key].validate(value, self.name) for key, value in params.items()})
        self._params = values
        self.check_params(values)
        self.context: ModuleContext | None = None

    # -- declared parameters -------------------------------------------------------------------
    @classmethod
    def parameters(cls) -> dict[str, Param]:
        """Declared parameters by name: searchable ones first, then the rest, each group in
        declaration order (base classes first)."""
        found: dict[str, Param] = {}
        for klass in reversed(cls.__mro__):
            for key, value in vars(klass).items():
                if isinstance(value, Param):
                    found[key] = value
        return dict(sorted(found.items(), key=lambda item: not item[1].searchable))

    @classmethod
    def searchable(cls) -> dict[str, Param]:
        """The parameters boundary search may vary."""
        return {k: p for k, p in cls.parameters().items() if p.searchable}

    @classmethod
    def describe(cls) -> dict[str, Any]:
        """JSON-ready description for ``sal modules --json``."""
        return {
            "name": cls.name,
            "version": cls.version,
            "summary": cls.summary,
            "needs_depth": cls.needs_depth,
            "whole_sequence": cls.whole_sequence,
            "drops_frames": cls.drops_frames,
            "parameters": [p.describe() for p in cls.parameters().values()],
        }

    @classmethod
    def unknown_parameter(cls, key: str) -> str:
        """``fog has no parameter 'visibilty_m'; did you mean 'visibility_m'?`` (else the list)."""
        return f"{cls.name or cls.__name__} has no parameter {key!r}" + suggestion(key, cls.parameters(), "parameters")

    def __getattr__(self, name: str) -> Any:
        """``fog().visibilty_m``: the same message as on the class."""
        if name.startswith("_"):
            raise AttributeError(name)
        raise AttributeError(self.unknown_parameter(name))

    def check_params(self, params: dict[str, Any]) -> None:
        """Checks between parameters (e.g. ``min <= max``); raise ``ParameterError``."""

    def param_error(self, message: str) -> ParameterError:
        """A ``ParameterError`` whose message starts with the module name."""
        return ParameterError(f"{self.name}: {message}")

    @property
    def params(self) -> dict[str, Any]:
        """The configured parameter values (a copy)."""
        return dict(self._params)

    def with_params(self, **changes: Any) -> Perturbation:
        """A copy with some parameters changed (validated like the constructor)."""
        return type(self)(**{**self._params, **changes})

    def ref(self, name: str) -> ParamRef:
        """Parameter ``name`` of this configured module, for a bound that keeps its other
        settings: ``motion_blur(exposure_ms=100).ref("speed_kmh") >= 30`` (on an instance,
        ``.speed_kmh`` is the value itself)."""
        from sal_modules.param_refs import ParamRef

        if name not in self.parameters():
            raise self.param_error(self.unknown_parameter(name))
        return ParamRef(self, name, self.parameters()[name])

    def unchanged_reason(self) -> str | None:
        """Why these settings leave every frame as it was (say, night at daylight), in words, or
        ``None``. Checked for a requirement's envelope edge, where no change means no test."""
        return None

    # -- identity and JSON ---------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """``{"module": name, "version": v, "params": {...}}`` with JSON types only."""
        return {"module": self.name, "version": self.version, "params": {k: _jsonable(v) for k, v in self._params.items()}}

    def to_json(self) -> str:
        """Canonical JSON (sorted keys): equal modules give equal strings."""
        return json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and other.to_json() == self.to_json()  # type: ignore[attr-defined]

    def __hash__(self) -> int:
        return hash(self.to_json())

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self._params.items())
        return f"{self.name}({args})"

    def __rshift__(self, other: Perturbation | type[Perturbation]) -> Composite:
        """``a >> b``: the chain that applies ``a`` first, then ``b`` (a class means its defaults)."""
        from sal_modules.chain import Composite

        return Composite.chain(self, other)

    def __rrshift__(self, other: type[Perturbation]) -> Composite:
        from sal_modules.chain import Composite

        return Composite.chain(other, self)

    # -- life cycle ----------------------------------------------------------------------------
    def setup(self, context: ModuleContext) -> None:
        """Prepare for one sequence. Overrides call ``super().setup(context)`` first."""
        if self.needs_depth and context.depth is None:
            raise ModuleError(f"{self.name} needs depth; run it through sal_modules.perturb(), which picks a depth provider")
        self.context = context

    @abstractmethod
    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray | None:
        """The perturbed copy of ``image`` (HxWx3 uint8 RGB); ``None`` drops the frame."""
        raise NotImplementedError(f"{type(self).__name__}.apply")

    def keep_frame(self, index: int) -> bool:
        """Whether frame ``index`` survives; modules with ``drops_frames`` decide it from the
        index alone, so the kept frames are known before any image is decoded."""
        return True

    def cleanup(self) -> None:
        """Release what ``setup`` made. Overrides call ``super().cleanup()``."""
        self.context = None

    def rng(self, *keys: str | int) -> np.random.Generator:
        """A generator for this module's random pattern, keyed by ``keys`` (e.g. the stream)."""
        return self.ready_context().rng(self.name, *keys)

    def ready_context(self) -> ModuleContext:
        """The context given to ``setup``; a clear error when ``setup`` was not called."""
        if self.context is None:
            raise ModuleError(f"{self.name}: call setup(context) before apply(); sal_modules.perturb() does both")
        return self.context


class SequencePerturbation(Perturbation):
    """A module that needs every frame of a stream before it can return any (video coding).

    The pipeline calls ``prepare(stream, frames)`` once per stream with ``(index, image)``
    pairs in time order, then ``result(index, stream)`` per frame; ``apply`` is the same as
    ``result`` once the stream is prepared, so the per-frame contract still holds.
    """

    whole_sequence: ClassVar[bool] = True

    @abstractmethod
    def prepare(self, stream: str, frames: Iterable[tuple[int, np.ndarray]]) -> None:
        """Consume every input frame of ``stream`` in order."""
        raise NotImplementedError(f"{type(self).__name__}.prepare")

    @abstractmethod
    def is_prepared(self, stream: str) -> bool:
        """Whether ``prepare`` ran for ``stream``."""
        raise NotImplementedError(f"{type(self).__name__}.is_prepared")

    @abstractmethod
    def result(self, index: int, stream: str) -> np.ndarray:
        """The output frame for dataset index ``index``."""
        raise NotImplementedError(f"{type(self).__name__}.result")

    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray | None:
        if not self.is_prepared(stream):
            raise ModuleError(f"{self.name} works on whole sequences: call prepare({stream!r}, frames) first, or use sal_modules.perturb()")
        return self.result(index, stream)


def _jsonable(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value
