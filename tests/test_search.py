"""Boundary search (pure) and the requirement language."""

from __future__ import annotations

import math
import re

import pytest

import pytest_sal as sal
from pytest_sal import InvalidRequirement, ate_rmse, tracking_rate
from pytest_sal.engine.execution.trial_runner import NOISY_RUNS, RunPolicy
from pytest_sal.engine.outcomes.outcome import Trial
from pytest_sal.engine.requirements import Requirement
from pytest_sal.engine.search.bisection import SearchSpace, boundary_search
from pytest_sal.testing import FakeSlam
from sal_modules import fog, frame_drop, motion_blur, night, rain, sensor_noise

FOG = SearchSpace(mild=100_000.0, severe=1.0)  # visibility gets worse when lower


def threshold_system(boundary: float, worse_lower: bool = True):
    """Passes exactly on the mild side of ``boundary``; records what it was asked."""
    asked: list[float] = []

    def evaluate(value: float) -> Trial:
        asked.append(value)
        return Trial(value, value >= boundary if worse_lower else value <= boundary)

    return evaluate, asked


def test_edge_first_then_bisect_to_tolerance() -> None:
    evaluate, asked = threshold_system(14.3)
    result = boundary_search(evaluate, FOG, edge=25, tolerance=2, max_trials=10)
    assert asked[0] == 25 and result.edge_passed
    assert result.termination == "tolerance"
    assert result.fail_value < 14.3 <= result.pass_value and result.pass_value - result.fail_value <= 2
    assert not result.contradictions


def test_a_failing_edge_bisects_toward_the_mild_end() -> None:
    evaluate, asked = threshold_system(40.0)
    result = boundary_search(evaluate, SearchSpace(mild=200.0, severe=1.0), edge=25, tolerance=2, max_trials=12)
    assert not result.edge_passed and asked[1] == 200.0  # the far end on the mild side
    assert result.fail_value < 40.0 <= result.pass_value and result.termination == "tolerance"


def test_not_bracketed_when_the_far_end_agrees_with_the_edge() -> None:
    result = boundary_search(lambda v: Trial(v, True), FOG, edge=25, tolerance=2)
    assert result.termination == "not_bracketed" and result.pass_value == 1.0 and result.fail_value is None
    result = boundary_search(lambda v: Trial(v, False), FOG, edge=25, tolerance=2)
    assert result.termination == "not_bracketed" and result.fail_value == 100_000.0 and result.pass_value is None


def test_max_trials_stops_the_search_with_the_bracket_so_far() -> None:
    evaluate, asked = threshold_system(14.3)
    result = boundary_search(evaluate, FOG, edge=25, tolerance=0.01, max_trials=4)
    assert len(asked) == 4 and result.termination == "max_trials"
    assert result.fail_value < 14.3 <= result.pass_value


def test_integer_domain_stops_at_neighbours() -> None:
    evaluate, _ = threshold_system(37, worse_lower=False)
    result = boundary_search(evaluate, SearchSpace(mild=0, severe=100, domain="integer"), edge=20, tolerance=0.5, max_trials=20)
    assert (result.pass_value, result.fail_value) == (37, 38) and result.termination == "domain_resolution"
    assert all(float(t.value).is_integer() for t in result.trials)


def test_warm_start_needs_three_trials_when_nothing_changed() -> None:
    evaluate, _ = threshold_system(14.3)
    first = boundary_search(evaluate, FOG, edge=25, tolerance=2, max_trials=10)
    evaluate, asked = threshold_system(14.3)
    again = boundary_search(evaluate, FOG, edge=25, tolerance=2, max_trials=10, warm_start=(first.pass_value, first.fail_value))
    assert len(asked) == 3 and (again.pass_value, again.fail_value) == (first.pass_value, first.fail_value)
    assert len(first.trials) >= 6  # the cold search needed twice as many


def test_geometric_bisection_over_decades() -> None:
    evaluate, asked = threshold_system(500.0)
    boundary_search(evaluate, FOG, edge=25, tolerance=1, max_trials=3)
    # edge fails, the mild end passes, the next try is the geometric mean, not 50012 m
    assert asked == [25, 100_000.0, pytest.approx(math.sqrt(25 * 100_000.0))]


def test_contradictions_are_reported() -> None:
    # passes at 25 m and (oddly) at 10 m, fails at 15 m: the warm start visits both
    result = boundary_search(lambda v: Trial(v, v >= 20 or v == 10), FOG, edge=25, tolerance=2, max_trials=6, warm_start=(10.0, 15.0))
    assert "10 passed but the milder 15 failed" in result.contradictions


