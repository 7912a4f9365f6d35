"""Decorators and helpers users write robustness tests with: ``sal.require``, ``sal.sweep``,
``sal.at`` and ``sal.dataset_fixture``.

>>> import pytest_sal as sal
>>> from pytest_sal import ate_rmse
>>> from sal_modules import fog
>>> @sal.require(ate_rmse < 1.5, fog.visibility_m >= 25)
... def test_fog(sal_outcome): ...
>>> [mark.name for mark in test_fog.pytestmark]
['sal', 'sal_require', 'usefixtures']

Each decorator validates what it is given when the test module is imported (so pytest reports
misuse at collection) and attaches registered marks: the marks are what the plugin reads
(``requirement_of``, ``levels_of``); ``pytest.mark.sal_require(requirement)`` written by hand
is the same requirement.
"""

from __future__ import annotations

import numbers
from collections.abc import Callable
from typing import Any, TypeVar

import pytest

from pytest_sal.engine.requirements import InvalidRequirement, Requirement
from sal_adapters.common.errors import SalError
from sal_modules.params import ParamRef

__all__ = ["at", "dataset_fixture", "levels_of", "require", "requirement_of", "sweep"]

F = TypeVar("F", bound=Callable[..., Any])


def require(
    *criteria_and_envelope: Any,
    tolerance: float | str | None = None,
    max_trials: int | None = None,
    runs: int | None = None,
    search_range: tuple[float, float] | None = None,
    seed: int | None = None,
    reliability: float | None = None,
    confidence: float | None = None,
    max_runs: int | None = None,
) -> Callable[[F], F]:
    """The system must meet every criterion wherever the envelope holds.

    ``@sal.require(ate_rmse < 1.5, fog.visibility_m >= 25)`` makes the test one boundary search:
    the envelope's edge (25 m) decides pass or fail, then bisection between the edge and the far
    end of the search range locates the failure boundary within ``tolerance`` (a number: in the
    parameter's unit; ``"10%"``: of the bracket's larger end; default: ini ``sal_tolerance``,
    10%) in at most ``max_trials`` trials (ini ``sal_max_trials``) of ``runs`` runs each. Without an envelope, use it with ``sal.sweep`` or ``sal.at``.

    A noisy system (ORB-SLAM3) holds a requirement with a probability that falls with
    severity: the test passes when ``p(edge) >= reliability`` at ``confidence`` (one-sided;
    ini ``sal_reliability``, ``sal_confidence``), fails when ``p(edge) < reliability`` at that
    confidence, and is inconclusive when ``max_runs`` runs (ini ``sal_max_runs``) did not
    settle it; the outcome reports ``s_R``, the most severe value where ``p >= reliability``.
    """
    given = {
        "tolerance": tolerance,
        "max_trials": max_trials,
        "runs": runs,
        "search_range": search_range,
        "seed": seed,
        "reliability": reliability,
        "confidence": confidence,
        "max_runs": max_runs,
    }
    options = {k: v for k, v in given.items() if v is not None}
    requirement = Requirement.build(criteria_and_envelope, **options)

    def decorate(function: F) -> F:
        if _marked(function, "sal_require"):
            raise InvalidRequirement(f"{function.__name__}: sal.require() is applied twice; give one requirement per test")
        marks = [pytest.mark.sal, pytest.mark.sal_require(requirement)]
        if requirement.envelope is not None and not _marked(function, "sal_sweep"):
            marks.append(pytest.mark.usefixtures("sal_outcome"))
        for mark in marks:
            function = mark(function)
        return function

    return decorate


def sweep(param: Any, **levels: float) -> Callable[[F], F]:
    """Run the test once per named severity level: ``@sal.sweep(rain.intensity_mm_h, L=3, M=10)``
    gives items ``[L-rain.intensity_mm_h=3]``, ``[M-rain.intensity_mm_h=10]`` (``-k "[M-"``
    selects one); the ``sal_trial`` fixture holds that level's trial (metrics, verdict). Put it
    above ``@sal.require``."""
    ref = _ref(param, "sal.sweep")
    if not levels:
        raise InvalidRequirement(f"sal.sweep({ref.label}) needs named levels, e.g. sal.sweep({ref.label}, L=3, M=10, H=50)")
    for name, value in levels.items():
        _check_value(ref, value, f"sal.sweep level {name}")

    def decorate(function: F) -> F:
        return pytest.mark.sal(pytest.mark.sal_sweep(ref, dict(levels))(function))

    return decorate


