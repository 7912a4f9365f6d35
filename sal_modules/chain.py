"""``composite``: an ordered chain of modules, each step seeing the previous step's output.

Build one with ``>>`` (``night() >> fog(visibility_m=40)``) or ``create("composite",
steps=[...])``. Every child parameter is addressable:

- ``"fog.visibility_m"``: by module name, when the name occurs once in the chain;
- ``"fog@1.visibility_m"``: by module name and step position, always;
- ``"visibility_m"``: the bare name, when exactly one step has that parameter.

``sal_modules.perturb`` runs the chain step by step (so frame drops and whole-sequence steps
like ``bandwidth`` see exactly the frames earlier steps produced); ``apply`` on a composite
is the per-frame chain for direct use.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from sal_adapters.suggest import suggestion
from sal_modules.base import ModuleContext, Perturbation
from sal_modules.errors import ParameterError
from sal_modules.param_refs import ParamRef
from sal_modules.params import Param

__all__ = ["Composite"]


class Composite(Perturbation):
    """An ordered chain of perturbation modules.

    Args:
        steps: modules, module classes (their defaults) or ``{"module": name, "params": {...}}``
            dicts, applied in order.
    """

    name = "composite"
    version = 1
    summary = "Ordered chain of modules; each step sees the previous step's output"

    def __init__(self, steps: Iterable[Perturbation | type[Perturbation] | Mapping[str, Any]] = ()):
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


def _flatten(steps: Iterable[Perturbation | type[Perturbation] | Mapping[str, Any]]) -> list[Perturbation]:
    from sal_modules.registry import from_dict

    flat: list[Perturbation] = []
    for step in steps:
        if isinstance(step, type) and issubclass(step, Perturbation):
            step = step()
        elif isinstance(step, Mapping):
            step = from_dict(step)
        if not isinstance(step, Perturbation):
            raise ParameterError(f"composite: a step must be a module, a module class or a dict, got {step!r}")
        flat.extend(step.steps if isinstance(step, Composite) else [step])
    return flat
