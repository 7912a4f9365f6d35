"""Perturbation modules in physical units, depth providers and composition.

>>> from sal_modules import create, perturb, fog, night
>>> fog.visibility_m.unit                      # on the class: the declared parameter
'm'
>>> chain = night() >> fog(visibility_m=40)    # an ordered chain
>>> seq = perturb(clean, chain, seed=1)         # doctest: +SKIP

Module classes are found through the ``sal.perturbations`` entry-point group, so
``from sal_modules import fog`` works for built-ins and installed plug-ins alike. Each name
loads its module on first use (``sal_adapters.common.lazy``): importing the package pulls no numpy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from sal_adapters.common.lazy import lazy_exports

if TYPE_CHECKING:  # what type checkers see; at run time each name loads on first use
    from sal_modules.base import Composite, Perturbation, SequencePerturbation
    from sal_modules.context import STREAMS, ModuleContext
    from sal_modules.errors import DepthUnavailable, ModuleError, ParameterError
    from sal_modules.params import Param, SearchScale
    from sal_modules.pipeline import chain_of, perturb
    from sal_modules.registry import PERTURBATIONS, create, from_dict, from_json, module_class

__all__ = [
    "PERTURBATIONS",
    "STREAMS",
    "Composite",
    "DepthUnavailable",
    "ModuleContext",
    "ModuleError",
    "Param",
    "ParameterError",
    "Perturbation",
    "SearchScale",
    "SequencePerturbation",
    "chain_of",
    "create",
    "from_dict",
    "from_json",
    "module_class",
    "perturb",
]


def _registered(name: str) -> Any:
    """``sal_modules.fog`` and friends: the registered module class of that name."""
    from sal_adapters.common.suggest import suggestion
    from sal_modules.registry import PERTURBATIONS, module_class

    if name not in PERTURBATIONS.names():
        raise AttributeError(
            f"module 'sal_modules' has no attribute {name!r}" + suggestion(name, [*PERTURBATIONS.names(), *__all__], "modules and names")
        )
    return module_class(name)


__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "sal_modules.base": ["Composite", "Perturbation", "SequencePerturbation"],
        "sal_modules.context": ["STREAMS", "ModuleContext"],
        "sal_modules.errors": ["DepthUnavailable", "ModuleError", "ParameterError"],
        "sal_modules.params": ["Param", "SearchScale"],
        "sal_modules.pipeline": ["chain_of", "perturb"],
        "sal_modules.registry": ["PERTURBATIONS", "create", "from_dict", "from_json", "module_class"],
    },
    fallback=_registered,
)