def test_run_policy_is_noisy_above_one_run_per_trial() -> None:
    # runs given decide; not given: 1 for a deterministic system, NOISY_RUNS for a noisy one
    steady, noisy = FakeSlam(), FakeSlam(flaky=0.3)
    assert not RunPolicy.for_system(steady, None).noisy and RunPolicy.for_system(noisy, None).max_runs == NOISY_RUNS
    assert RunPolicy.for_system(steady, 3).noisy and RunPolicy.for_system(steady, 3).max_runs == 3
    assert not RunPolicy.for_system(noisy, 1).noisy and not RunPolicy().noisy


# -- the requirement language ------------------------------------------------------------------
def test_requirement_reads_like_its_source() -> None:
    req = Requirement.build([ate_rmse < 1.5, tracking_rate >= 0.9, fog.visibility_m >= 25])
    assert str(req) == "ate_rmse < 1.5 m and tracking_rate >= 0.9 wherever fog.visibility_m >= 25 m"
    assert req.holds({"ate_rmse": 1.2, "tracking_rate": 0.95})
    assert not req.holds({"ate_rmse": 1.2, "tracking_rate": None})  # a missing metric fails
    assert [str(c) for c in req.failed({"ate_rmse": 2.0, "tracking_rate": 0.95})] == ["ate_rmse < 1.5 m"]


def test_chain_parameters_and_one_unit_for_every_bound() -> None:
    bound = (night() >> fog).visibility_m >= 40
    assert str(bound) == "(night>>fog).visibility_m >= 40 m"
    chain = bound.ref.module(30.0)
    assert chain.steps[1].visibility_m == 30.0 and chain.steps[0].name == "night"
    # the unit `sal modules` prints is the unit of the bound and of the module the search runs
    drop = Requirement.build([ate_rmse < 1, frame_drop.drop_rate <= 0.3]).envelope
    assert str(drop) == "frame_drop.drop_rate <= 0.3" and drop.ref.module(drop.value).drop_rate == 0.3
    dark = Requirement.build([ate_rmse < 1, night.illuminance_lux >= 5]).envelope
    assert str(dark) == "night.illuminance_lux >= 5 lx" and dark.ref.module(dark.value).illuminance_lux == 5.0
    iso = Requirement.build([ate_rmse < 1, sensor_noise.iso <= 800]).envelope
    assert str(iso) == "sensor_noise.iso <= 800 ISO" and iso.ref.module(iso.value).iso == 800.0
    with pytest.raises(InvalidRequirement, match=r"drop_rate = 30.0 is not valid.* must be a number in 0 .. 1"):
        Requirement.build([ate_rmse < 1, frame_drop.drop_rate <= 30])


@pytest.mark.parametrize(
    ("bound", "reason"),
    [
        (lambda: night.illuminance_lux >= 5000, "the auto-exposure makes up for all the light lost"),
        (lambda: frame_drop.drop_rate <= 0, "drops no frame"),
        (lambda: motion_blur.speed_kmh <= 0, "does not move the camera"),
    ],
    ids=["night-brighter-than-the-camera-needs", "no-drops", "no-speed"],
)
def test_an_edge_that_cannot_change_the_frames_is_refused(bound, reason: str) -> None:
    with pytest.raises(InvalidRequirement, match=f"the envelope's edge cannot change the frames .*{reason}"):
        Requirement.build([ate_rmse < 1, bound()])


def test_a_geometric_search_speaks_the_parameter_unit_and_a_relative_tolerance_suits_decades() -> None:
    # bandwidth 0.01 .. 200 Mbit/s, the system fails below 0.085: the old absolute default
    # (10 % of the 1 Mbit/s edge) stopped at 0.01-0.1 after 3 trials
    evaluate, _asked = threshold_system(0.085)
    space = SearchSpace(mild=200.0, severe=0.01, scale="log")
    result = boundary_search(evaluate, space, edge=1.0, rel_tolerance=0.1, max_trials=20)
    assert result.fail_value < 0.085 <= result.pass_value and result.pass_value / result.fail_value <= 1.1 + 1e-9
    lux = SearchSpace(mild=100_000.0, severe=0.01, scale="log")
    assert lux.midpoint(1.0, 100.0) == pytest.approx(10.0) and lux.midpoint(2.0, 8.0) == pytest.approx(4.0)


