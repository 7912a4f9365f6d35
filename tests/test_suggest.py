"""A misspelt name gets the closest known one (``sal_adapters.common.suggest``), wherever it is typed
in Python: a parameter on a module class or instance, a chain's parameter, a ``sal.at``
address, a module name. The YAML, CLI and ``--sal-compare-fail`` entry points are tested with
their commands (test_experiment, test_module_commands, test_history)."""

from __future__ import annotations

import pytest

import pytest_sal as sal
from pytest_sal.engine.requirements import InvalidRequirement
from sal_adapters.common.plugins import PluginError
from sal_adapters.common.suggest import closest, suggestion
from sal_modules import ParameterError, create, fog, module_class, night

FOG_PARAMETERS = ", ".join(fog.parameters())


def test_suggestion_names_the_closest_else_lists_the_known_names() -> None:
    assert suggestion("visibilty_m", fog.parameters(), "parameters") == "; did you mean 'visibility_m'?"
    assert suggestion("xyz", ["a", "b", "a"], "known") == "; known: a, b"
    assert suggestion("xyz", [], "known") == "; known: none"
    assert closest("tracking_rte", ["ate_rmse", "tracking_rate"]) == "tracking_rate" and closest("q", ["ate_rmse"]) is None


def test_a_misspelt_parameter_on_a_module_class_or_instance() -> None:
    with pytest.raises(AttributeError, match=r"^fog has no parameter 'visibilty_m'; did you mean 'visibility_m'\?$"):
        fog.visibilty_m
    with pytest.raises(AttributeError, match=rf"^fog has no parameter 'xyz'; parameters: {FOG_PARAMETERS}$"):
        fog.xyz
    with pytest.raises(AttributeError, match=r"^fog has no parameter 'visibilty_m'; did you mean 'visibility_m'\?$"):
        fog(visibility_m=30).visibilty_m
    assert not hasattr(fog, "_private") and not hasattr(fog, "qualname")  # probes still just fail
    with pytest.raises(ParameterError, match=r"fog has no parameter 'visibilty_m'; did you mean 'visibility_m'\?"):
        fog(visibilty_m=30)
    with pytest.raises(ParameterError, match=r"fog has no parameter 'visibilty_m'; did you mean 'visibility_m'\?"):
        fog().ref("visibilty_m")


def test_a_misspelt_parameter_of_a_chain() -> None:
    with pytest.raises(AttributeError, match=r"composite night>>fog has no parameter 'visibilty_m'; did you mean 'visibility_m'\?"):
        (night() >> fog).visibilty_m
    with pytest.raises(ParameterError, match=r"has no parameter 'fog.visibilty_m'; did you mean 'fog.visibility_m'\?"):
        (night() >> fog).ref("fog.visibilty_m")


def test_a_misspelt_module_name() -> None:
    with pytest.raises(
        PluginError, match=r"^unknown perturbation module 'fgo'; did you mean 'fog'\? \(entry-point group 'sal.perturbations'\)$"
    ):
        module_class("fgo")
    with pytest.raises(PluginError, match=r"unknown perturbation module 'xyz'; known: bandwidth, .*fog.*"):
        create("xyz")
    import sal_modules

    with pytest.raises(AttributeError, match=r"^module 'sal_modules' has no attribute 'fgo'; did you mean 'fog'\?$"):
        sal_modules.fgo
    with pytest.raises(AttributeError, match=r"^module 'pytest_sal' has no attribute 'ate_rmce'; did you mean 'ate_rmse'\?$"):
        sal.ate_rmce


@pytest.mark.parametrize(
    ("address", "message"),
    [
        ("fog.visibilty_m", "sal.at(): no parameter 'fog.visibilty_m' (fog has no parameter 'visibilty_m'; did you mean 'visibility_m'?)"),
        ("fgo.visibility_m", "sal.at(): no parameter 'fgo.visibility_m' (unknown perturbation module 'fgo'; did you mean 'fog'?"),
        ("fog.xyz", f"sal.at(): no parameter 'fog.xyz' (fog has no parameter 'xyz'; parameters: {FOG_PARAMETERS})"),
    ],
)
def test_a_misspelt_sal_at_address(address: str, message: str) -> None:
    with pytest.raises(InvalidRequirement) as info:
        sal.at(**{address: 30})
    assert str(info.value).startswith(message)
