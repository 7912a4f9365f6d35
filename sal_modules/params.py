"""Declared parameters of perturbation modules: unit, default, valid range, search direction.

A module declares each parameter as a class attribute::

    class Fog(Perturbation):
        visibility_m = Param(50.0, unit="m", min=1.0, max=100_000.0, searchable=True,
                             worse="lower", doc="meteorological visibility (2 % contrast)")

On the class, ``Fog.visibility_m`` is the ``Param`` itself (what the requirement language and
boundary search use); on an instance it is the configured value.

``fog.visibility_m >= 25`` and ``(night() >> fog).visibility_m >= 40`` build a ``Bound``: a
``ParamRef`` to the parameter, the comparison and the number. The requirement language of
``pytest_sal`` reads bounds as operating envelopes; nothing here runs a search. ``Param`` and
``ParamRef`` name each other, so they live together; a ``ParamRef`` makes a configured
``sal_modules.base.Perturbation`` without naming that class, so this module sits below
``sal_modules.base`` and imports nothing from it.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

from sal_adapters.common.json_values import json_safe
from sal_adapters.common.quoting import short_repr
from sal_modules.errors import ParameterError

__all__ = ["COMPARISONS", "Bound", "Domain", "Param", "ParamRef", "SearchScale", "Worse"]

Domain = Literal["continuous", "integer", "choice", "vector", "flag", "text"]
Worse = Literal["higher", "lower"]
_DOMAINS = ("continuous", "integer", "choice", "vector", "flag", "text")


Scale = Literal["linear", "log"]


@dataclass(frozen=True)
class SearchScale:
    """The range and spacing boundary search walks, always in the parameter's own unit.

    Example: ``night.illuminance_lux`` is searched from 0.01 to 100000 lx on a ``log`` scale
    (bisection takes the geometric mean ``sqrt(a b)``, so 1..100 lx is halved at 10 lx). Log
    or linear is a detail of the search: bounds, ids, reports and history stay in lx.

    Attributes:
        domain: ``continuous`` or ``integer`` values.
        min, max: the default search range, in the parameter's unit.
        unit: the parameter's unit.
        scale: ``linear`` (arithmetic midpoints) or ``log`` (geometric midpoints; min > 0).
    """

    domain: Literal["continuous", "integer"]
    min: float
    max: float
    unit: str
    scale: Scale = "linear"


class Param:
    """One declared parameter of a perturbation module.

    Args:
        default: value when none is given (``None`` allowed with ``optional=True``).
        unit: physical unit (``m``, ``mm/h``, ``km/h``, ``ms``, ``Mbit/s``; ``""`` for none).
        min, max: inclusive valid range of a number (or of each vector component).
        domain: ``continuous`` (float), ``integer``, ``choice`` (one of ``choices``),
            ``vector`` (``length`` numbers), ``flag`` (bool) or ``text`` (a string, e.g. a path).
        searchable: boundary search may vary it.
        worse: ``higher`` or ``lower``: the direction in which the perturbation gets stronger.
        choices: allowed values of a ``choice`` parameter.
        length: number of components of a ``vector``.
        optional: ``None`` is a valid value (meaning "estimate" or "not set").
        scale: ``log`` for a parameter that spans decades (lux, ISO, Mbit/s): the search
            bisects it geometrically. Bounds and reports stay in ``unit`` either way.
        search_range: the range the search walks by default when narrower than ``min .. max``
            (in ``unit``).
        doc: one line for ``sal modules`` and error messages.
    """

    def __init__(
        self,
        default: Any,
        *,
        unit: str = "",
        min: float | None = None,
        max: float | None = None,
        domain: Domain = "continuous",
        searchable: bool = False,
        worse: Worse | None = None,
        choices: Sequence[Any] | None = None,
        length: int | None = None,
        optional: bool = False,
        scale: Scale = "linear",
        search_range: tuple[float, float] | None = None,
        doc: str = "",
    ):
        if domain not in _DOMAINS:
            raise ValueError(f"domain must be one of {_DOMAINS}, got {domain!r}")
        if searchable and (domain not in ("continuous", "integer") or worse not in ("higher", "lower")):
            raise ValueError("a searchable parameter needs a continuous or integer domain and worse='higher'|'lower'")
        if scale not in ("linear", "log"):
            raise ValueError(f"scale must be 'linear' or 'log', got {scale!r}")
        lowest = search_range[0] if search_range is not None else min
        if scale == "log" and searchable and (lowest is None or lowest <= 0):
            raise ValueError("a log-scale parameter needs a search range above 0")
        if domain == "choice" and not choices:
            raise ValueError("a choice parameter needs choices")
        if domain == "vector" and not length:
            raise ValueError("a vector parameter needs a length")
        self.unit = unit
        self.min = min
        self.max = max
        self.domain: Domain = domain
        self.searchable = searchable
        self.worse = worse
        self.choices = tuple(choices) if choices is not None else None
        self.length = length
        self.optional = optional
        self.scale: Scale = scale
        self.search_range = None if search_range is None else (float(search_range[0]), float(search_range[1]))
        self.doc = doc
        self.name = ""
        self.owner: type | None = None
        self.default = default if default is None and optional else self.validate(default, "default")

    # -- descriptor: the Param on the class, the value on an instance --------------------------
    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name
        self.owner = owner

    def __get__(self, instance: Any, owner: type | None = None) -> Any:
        if instance is None:
            return self
        return instance.params[self.name]

    def __set__(self, instance: Any, value: Any) -> None:
        raise AttributeError(f"{self.qualname} is read-only; use .with_params({self.name}=...) for a changed copy")

    # -- bounds: ``fog.visibility_m >= 25`` (the requirement language reads them) -------------
    def ref(self) -> ParamRef:
        """This parameter of its module class as a ``ParamRef``."""
        return ParamRef(self.owner, self.name, self)

    def __ge__(self, value: Any) -> Bound:
        return self.ref() >= value

    def __gt__(self, value: Any) -> Bound:
        return self.ref() > value

    def __le__(self, value: Any) -> Bound:
        return self.ref() <= value

    def __lt__(self, value: Any) -> Bound:
        return self.ref() < value

    __hash__ = object.__hash__

    # -- description ---------------------------------------------------------------------------
    @property
    def qualname(self) -> str:
        """``module.parameter``, e.g. ``fog.visibility_m``."""
        module = getattr(self.owner, "name", None) or (self.owner.__name__ if self.owner else "?")
        return f"{module}.{self.name}"

    def allowed(self) -> str:
        """What values are valid, in words with the unit: ``1 .. 100000 m``."""
        unit = f" {self.unit}" if self.unit else ""
        if self.domain == "choice":
            text = "one of " + ", ".join(repr(c) for c in self.choices or ())
        elif self.domain == "flag":
            text = "true or false"
        elif self.domain == "text":
            text = "a string"
        else:
            lo = "-inf" if self.min is None else f"{self.min:g}"
            hi = "inf" if self.max is None else f"{self.max:g}"
            kind = "an integer" if self.domain == "integer" else "a number"
            if self.domain == "vector":
                kind = f"{self.length} numbers, each"
            text = f"{kind} in {lo} .. {hi}{unit}"
        return text + (" or null" if self.optional else "")

    def describe(self) -> dict[str, Any]:
        """JSON-ready description (``sal modules --json``)."""
        info: dict[str, Any] = {
            "name": self.name,
            "unit": self.unit,
            "default": json_safe(self.default),
            "min": self.min,
            "max": self.max,
            "domain": self.domain,
            "searchable": self.searchable,
            "worse": self.worse,
            "doc": self.doc,
        }
        if self.choices is not None:
            info["choices"] = list(self.choices)
        if self.searchable:
            space = self.search_space()
            info["search"] = {"domain": space.domain, "min": space.min, "max": space.max, "unit": space.unit, "scale": space.scale}
        return info

    def search_space(self) -> SearchScale:
        """The range and scale boundary search walks, in the parameter's unit (``search_range``
        when declared, else the valid range)."""
        if not self.searchable:
            raise ParameterError(f"{self.qualname} is not searchable; searchable parameters are declared with searchable=True")
        lo, hi = self.search_range or (self.min, self.max)
        assert lo is not None and hi is not None
        return SearchScale(self.domain, float(lo), float(hi), self.unit, self.scale)  # type: ignore[arg-type]

    # -- validation ----------------------------------------------------------------------------
    def validate(self, value: Any, module: str | None = None) -> Any:
        """``value`` converted to the canonical type, or ``ParameterError`` naming module,
        parameter, unit and valid range."""
        if value is None and self.optional:
            return None
        checker = getattr(self, f"_check_{self.domain}")
        converted = checker(value)
        if converted is _INVALID:
            where = f"{module}: " if module else ""
            quoted = short_repr(value)
            shown = f"{quoted}{' ' + self.unit if self.unit and _is_number(value) else ''}"
            doc = f" ({self.doc})" if self.doc else ""
            raise ParameterError(f"{where}{self.name} = {shown} is not valid; {self.name}{doc} must be {self.allowed()}")
        return converted

    def _in_range(self, x: float | None) -> bool:
        return x is not None and math.isfinite(x) and (self.min is None or x >= self.min) and (self.max is None or x <= self.max)

    def _check_continuous(self, value: Any) -> Any:
        x = _as_float(value)
        return x if self._in_range(x) else _INVALID

    def _check_integer(self, value: Any) -> Any:
        x = _as_float(value)
        if x is None or not math.isfinite(x) or x != int(value):
            return _INVALID
        return int(value) if self._in_range(x) else _INVALID

    def _check_choice(self, value: Any) -> Any:
        return value if value in (self.choices or ()) and not isinstance(value, bool) else _INVALID

    def _check_vector(self, value: Any) -> Any:
        if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != self.length:
            return _INVALID
        if not all(self._in_range(_as_float(v)) for v in value):
            return _INVALID
        return tuple(float(v) for v in value)

    def _check_flag(self, value: Any) -> Any:
        return value if isinstance(value, bool) else _INVALID

    def _check_text(self, value: Any) -> Any:
        return str(value) if isinstance(value, str) or hasattr(value, "__fspath__") else _INVALID

    def __repr__(self) -> str:
        return f"<Param {self.qualname} [{self.unit or '-'}] default={self.default!r}>"


_INVALID = object()


def _is_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _as_float(value: Any) -> float | None:
    """``value`` as a float; ``None`` for a non-number and for an integer beyond any float
    (``float`` would raise ``OverflowError`` on 4000 digits)."""
    if not _is_number(value):
        return None
    try:
        return float(value)
    except OverflowError:
        return None


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

    def module(self, value: Any) -> Any:
        """The configured module (or chain) with this parameter set to ``value`` (its unit): a
        ``sal_modules.base.Perturbation``, typed ``Any`` as ``target`` is, since that class sits
        above this module (it makes ``ParamRef``s)."""
        if isinstance(self.target, type):  # a module class: built once, with its defaults elsewhere
            return self.target(**{self.address: value})
        return self.target.with_params(**{self.address: value})

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
