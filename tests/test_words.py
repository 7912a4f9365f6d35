"""One word per concept (issue 24, item 3): the trial budget is ``max_trials`` in
``sal.require``, the ini (``sal_max_trials``) and YAML (``robustness_boundary.max_trials``;
``max_iters``, its old name, still read with a deprecation warning), and ``tolerance`` means the
same wherever it is given: a number in the parameter's unit, ``"10%"`` a percent of the
bracket's larger end (the ini's old bare number still read as a percent, with a warning)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import pytest
from experiment_configs import base_config, write
from plugin_suites import calls, output, project, run

from pytest_sal import tracking_rate
from pytest_sal.engine.requirements import InvalidRequirement, Requirement
from pytest_sal.engine.tolerance import Tolerance, ini_tolerance_percent, parse_tolerance, search_tolerances
from pytest_sal.experiment.boundary import prepare_boundary_search
from pytest_sal.experiment.config import ConfigError, load_config
from pytest_sal.testing import FakeSlam
from sal_adapters.common.errors import SalDeprecationWarning
from sal_modules import fog


def boundary_block(tmp_path: Path, **changes: object) -> dict[str, object]:
    config = base_config(tmp_path)
    block = config["robustness_boundary"]
    block.pop("max_trials")
    block.update(changes)
    return config


# -- the trial budget ------------------------------------------------------------------------------


def test_yaml_max_trials_is_the_trial_budget_and_max_iters_its_old_name_read_with_a_warning(tmp_path: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the new name warns of nothing
        new = load_config(write(tmp_path, boundary_block(tmp_path, max_trials=6), "new.yaml"))
    assert new.robustness_boundary is not None and new.robustness_boundary.max_trials == 6
    old_path = write(tmp_path, boundary_block(tmp_path, max_iters=6), "old.yaml")
    with pytest.warns(SalDeprecationWarning) as caught:
        old = load_config(old_path)
    assert old.robustness_boundary == new.robustness_boundary
    (message,) = [str(w.message) for w in caught]
    assert message.startswith(f"{old_path}: robustness_boundary.max_iters is the old name of robustness_boundary.max_trials")
    assert "rename the key" in message


def test_yaml_max_iters_and_max_trials_together_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="robustness_boundary.max_iters: is the old name of max_trials; give max_trials only"):
        load_config(write(tmp_path, boundary_block(tmp_path, max_trials=6, max_iters=6)))


def test_yaml_max_trials_reaches_the_search_as_sal_require_max_trials(tmp_path: Path) -> None:
    config = load_config(write(tmp_path, boundary_block(tmp_path, max_trials=5)))
    search = prepare_boundary_search(config, FakeSlam(), use_cache=False)
    assert search.search.requirement.options["max_trials"] == 5


# -- the tolerance -------------------------------------------------------------------------------


def test_a_tolerance_is_a_number_in_the_unit_or_a_percent_of_the_larger_end() -> None:
    assert parse_tolerance(5) == Tolerance(absolute=5.0) and parse_tolerance(" 10 %") == Tolerance(percent=10.0)
    assert parse_tolerance("10%").step(20, 22) == pytest.approx(2.2) and parse_tolerance(2).step(20, 22) == 2
    assert parse_tolerance("2.5%").text() == "2.5% of the bracket's larger end" and parse_tolerance(5).text("m") == "5 m"
    for bad in (0, -1, float("nan"), float("inf"), True, "10", "0%", "x%", None, [10]):
        with pytest.raises(ValueError, match="a number > 0 in the parameter's unit, or a percent"):
            parse_tolerance(bad)


def test_the_default_tolerance_is_the_same_in_the_decorator_the_ini_and_yaml(tmp_path: Path) -> None:
    """A requirement and a YAML block that name no tolerance search to 10 % of the bracket's
    larger end, the ini's default (YAML's default was 0.05 in the unit before)."""
    block = boundary_block(tmp_path)
    block["robustness_boundary"].pop("tolerance", None)  # type: ignore[attr-defined]
    config = load_config(write(tmp_path, block))
    assert config.robustness_boundary is not None and config.robustness_boundary.tolerance == "10%"
    decorator = Requirement.build([tracking_rate >= 0.5, fog.visibility_m >= 25])
    ini_default, _ = ini_tolerance_percent("10%")
    assert search_tolerances(decorator.options, ini_default) == (None, 0.1)
    yaml_search = prepare_boundary_search(config, FakeSlam(), use_cache=False)
    assert search_tolerances(yaml_search.search.requirement.options, ini_default) == (None, 0.1)


@pytest.mark.parametrize("given, expected", [(5, (5.0, None)), ("10%", (None, 0.1)), ("2.5%", (None, 0.025))])
def test_the_same_tolerance_means_the_same_in_the_decorator_yaml_and_ini(
    tmp_path: Path, given: float | str, expected: tuple[float | None, float | None]
) -> None:
    """``(absolute, share)`` as the searches take them, from ``sal.require(tolerance=)``, from
    YAML ``robustness_boundary.tolerance`` and, for a percent, from the ini default."""
    decorator = Requirement.build([tracking_rate >= 0.5, fog.visibility_m >= 25], tolerance=given)
    assert search_tolerances(decorator.options, 10.0) == expected
    config = load_config(
        write(tmp_path, base_config(tmp_path, robustness_boundary={**base_config(tmp_path)["robustness_boundary"], "tolerance": given}))
    )
    assert config.robustness_boundary is not None
    yaml_search = prepare_boundary_search(config, FakeSlam(), use_cache=False)
    assert search_tolerances(yaml_search.search.requirement.options, 10.0) == expected
    if isinstance(given, str):
        percent, deprecated = ini_tolerance_percent(given)
        assert deprecated is None and search_tolerances({}, percent) == expected


def test_a_yaml_percent_tolerance_sets_the_linear_sweep_step_and_a_bad_one_names_the_key(tmp_path: Path) -> None:
    block = {**base_config(tmp_path)["robustness_boundary"], "tolerance": "10%"}  # 10 .. 200 m: 20 m steps
    config = load_config(write(tmp_path, base_config(tmp_path, robustness_boundary=block)))
    assert config.robustness_boundary is not None and config.robustness_boundary.tolerance == "10%"
    assert prepare_boundary_search(config, FakeSlam(), use_cache=False).sweep_trials == 11
    for bad in ("10", "-5%", "lots"):
        block["tolerance"] = bad
        with pytest.raises(ConfigError, match=f"robustness_boundary.tolerance: '{bad}' is not valid; must be a number > 0"):
            load_config(write(tmp_path, base_config(tmp_path, robustness_boundary=block)))


def test_the_decorator_takes_a_percent_and_refuses_what_is_neither_form() -> None:
    assert Requirement.build([tracking_rate >= 0.5, fog.visibility_m >= 25], tolerance="10%").options["tolerance"] == "10%"
    with pytest.raises(InvalidRequirement, match="tolerance must be a number > 0 in the parameter's unit, or a percent"):
        Requirement.build([tracking_rate >= 0.5, fog.visibility_m >= 25], tolerance="10")


def test_the_ini_takes_a_percent_and_reads_its_old_bare_number_as_one_with_a_warning() -> None:
    assert ini_tolerance_percent("10%") == (10.0, None) and ini_tolerance_percent(" 5 % ")[0] == 5.0
    percent, deprecated = ini_tolerance_percent("10")
    assert percent == 10.0 and deprecated is not None
    assert "a bare number is the old form, read as 10% of the bracket's larger end; write sal_tolerance = 10%" in deprecated
    for bad in ("x", "0", "0%", "nan", "-3"):
        with pytest.raises(ValueError, match="expected a percent > 0"):
            ini_tolerance_percent(bad)


SUITE = """
import json, pathlib

