"""The perturbation module contract and its composition: ``Perturbation`` and ``Composite``.

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

``a >> b`` is a ``Composite``, and a ``Composite`` is a ``Perturbation``: the two are defined
together here, so imports run one way (``registry`` builds modules by name on top of this).
"""

from __future__ import annotations

import json
from abc import ABCMeta, abstractmethod
from collections.abc import Iterable
from typing import Any, ClassVar

import numpy as np

from sal_adapters.common.json_values import json_safe
from sal_adapters.common.suggest import suggestion
from sal_modules.context import ModuleContext
from sal_modules.errors import ModuleError, ParameterError
from sal_modules.params import Param, ParamRef

__all__ = ["Composite", "Perturbation", "SequencePerturbation"]


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
        return {"module": self.name, "version": self.version, "params": json_safe(self._params)}

    def to_json(self) -> str:
        """Canonical JSON (sorted keys): equal modules give equal strings."""
        return json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and other.to_json() == self.to_json()

    def __hash__(self) -> int:
        return hash(self.to_json())

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self._params.items())
        return f"{self.name}({args})"

    def __rshift__(self, other: Perturbation | type[Perturbation]) -> Composite:
        """``a >> b``: the chain that applies ``a`` first, then ``b`` (a class means its defaults)."""
        return Composite.chain(self, other)

    def __rrshift__(self, other: type[Perturbation]) -> Composite:
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


class Composite(Perturbation):
    """An ordered chain of perturbation modules, each step seeing the previous step's output.

    Built with ``>>`` (``night() >> fog(visibility_m=40)``) or ``sal_modules.create("composite",
    steps=[...])``, which also takes module descriptions (``{"module": name, "params": {...}}``).
    Every child parameter is addressable:

    - ``"fog.visibility_m"``: by module name, when the name occurs once in the chain;
    - ``"fog@1.visibility_m"``: by module name and step position, always;
    - ``"visibility_m"``: the bare name, when exactly one step has that parameter.

    ``sal_modules.perturb`` runs the chain step by step (so frame drops and whole-sequence steps
    like ``bandwidth`` see exactly the frames earlier steps produced); ``apply`` here is the
    per-frame chain for direct use.

    Args:
        steps: modules or module classes (their defaults), applied in order.
    """

    name = "composite"
    version = 1
    summary = "Ordered chain of modules; each step sees the previous step's output"

    def __init__(self, steps: Iterable[Perturbation | type[Perturbation]] = ()):
        self.steps: tuple[Perturbation, ...] = tuple(_flatten(steps))
        if not self.steps:
            raise ParameterError("composite: steps must name at least one module")
        self._params = {}
        self.context = None

    @classmethod
    def chain(cls, first: Perturbation | type[Perturbation], second: Perturbation | type[Perturbation]) -> Composite:
        """``first >> second`` as one flat chain."""
        return cls([first, second])

    # -- addressing child parameters -----------------------------------------------------------
    def addresses(self) -> dict[str, tuple[int, Param]]:
        """Every address of every child parameter -> (step position, Param)."""
        names = [step.name for step in self.steps]
        per_param: dict[str, list[tuple[int, Param]]] = {}
        found: dict[str, tuple[int, Param]] = {}
        for position, step in enumerate(self.steps):
            for key, spec in step.parameters().items():
                found[f"{step.name}@{position}.{key}"] = (position, spec)
                if names.count(step.name) == 1:
                    found[f"{step.name}.{key}"] = (position, spec)
                per_param.setdefault(key, []).append((position, spec))
        for key, owners in per_param.items():
            if len(owners) == 1:
                found.setdefault(key, owners[0])
        return found

    def param(self, address: str) -> tuple[int, Param]:
        """(step position, Param) of ``address``; ``ParameterError`` lists the valid addresses."""
        known = self.addresses()
        if address not in known:
            plain = [a for a in known if "@" not in a]
            raise ParameterError(
                f"composite {self.label()} has no parameter {address!r}" + suggestion(address, plain or known, "addresses")
            )
        return known[address]

    def __getattr__(self, name: str) -> ParamRef:
        """``(night() >> fog).visibility_m``: a child parameter by bare name, for bounds."""
        if name.startswith("_") or "steps" not in self.__dict__:
            raise AttributeError(name)
        try:
            _, spec = self.param(name)
        except ParameterError as exc:
            raise AttributeError(str(exc)) from None
        return ParamRef(self, name, spec)

    def ref(self, address: str) -> ParamRef:
        """A child parameter by any address (``fog.visibility_m``, ``fog@1.visibility_m``)."""
        return ParamRef(self, address, self.param(address)[1])

    @property
    def params(self) -> dict[str, Any]:
        """Child values by ``name@position.parameter``."""
        return {f"{s.name}@{i}.{k}": v for i, s in enumerate(self.steps) for k, v in s.params.items()}

    def with_params(self, **changes: Any) -> Composite:
        """A copy with child parameters changed, by any address (``**{"fog.visibility_m": 30}``)."""
        steps = list(self.steps)
        for address, value in changes.items():
            position, spec = self.param(address)
            steps[position] = steps[position].with_params(**{spec.name: value})
        return Composite(steps)

    def label(self) -> str:
        """``night>>fog``."""
        return ">>".join(step.name for step in self.steps)

    @classmethod
    def describe(cls) -> dict[str, Any]:
        info = super().describe()
        info["parameters"] = [
            {
                "name": "steps",
                "unit": "",
                "default": [],
                "min": None,
                "max": None,
                "domain": "list",
                "searchable": False,
                "worse": None,
                "doc": "modules applied in order; child parameters by address (fog.visibility_m)",
            }
        ]
        return info

    # -- JSON ----------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {"module": self.name, "version": self.version, "steps": [step.to_dict() for step in self.steps]}

    def __repr__(self) -> str:
        return " >> ".join(repr(step) for step in self.steps)

    # -- life cycle ----------------------------------------------------------------------------
    def setup(self, context: ModuleContext) -> None:
        self.context = context
        for step in self.steps:
            step.setup(context)

    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray | None:
        for step in self.steps:
            if not step.keep_frame(index):
                return None
            out = step.apply(image, depth if step.needs_depth else None, index, stream)
            if out is None:
                return None
            image = out
        return image

    def keep_frame(self, index: int) -> bool:
        return all(step.keep_frame(index) for step in self.steps)

    def cleanup(self) -> None:
        for step in self.steps:
            step.cleanup()
        self.context = None


def _flatten(steps: Iterable[Perturbation | type[Perturbation]]) -> list[Perturbation]:
    flat: list[Perturbation] = []
    for step in steps:
        if isinstance(step, type) and issubclass(step, Perturbation):
            step = step()
        if not isinstance(step, Perturbation):
            raise ParameterError(
                f"composite: a step must be a module, a module class or (through create / from_dict) a module description, got {step!r}"
            )
        flat.extend(step.steps if isinstance(step, Composite) else [step])
    return flat
