"""The ``robustness_boundary`` block of an experiment config, checked: its target is a
perturbation of the config (not the clean sequence), its parameter a searchable parameter of
that perturbation (a composite's by its address, ``fog.visibility_m``), its bounds inside the
parameter's search range and in order, ``tolerance`` a number > 0 in the parameter's unit or a
percent ``"N%"`` (``pytest_sal.engine.tolerance``), ``max_trials`` a trial budget (``max_iters``,
its old name, read with a ``SalDeprecationWarning``), ``ate_rmse_fail`` positive, and a noisy
system's ``reliability`` and ``confidence`` probabilities and ``max_runs`` a run budget."""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, Any

from pytest_sal.engine.tolerance import parse_tolerance
from pytest_sal.experiment.schema import BOUNDARY_KEYS, BoundaryConfig, PerturbationConfig, build_module
from pytest_sal.experiment.value_checks import ValueChecks, is_number
from sal_adapters.common.bounded_yaml import quote
from sal_adapters.common.errors import SalDeprecationWarning
from sal_adapters.common.suggest import suggestion
from sal_modules.errors import ParameterError

if TYPE_CHECKING:
    from sal_modules.params import Param

__all__ = ["read_boundary"]

#: the block's key in the config (and the start of every key path in its errors)
BLOCK = "robustness_boundary"
_REQUIRED = ("target_perturbation", "parameter", "lower_bound", "upper_bound")


def read_boundary(checks: ValueChecks, value: Any, perturbations: tuple[PerturbationConfig, ...]) -> BoundaryConfig | None:
    """The block ``value`` (``None`` when the config has none), checked against the config's
    ``perturbations``."""
    if value is None:
        return None
    d = checks.mapping(value, BLOCK, BOUNDARY_KEYS, required=_REQUIRED)
    target = _target(checks, d["target_perturbation"], perturbations)
    parameter = checks.typed(d["parameter"], f"{BLOCK}.parameter", "str")
    spec, owner = _searched_parameter(checks, target, parameter)
    declared = checks.typed(d.get("module", ""), f"{BLOCK}.module", "str")
    if declared and declared != owner:
        raise checks.error(
            f"{BLOCK}.module",
            f"{quote(declared)} does not match the module of {quote(parameter)} in {quote(target.name)}, which is {owner!r}",
        )
    lower, upper = _bounds(checks, d, parameter, spec)
    tolerance = _tolerance(checks, d.get("tolerance", BoundaryConfig.tolerance), spec.search_space().unit)
    fail = checks.typed(d.get("ate_rmse_fail", 1.5), f"{BLOCK}.ate_rmse_fail", "number")
    if not 0 < fail < float("inf"):
        raise checks.error(f"{BLOCK}.ate_rmse_fail", f"{fail:g} m is not valid; must be a number > 0 m")
    probabilities = {}
    for key, lowest in (("reliability", 0.0), ("confidence", 0.5)):
        chance = checks.typed(d.get(key, getattr(BoundaryConfig, key)), f"{BLOCK}.{key}", "number")
        if not lowest < chance < 1:
            raise checks.error(f"{BLOCK}.{key}", f"{chance:g} is not valid; must be a probability between {lowest:g} and 1 (both excluded)")
        probabilities[key] = float(chance)
    name = d.get("name") or f"{target.name}_{parameter.replace('.', '_')}"
    return BoundaryConfig(
        target_perturbation=target.name,
        parameter=parameter,
        lower_bound=lower,
        upper_bound=upper,
        enabled=checks.typed(d.get("enabled", False), f"{BLOCK}.enabled", "bool"),
        name=checks.safe_name(name, f"{BLOCK}.name"),
        module=owner,
        tolerance=tolerance,
        max_trials=_trial_budget(checks, d),
        ate_rmse_fail=fail,
        fail_on_tracking_failure=checks.typed(d.get("fail_on_tracking_failure", True), f"{BLOCK}.fail_on_tracking_failure", "bool"),
        max_runs=checks.search_runs(d.get("max_runs", BoundaryConfig.max_runs), f"{BLOCK}.max_runs"),
        **probabilities,
    )


def _tolerance(checks: ValueChecks, value: Any, unit: str) -> float | str:
    """``tolerance``: a number > 0 in the parameter's unit, or a percent ``"N%"`` of the
    bracket's larger end (kept as ``"N%"``), as ``sal.require(tolerance=)`` takes it."""
    if isinstance(value, str):
        try:
            return f"{parse_tolerance(value).percent:g}%"
        except ValueError as exc:
            raise checks.error(f"{BLOCK}.tolerance", f"{quote(value)} is not valid; {exc}") from None
    tolerance = checks.typed(value, f"{BLOCK}.tolerance", "number")
    if not 0 < tolerance < float("inf"):  # NaN and inf are refused here, naming this key
        raise checks.error(
            f"{BLOCK}.tolerance", f'{tolerance:g} is not valid; must be a number > 0{f" {unit}" if unit else ""} or a percent such as "10%"'
        )
    return tolerance