def record(name, outcome):
    path = pathlib.Path("trials.json")
    found = json.loads(path.read_text()) if path.exists() else {}
    found[name] = [t.value for t in outcome.trials]
    path.write_text(json.dumps(found))

@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25)
def test_default(sal_outcome):
    record("default", sal_outcome)

@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25, tolerance="10%")
def test_percent(sal_outcome):
    record("percent", sal_outcome)

@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25, tolerance=1)
def test_absolute(sal_outcome):
    record("absolute", sal_outcome)
"""


def test_ini_and_decorator_percents_search_alike_and_the_old_ini_number_warns(pytester: pytest.Pytester) -> None:
    project(pytester, SUITE)
    new = run(pytester, [], "--sal-no-history", "-o", "sal_tolerance=10%")
    new.assert_outcomes(passed=3)
    assert "SalDeprecationWarning" not in output(new)
    trials = json.loads((pytester.path / "trials.json").read_text())
    assert trials["default"] == trials["percent"] != trials["absolute"]
    assert len(trials["absolute"]) > len(trials["percent"])  # 1 m is finer than 10% of ~20 m
    ran = calls(pytester)
    old = run(pytester, [], "--sal-no-history", "-o", "sal_tolerance=10")  # no warm start from the first
    old.assert_outcomes(passed=3)
    assert "SalDeprecationWarning: ini option sal_tolerance = 10: a bare number is the old form" in output(old)
    assert json.loads((pytester.path / "trials.json").read_text()) == trials and calls(pytester) == ran  # the same trials, cached


@pytest.mark.parametrize("command", ["boundary", "evaluate"])
def test_the_commands_name_the_system_system_and_still_take_slam(command: str) -> None:
    from pytest_sal.cli.main import build_parser

    parser = build_parser()
    new = parser.parse_args([command, "exp.yaml", "--system", "fake", "--system-option", "a=1"])
    old = parser.parse_args([command, "exp.yaml", "--slam", "fake", "--slam-option", "a=1"])
    assert (new.slam, new.slam_option) == (old.slam, old.slam_option) == ("fake", ["a=1"])
