"""The report tests' outcomes (report_outcomes.py) are ones the plugin could write: checked
against the real module, system and dataset registries and the real requirement and regression
code, so a renamed module, parameter, unit, system or dataset kind breaks a test instead of
leaving the report tests on made-up names."""

from __future__ import annotations

import dataclasses
import operator
import re
from typing import Any

import pytest
from report_outcomes import flaky, fog, never_passed, rain, regressed, sweep_point

from pytest_sal.engine.outcomes.outcome import Outcome
from pytest_sal.engine.requirements import METRICS, Requirement
from pytest_sal.history.regression import parse_compare_fail, regressions
from sal_adapters import DATASETS
from sal_modules import Composite
from sal_modules.registry import module_class
from sal_wrappers import SYSTEMS

COMPARISONS = {"<": operator.lt, "<=": operator.le, ">": operator.gt, ">=": operator.ge}
#: the plugin's reproduction line (pytest_sal.engine.search.requirement_search)
REPRODUCTION = re.compile(
    r"@sal\.at\((?P<label>.+), (?P<value>[^,]+)\)  # (?P<unit>[^;]+); seed \d+, up to \d+ run\(s\), "
    r"system (?P<system>\S+), dataset (?P<dataset>\S+)"
)


def declared_parameter(label: str) -> Any:
    """The parameter ``label`` names (``fog.visibility_m``, ``(night>>fog).visibility_m``), from
    the module registry; a module or parameter that does not exist raises."""
    owner, _, name = label.rpartition(".")
    if owner.startswith("("):
        return getattr(Composite([module_class(step) for step in owner.strip("()").split(">>")]), name)
    return getattr(module_class(owner), name)


@pytest.mark.parametrize("outcome", [fog(), rain(), flaky(), regressed(), never_passed(), sweep_point()], ids=lambda o: o.test_id)
def test_fixtures_name_real_parameters_requirements_systems_and_datasets(outcome: Outcome) -> None:
    """The parameter exists with that unit and direction, the requirement and envelope are what
    ``sal.require`` makes of the criteria and the edge, the system and the dataset kind are
    registered, and the reproduction and regression lines are the plugin's."""
    parameter = declared_parameter(outcome.parameter)
    declared = getattr(parameter, "param", parameter)  # a chain's parameter is a reference to a module's
    assert (getattr(parameter, "label", None) or declared.qualname) == outcome.parameter
    assert declared.worse == outcome.worse and outcome.boundary.unit in ("", declared.unit)
    assert all(declared.min <= trial.value <= declared.max for trial in outcome.trials)
    items = [COMPARISONS[op](METRICS[name], threshold) for name, op, threshold in outcome.criteria]
    if outcome.envelope:
        op, value = outcome.envelope.split()[:2]
        items.append(COMPARISONS[op](parameter, float(value)))
        assert float(value) == outcome.edge
    requirement = Requirement.build(items)
    assert str(requirement) == outcome.requirement
    assert (requirement.envelope.condition if requirement.envelope is not None else "") == outcome.envelope
    assert outcome.system in SYSTEMS.names() and outcome.dataset.split("/")[0] in DATASETS.names()
    if outcome.reproduction:
        line = REPRODUCTION.fullmatch(outcome.reproduction)
        assert line is not None, outcome.reproduction
        unit = declared.unit or "no unit"
        assert (line["label"], float(line["value"]), line["unit"]) == (outcome.parameter, outcome.edge, unit)
        assert (line["system"], line["dataset"]) == (outcome.system, outcome.dataset)
    if outcome.regression:
        assert outcome.previous is not None
        previous = dataclasses.replace(outcome, boundary=outcome.previous, regression=None)
        assert "; ".join(regressions([parse_compare_fail("boundary:10%")], outcome, previous)) == outcome.regression
