"""Regression checks against a previous run: ``--compare-fail`` parsing, boundary and metric
checks (relative and absolute, worse lower or higher, unbracketed), the failing checks listed,
and the warm start and edge trial taken from the history."""

from __future__ import annotations

import argparse

import pytest
from history_outcomes import drop, fog

from pytest_sal.history.regression import BoundaryCheck, MetricCheck, edge_trial, parse_compare_fail, regressions, warm_start

# -- regression checks ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("boundary:10%", BoundaryCheck(10.0, True)),
        ("boundary:2.5", BoundaryCheck(2.5, False)),
        ("ate_rmse:0.2", MetricCheck("ate_rmse", 0.2, False)),
        (" ATE_RMSE : 15 % ", MetricCheck("ate_rmse", 15.0, True)),
        ("tracking_rate:0", MetricCheck("tracking_rate", 0.0, False)),
    ],
)
def test_parse_compare_fail_valid(text: str, expected: object) -> None:
    check = parse_compare_fail(text)
    assert check == expected
    assert parse_compare_fail(str(check)) == expected


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("boundary", "'boundary': expected WHAT:LIMIT"),
        ("ate:0.2", "'ate:0.2': unknown quantity 'ate'"),
        ("tracking_rte:0.1", "'tracking_rte:0.1': unknown quantity 'tracking_rte' (did you mean 'tracking_rate'?)"),
        ("boundary:ten%", "'boundary:ten%': the limit 'ten%' is not a number"),
        ("boundary:", "'boundary:': the limit '' is not a number"),
        ("ate_rmse:-1", "'ate_rmse:-1': the limit must be a finite number >= 0, got '-1'"),
        ("boundary:inf%", "'boundary:inf%': the limit must be a finite number >= 0, got 'inf%'"),
    ],
)
def test_parse_compare_fail_invalid(text: str, reason: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError) as info:
        parse_compare_fail(text)
    message = str(info.value)
    assert message.startswith(reason + "; valid forms: boundary:10% (")
    for form in ("boundary:2.5 (", "METRIC:0.2 (", "METRIC:15% (", "ate_rmse, rpe_trans, rpe_rot, tracking_rate, scale_error"):
        assert form in message


def test_parse_compare_fail_as_argparse_type(capsys: pytest.CaptureFixture[str]) -> None:
    parser = argparse.ArgumentParser(prog="p")
    parser.add_argument("--sal-compare-fail", type=parse_compare_fail, action="append")
    assert parser.parse_args(["--sal-compare-fail=boundary:5%"]).sal_compare_fail == [BoundaryCheck(5.0, True)]
    with pytest.raises(SystemExit):
        parser.parse_args(["--sal-compare-fail=speed:3"])
    assert "argument --sal-compare-fail: 'speed:3': unknown quantity 'speed'; valid forms:" in capsys.readouterr().err


def test_boundary_relative_check_worse_lower() -> None:
    check = parse_compare_fail("boundary:10%")
    assert check.fails(fog(22, 20), fog(15, 14)) == (
        "fog.visibility_m boundary moved toward the requirement: passed down to 15 m before, now only down to 22 m (+47 %, limit 10 %)"
    )
    assert check.fails(fog(16.4, 15), fog(15, 14)) is None  # +9.3 %: within the limit
    assert check.fails(fog(16.5, 15), fog(15, 14)) is None  # exactly +10 %: not more than the limit
    assert check.fails(fog(5, 4), fog(15, 14)) is None  # an improvement never fails
    assert check.fails(fog(30, 28, verdict="failed"), fog(15, 14)) == (
        "fog.visibility_m boundary moved toward the mild side, past the requirement: passed down to 15 m before, "
        "now only down to 30 m (+100 %, limit 10 %)"
    )


def test_boundary_checks_worse_higher() -> None:
    relative, absolute = parse_compare_fail("boundary:10%"), parse_compare_fail("boundary:2.5")
    assert relative.fails(drop(20, 22), drop(30, 32)) == (
        "frame_drop.drop_rate boundary moved toward the requirement: passed up to 30 % before, now only up to 20 % (-33 %, limit 10 %)"
    )
    assert absolute.fails(drop(27, 29), drop(30, 32)) == (
        "frame_drop.drop_rate boundary moved toward the requirement: passed up to 30 % before, now only up to 27 % (-3 %, limit 2.5 %)"
    )
    assert absolute.fails(drop(28, 30), drop(30, 32)) is None  # -2: within 2.5
    assert relative.fails(drop(45, 47), drop(30, 32)) is None  # improvement
    assert absolute.fails(drop(45, 47), drop(30, 32)) is None


