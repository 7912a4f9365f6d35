"""Finding and building modules by name: ``create``, ``from_dict``, ``module_class``."""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

from sal_adapters.common.plugins import EntryPointRegistry
from sal_modules.base import Composite, Perturbation
from sal_modules.errors import ParameterError

__all__ = ["PERTURBATIONS", "create", "from_dict", "from_json", "module_class"]

#: Perturbation modules by name; built-ins and plug-ins register in ``sal.perturbations``.
PERTURBATIONS: EntryPointRegistry[type[Perturbation]] = EntryPointRegistry("sal.perturbations", "perturbation module")


def module_class(name: str) -> type[Perturbation]:
    """The module class registered as ``name`` (``PluginError`` lists the known names)."""
    cls = PERTURBATIONS.get(name)
    if not (isinstance(cls, type) and issubclass(cls, Perturbation)):
        raise ParameterError(f"perturbation module {name!r} is {cls!r}, not a Perturbation subclass")
    return cls


def create(name: str, **params: Any) -> Perturbation:
    """Build module ``name`` with ``params`` (validated: a wrong name or value raises one
    ``ParameterError`` naming module, parameter, unit and valid range). The ``steps`` of a
    composite may be modules, module classes or module descriptions (``from_dict`` input)."""
    cls = module_class(name)
    if issubclass(cls, Composite) and "steps" in params:
        params["steps"] = [from_dict(step) if isinstance(step, Mapping) else step for step in params["steps"]]
    return cls(**params)


def from_dict(data: Mapping[str, Any]) -> Perturbation:
    """Rebuild a module from ``to_dict()`` output (``{"module", "params"}`` or, for a
    composite, ``{"module": "composite", "steps": [...]}``)."""
    if not isinstance(data, Mapping) or "module" not in data:
        raise ParameterError(f"a module description needs a 'module' key, got {data!r}")
    extra = set(data) - {"module", "version", "params", "steps"}
    if extra:
        raise ParameterError(
            f"module description for {data['module']!r} has unknown keys {sorted(extra)}; allowed: module, version, params, steps"
        )
    if "steps" in data:
        return create(str(data["module"]), steps=data["steps"])
    params = data.get("params") or {}
    if not isinstance(params, Mapping):
        raise ParameterError(f"{data['module']}: 'params' must be a mapping, got {params!r}")
    return create(str(data["module"]), **params)


def from_json(text: str) -> Perturbation:
    """``from_dict`` of a JSON string."""
    return from_dict(json.loads(text))
