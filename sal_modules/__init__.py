"""Perturbation modules in physical units, depth providers and composition.

>>> from sal_modules import create, perturb, fog, night
>>> fog.visibility_m.unit                      # on the class: the declared parameter
'm'
>>> chain = night() >> fog(visibility_m=40)    # an ordered chain
>>> seq = perturb(clean, chain, seed=1)         # doctest: +SKIP

Module classes are found through the ``sal.perturbations`` entry-point group, so
``from sal_modules import fog`` works for built-ins and installed plug-ins alike.
"""

from __future__ import annotations

from typing import Any

from sal_modules.base import STREAMS, ModuleContext, Perturbation, SequencePerturbation
from sal_modules.chain import Composite
from sal_modules.errors import DepthUnavailable, ModuleError, ParameterError
from sal_modules.params import Param, SearchScale
from sal_modules.pipeline import chain_of, perturb
from sal_modules.registry import (
    PERTURBATIONS,
    create,
    from_dict,
    from_json,
    module_class,
)

__all__ = [
    "Composite",
    "DepthUnavailable",
    "ModuleContext",
    "ModuleError",
    "PERTURBATIONS",
    "Param",
    "ParameterError",
    "Perturbation",
    "STREAMS",
    "SearchScale",
    "SequencePerturbation",
    "chain_of",
    "create",
    "from_dict",
    "from_json",
    "module_class",
    "perturb",
]


def __getattr__(name: str) -> Any:
    """``sal_modules.fog`` and friends: the registered module class of that name."""
    if name.startswith("_") or name not in PERTURBATIONS.names():
        raise AttributeError(f"module 'sal_modules' has no attribute {name!r}")
    return module_class(name)