@pytest.mark.parametrize(
    ("items", "message"),
    [
        ([ate_rmse < 1.5, fog.visibility_m <= 25], "write fog.visibility_m >= 25"),
        ([ate_rmse < 1.5, fog.heterogeneity >= 0.1], "fog.heterogeneity is not searchable"),
        ([ate_rmse < 1.5, fog.visibility_m >= 25, rain.intensity_mm_h <= 5], "searches one parameter; got 2 envelopes"),
        ([fog.visibility_m >= 25], "needs at least one metric criterion"),
        ([ate_rmse, fog.visibility_m >= 25], "ate_rmse alone is not a criterion"),
        ([ate_rmse < 1.5, fog.visibility_m >= 0.5], "visibility_m = 0.5 m is not valid"),
    ],
)
def test_misuse_says_what_to_write_instead(items, message: str) -> None:
    with pytest.raises(InvalidRequirement, match=message.replace("(", r"\(").replace(")", r"\)")):
        Requirement.build(items)


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: ate_rmse < 0, "ate_rmse < 0 m can never hold: ate_rmse is 0 m or more; pick a threshold inside that range"),
        (lambda: ate_rmse >= 0, "ate_rmse >= 0 m always holds, so it tests nothing: ate_rmse is 0 m or more"),
        (lambda: tracking_rate >= 1.5, "tracking_rate >= 1.5 can never hold: tracking_rate is 0 .. 1"),
        (lambda: tracking_rate <= 1, "tracking_rate <= 1 always holds, so it tests nothing: tracking_rate is 0 .. 1"),
        (
            lambda: sal.require(ate_rmse < 1, fog.visibility_m >= 25, search_range=(0.1, 30)),
            "search_range (0.1, 30) m leaves the valid range of fog.visibility_m, 1 .. 100000 m",
        ),
        (
            lambda: sal.require(ate_rmse < 1, fog.visibility_m >= 25, search_range=(30, 30)),
            "search_range (30, 30) must be two finite numbers low < high, in m",
        ),
        (
            lambda: sal.require(ate_rmse < 1, fog.visibility_m >= 25, reliability=1.0),
            "reliability must be a probability between 0 and 1 (both excluded), got 1.0",
        ),
        (
            lambda: sal.require(ate_rmse < 1, fog.visibility_m >= 25, confidence=0.4),
            "confidence must be a probability between 0.5 and 1 (both excluded), got 0.4",
        ),
        (lambda: sal.require(ate_rmse < 1, fog.visibility_m >= 25, confidence=float("nan")), "confidence must be a probability"),
        (lambda: sal.require(ate_rmse < 1, fog.visibility_m >= 25, max_runs=0), "max_runs must be a whole number >= 1, got 0"),
    ],
    ids=["ate<0", "ate>=0", "rate>=1.5", "rate<=1", "range-outside", "range-empty", "reliability=1", "confidence=0.4", "nan", "runs=0"],
)
def test_a_requirement_that_cannot_fail_or_cannot_pass_is_refused(build, message: str) -> None:
    with pytest.raises(InvalidRequirement, match=re.escape(message)):
        build()


def test_thresholds_at_the_ends_of_a_metric_still_test_something() -> None:
    assert str(tracking_rate >= 1) == "tracking_rate >= 1" and str(ate_rmse <= 0) == "ate_rmse <= 0 m"
    assert str(tracking_rate > 0) == "tracking_rate > 0"


def test_comparing_with_a_string_is_an_error_naming_the_unit() -> None:
    with pytest.raises(InvalidRequirement, match=r"ate_rmse < '1.5': compare a metric with a finite number in m"):
        ate_rmse < "1.5"  # noqa: B015
    with pytest.raises(TypeError, match=r"compare a parameter with a number in m"):
        fog.visibility_m >= "25"  # noqa: B015


def test_sal_at_and_sweep_values_are_the_module_values_in_its_unit() -> None:
    # sal.at(night.illuminance_lux, 1) ran at 10 lx while its id said 1 (a log10 search unit)
    @sal.at(night.illuminance_lux, 1)
    @sal.require(tracking_rate >= 0.9)
    def test_dark(sal_trial): ...

    @sal.sweep(sensor_noise.iso, L=200, H=6400)
    @sal.require(tracking_rate >= 0.9)
    def test_iso(sal_trial): ...

    ref, levels = next(m.args for m in test_dark.pytestmark if m.name == "sal_sweep")
    assert levels == {"at": 1.0} and ref.module(levels["at"]).illuminance_lux == 1.0
    ref, levels = next(m.args for m in test_iso.pytestmark if m.name == "sal_sweep")
    assert [ref.module(v).iso for v in levels.values()] == [200.0, 6400.0]
    assert sal.sweep(sensor_noise.iso, L=50)  # below the search range, still a valid ISO
    with pytest.raises(
        InvalidRequirement,
        match=r"sal.sweep level L: sensor_noise.iso: iso = 5.0 ISO is not valid; .* must be a number in 25 .. 409600 ISO",
    ):
        sal.sweep(sensor_noise.iso, L=5)