def at(param: Any = None, value: float | None = None, **by_address: float) -> Callable[[F], F]:
    """Run the test at one explicit point: ``@sal.at(fog.visibility_m, 30)`` (or
    ``@sal.at(**{"fog.visibility_m": 30})``); ``sal_trial`` holds the trial. Explicit points
    always run, like hypothesis' ``@example``."""
    if param is None:
        if len(by_address) != 1:
            raise InvalidRequirement(
                'sal.at() takes one parameter and value: sal.at(fog.visibility_m, 30) or sal.at(**{"fog.visibility_m": 30})'
            )
        ((address, value),) = by_address.items()
        param = _resolve(address)
    ref = _ref(param, "sal.at")
    if value is None:
        raise InvalidRequirement(
            f"sal.at({ref.label}) needs a value in {ref.unit or 'its unit'}, e.g. sal.at({ref.label}, {ref.param.default!r})"
        )
    _check_value(ref, value, "sal.at")

    def decorate(function: F) -> F:
        return pytest.mark.sal(pytest.mark.sal_sweep(ref, {"at": float(value)})(function))

    return decorate


def dataset_fixture(kind: str, path: str | None = None, *, scope: str = "session", **options: Any) -> Any:
    """A ``sal_dataset`` fixture for a real dataset, to assign in ``conftest.py``::

        sal_dataset = sal.dataset_fixture("kitti", "/data/kitti", sequence="07", max_frames=200)

    The dataset is opened once per session; a missing folder is one clear error naming it.
    """

    @pytest.fixture(scope=scope)  # type: ignore[call-overload]
    def sal_dataset() -> Any:
        from sal_adapters import open_dataset

        return open_dataset(kind, path, **options)

    return sal_dataset


def requirement_of(node: pytest.Item) -> Requirement | None:
    """The requirement of a test: its ``sal_require`` mark (``sal.require``), or ``None``."""
    mark = node.get_closest_marker("sal_require")
    return None if mark is None else mark.args[0]


def levels_of(node: pytest.Item) -> tuple[ParamRef, dict[str, float]] | None:
    """The parameter and named levels of a test: its ``sal_sweep`` mark (``sal.sweep``,
    ``sal.at``, whose one level is ``at``), or ``None``."""
    mark = node.get_closest_marker("sal_sweep")
    return None if mark is None else (mark.args[0], mark.args[1])


def _marked(function: Callable[..., Any], name: str) -> bool:
    """``function`` already carries the mark ``name`` (pytest keeps a function's marks in ``pytestmark``)."""
    return any(mark.name == name for mark in getattr(function, "pytestmark", ()))


def _ref(param: Any, where: str) -> ParamRef:
    if isinstance(param, ParamRef):
        ref = param
    elif hasattr(param, "ref") and hasattr(param, "qualname"):  # a Param on a module class
        ref = param.ref()
    else:
        raise InvalidRequirement(f"{where}() takes a searchable parameter such as fog.visibility_m, got {param!r}")
    if not ref.param.searchable:
        raise InvalidRequirement(f"{where}({ref.label}): the parameter is not searchable; pick one that `sal modules` lists as searchable")
    return ref


def _check_value(ref: ParamRef, value: Any, where: str) -> None:
    if not isinstance(value, numbers.Real) or isinstance(value, bool):
        raise InvalidRequirement(f"{where}: {ref.label} needs a number in {ref.unit or 'its unit'}, got {value!r}")
    try:  # any valid value, in the parameter's unit (the search range only bounds searches)
        ref.param.validate(float(value), ref.label)
    except SalError as exc:
        raise InvalidRequirement(f"{where}: {exc}") from None


def _resolve(address: str) -> ParamRef:
    """``"fog.visibility_m"`` as a ``ParamRef``; a typo in the module or the parameter names the
    closest one: ``sal.at(): no parameter 'fog.visibilty_m' (fog has no parameter ...; did you mean ...)``."""
    from sal_modules import module_class

    module, _, name = address.partition(".")
    try:
        cls = module_class(module)
        if name not in cls.parameters():
            raise LookupError(cls.unknown_parameter(name))
    except (SalError, LookupError) as exc:  # re-raised as a requirement error naming the address
        raise InvalidRequirement(f"sal.at(): no parameter {address!r} ({exc})") from None
    return cls.parameters()[name].ref()