def _trial_budget(checks: ValueChecks, d: dict[str, Any]) -> int:
    """``max_trials``, the trials of the search (as ``sal.require(max_trials=)`` and ini
    ``sal_max_trials``); its old name ``max_iters`` is read with a ``SalDeprecationWarning``."""
    if "max_iters" not in d:
        return checks.search_trials(d.get("max_trials", BoundaryConfig.max_trials), f"{BLOCK}.max_trials")
    if "max_trials" in d:
        raise checks.error(f"{BLOCK}.max_iters", "is the old name of max_trials; give max_trials only")
    warnings.warn(
        SalDeprecationWarning(
            f"{checks.source}: {BLOCK}.max_iters is the old name of {BLOCK}.max_trials (the trial budget, as in "
            "sal.require(max_trials=) and ini sal_max_trials); it is read as max_trials: rename the key"
        ),
        stacklevel=2,
    )
    return checks.search_trials(d["max_iters"], f"{BLOCK}.max_iters")


def _target(checks: ValueChecks, value: Any, perturbations: tuple[PerturbationConfig, ...]) -> PerturbationConfig:
    """The perturbation ``target_perturbation`` names: one of the config's, not type none."""
    target = checks.typed(value, f"{BLOCK}.target_perturbation", "str")
    by_name = {p.name: p for p in perturbations}
    if target not in by_name:
        raise checks.error(
            f"{BLOCK}.target_perturbation",
            f"{quote(target)} is not a perturbation of this config" + suggestion(target, by_name, "perturbations"),
        )
    if by_name[target].type == "none":
        raise checks.error(
            f"{BLOCK}.target_perturbation", f"{quote(target)} is the clean sequence (type none); it has no parameter to search"
        )
    return by_name[target]


def _searched_parameter(checks: ValueChecks, target: PerturbationConfig, parameter: str) -> tuple[Param, str]:
    """(the declared parameter, the name of the module owning it) of ``parameter`` in
    ``target``: a searchable parameter of its module, or of a composite's step by address."""
    from sal_modules.base import Composite

    module = build_module(target)
    assert module is not None
    spec: Param | None
    if isinstance(module, Composite):
        searchable = [a for a, (_, p) in module.addresses().items() if p.searchable and "@" not in a and "." in a]
        try:
            position, spec = module.param(parameter)
        except ParameterError:
            raise checks.error(
                f"{BLOCK}.parameter",
                f"composite {quote(target.name)} has no parameter {quote(parameter)}" + suggestion(parameter, searchable, "searchable"),
            ) from None
        owner = module.steps[position].name
    else:
        searchable = list(type(module).searchable())
        spec = type(module).parameters().get(parameter)
        owner = module.name
    if spec is None or not spec.searchable:
        raise checks.error(
            f"{BLOCK}.parameter",
            f"{quote(parameter)} is not a searchable parameter of {quote(target.name)} ({module.name})"
            + suggestion(parameter, searchable, "searchable"),
        )
    return spec, owner


def _bounds(checks: ValueChecks, d: dict[str, Any], parameter: str, spec: Param) -> tuple[float, float]:
    """``lower_bound`` and ``upper_bound``: inside ``spec``'s search range (whole numbers for an
    integer parameter), the lower below the upper."""
    scale = spec.search_space()
    unit = f" {scale.unit}" if scale.unit else ""
    allowed = f"{'an integer' if scale.domain == 'integer' else 'a number'} in {scale.min:g} .. {scale.max:g}{unit}"
    bounds = {}
    for key in ("lower_bound", "upper_bound"):
        v = d[key]
        ok = is_number(v) and scale.min <= v <= scale.max and (scale.domain != "integer" or float(v).is_integer())
        if not ok:
            raise checks.error(
                f"{BLOCK}.{key}", f"{quote(v)}{unit if is_number(v) else ''} is not valid; {parameter} search values must be {allowed}"
            )
        bounds[key] = int(v) if scale.domain == "integer" else float(v)
    if not bounds["lower_bound"] < bounds["upper_bound"]:
        raise checks.error(f"{BLOCK}.upper_bound", f"{bounds['upper_bound']:g} must be greater than lower_bound {bounds['lower_bound']:g}")
    return bounds["lower_bound"], bounds["upper_bound"]
