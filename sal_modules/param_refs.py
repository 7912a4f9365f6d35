"""References to a searchable parameter of a module or chain, and bounds written with them.

``fog.visibility_m >= 25`` and ``(night() >> fog).visibility_m >= 40`` build a ``Bound``: the
parameter, the comparison and the number. The requirement language of ``pytest_sal`` reads
bounds as operating envelopes; nothing here runs a search.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from sal_modules.base import Perturbation
    from sal_modules.params import Param

__all__ = ["COMPARISONS", "Bound", "ParamRef"]

#: Comparison operators a bound may use, with their meaning in words.
COMPARISONS = {">=": "at least", ">": "above", "<=": "at most", "<": "below"}


@dataclass(frozen=True, eq=False)
class ParamRef:
    """One parameter of a module class (``fog.visibility_m``) or of a configured module or chain
    (``(night() >> fog).visibility_m``).

    Attributes:
        target: the module class, or the module instance / ``Composite`` whose other settings apply.
        address: the parameter's name in ``target`` (``visibility_m``; ``fog.visibility_m`` in a chain).
        param: the declared ``Param``.
    """

    target: Any
    address: str
    param: Param

    @property
    def label(self) -> str:
        """``fog.visibility_m``, or ``(night>>fog).visibility_m`` for a parameter of a chain."""
        if isinstance(self.target, type):
            return self.param.qualname
        if hasattr(self.target, "label"):
            return f"({self.target.label()}).{self.address}"
        return f"{self.target.name}.{self.address}"

    @property
    def unit(self) -> str:
        """The parameter's unit: the unit of every bound, search value, id and report cell."""
        return self.param.unit

    def module(self, value: Any) -> Perturbation:
        """The configured module (or chain) with this parameter set to ``value`` (its unit)."""
        base = self.target() if isinstance(self.target, type) else self.target
        return base.with_params(**{self.address: value})

    def unchanged_at(self, value: Any) -> str | None:
        """Why the module owning this parameter leaves the frames unchanged at ``value``
        (``Perturbation.unchanged_reason``), or ``None``."""
        module = self.module(value)
        steps = getattr(module, "steps", None)
        if steps is not None:  # a chain: the step that owns the parameter
            module = steps[module.param(self.address)[0]]
        return module.unchanged_reason()

    def _bound(self, op: str, value: Any) -> Bound:
        if not isinstance(value, numbers.Real) or isinstance(value, bool):
            raise TypeError(
                f"{self.label} {op} {value!r}: compare a parameter with a number in {self.unit or 'its unit'}, "
                f"e.g. {self.label} {op} {self.param.default!r}"
            )
        return Bound(self, op, float(value))

    def __ge__(self, value: Any) -> Bound:
        return self._bound(">=", value)

    def __gt__(self, value: Any) -> Bound:
        return self._bound(">", value)

    def __le__(self, value: Any) -> Bound:
        return self._bound("<=", value)

    def __lt__(self, value: Any) -> Bound:
        return self._bound("<", value)

    def __repr__(self) -> str:
        return f"<ParamRef {self.label} [{self.param.unit or '-'}]>"


@dataclass(frozen=True, eq=False)
class Bound:
    """``ref op value``: the parameter range a requirement must hold over (an envelope)."""

    ref: ParamRef
    op: str
    value: float

    def __bool__(self) -> bool:
        raise TypeError(f"{self} is a bound for sal.require(...), not a truth value")

    @property
    def condition(self) -> str:
        """The bound without the parameter: ``>= 25 m``."""
        unit = f" {self.ref.unit}" if self.ref.unit else ""
        return f"{self.op} {self.value:g}{unit}"

    def __str__(self) -> str:
        return f"{self.ref.label} {self.condition}"