def test_boundary_absolute_check_worse_lower() -> None:
    check = parse_compare_fail("boundary:2.5")
    assert check.fails(fog(18, 17), fog(15, 14)) == (
        "fog.visibility_m boundary moved toward the requirement: passed down to 15 m before, now only down to 18 m (+3 m, limit 2.5 m)"
    )
    assert check.fails(fog(17, 16), fog(15, 14)) is None
    assert check.fails(fog(1, None), fog(15, 14)) is None  # now passes everywhere searched: better


def test_boundary_check_unbracketed_and_not_comparable() -> None:
    check = parse_compare_fail("boundary:10%")
    assert check.fails(fog(None, 40, verdict="failed"), fog(15, 14)) == (
        "fog.visibility_m boundary moved toward the mild side: passed down to 15 m before, now failed everywhere searched (limit 10 %)"
    )
    assert check.fails(fog(None, 40), fog(None, 40)) is None  # never passed: cannot get worse
    assert check.fails(fog(50, 45, edge=60), fog(15, 14)) is None  # the requirement changed
    assert check.fails(fog(50, 45, parameter="rain.rate"), fog(15, 14)) is None


def test_metric_checks_fire_and_not() -> None:
    absolute, relative = parse_compare_fail("ate_rmse:0.2"), parse_compare_fail("ate_rmse:15%")
    assert absolute.fails(fog(15, 14, ate=0.6), fog(15, 14, ate=0.3)) == (
        "ate_rmse at the envelope's edge (fog.visibility_m = 25 m) got worse: 0.3 m before, now 0.6 m (+0.3 m, limit 0.2 m)"
    )
    assert absolute.fails(fog(15, 14, ate=0.45), fog(15, 14, ate=0.3)) is None
    assert relative.fails(fog(15, 14, ate=0.36), fog(15, 14, ate=0.3)) == (
        "ate_rmse at the envelope's edge (fog.visibility_m = 25 m) got worse: 0.3 m before, now 0.36 m (+20 %, limit 15 %)"
    )
    assert relative.fails(fog(15, 14, ate=0.33), fog(15, 14, ate=0.3)) is None
    assert absolute.fails(fog(15, 14, ate=0.1), fog(15, 14, ate=0.6)) is None  # improvement
    assert relative.fails(fog(15, 14, ate=None), fog(15, 14, ate=0.3)) == (
        "ate_rmse at the envelope's edge (fog.visibility_m = 25 m) got worse: 0.3 m before, now not available (the runs failed)"
    )
    assert relative.fails(fog(15, 14, ate=0.3), fog(15, 14, ate=None)) is None


def test_metric_check_higher_is_better() -> None:
    check = parse_compare_fail("tracking_rate:0.05")
    assert check.fails(drop(30, 32, rate=0.85), drop(30, 32, rate=0.95)) == (
        "tracking_rate at the envelope's edge (frame_drop.drop_rate = 10 %) got worse: 0.95 before, now 0.85 (-0.1, limit 0.05)"
    )
    assert check.fails(drop(30, 32, rate=0.92), drop(30, 32, rate=0.95)) is None
    assert check.fails(drop(30, 32, rate=1.0), drop(30, 32, rate=0.8)) is None  # improvement


def test_regressions_lists_every_failing_check() -> None:
    checks = [parse_compare_fail(t) for t in ("boundary:10%", "ate_rmse:0.2", "tracking_rate:0.5")]
    found = regressions(checks, fog(22, 20, ate=0.9), fog(15, 14, ate=0.3))
    assert [m.split(":")[0] for m in found] == [
        "fog.visibility_m boundary moved toward the requirement",
        "ate_rmse at the envelope's edge (fog.visibility_m = 25 m) got worse",
    ]
    assert regressions(checks, fog(22, 20), None) == []
    assert regressions(checks, fog(15, 14), fog(15, 14)) == []


def test_warm_start_and_edge_trial() -> None:
    previous = fog(15, 14)
    assert warm_start(None) is None
    assert warm_start(previous) == (15, 14)
    assert warm_start(previous, parameter="fog.visibility_m", edge=25.0, worse="lower") == (15, 14)
    assert warm_start(previous, parameter="rain.rate") is None
    assert warm_start(previous, edge=30.0) is None
    assert warm_start(previous, worse="higher") is None
    assert warm_start(fog(None, 40)) == (None, 40)
    assert warm_start(fog(None, None)) is None
    assert edge_trial(previous).value == 25.0 and edge_trial(fog(15, 14, edge=None)) is None
