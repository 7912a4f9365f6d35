"""One rule for a test's baseline and for a regression, in the gate and in ``sal compare``
(issue 23, item 1): the newest run of the baseline's name that holds the test, never the run
compared itself; a -50 % boundary is a regression with or without ``--fail``, failing only
with a check given (as ``--sal-compare`` alone passes the test and says so)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest
from history_outcomes import DROP, drop, fog, save

from pytest_sal.cli.main import main
from pytest_sal.engine.outcomes.outcome import Boundary, Outcome
from pytest_sal.history.gate import compare_with_baseline
from pytest_sal.history.regression import BoundaryCheck
from pytest_sal.history.run_history import History

TEN_PERCENT = [BoundaryCheck(10.0, True)]
HALVED = "frame_drop.drop_rate boundary moved toward the requirement: passed up to 0.3 before, now only up to 0.15"


def rate(pass_value: float, fail_value: float) -> Outcome:
    """The frame-drop test in today's unit (a fraction; ``drop`` stores the legacy %)."""
    return replace(drop(0, 0, edge=0.1), boundary=Boundary(pass_value, fail_value, ""))


def test_a_baseline_lacking_the_test_falls_back_to_the_older_run_of_its_name(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The newest 'main' is a -k run without the frame-drop test: the gate and sal compare both
    compare with the older 'main' and both call the -50 % a regression."""
    folder = tmp_path / "h"
    history = History(folder)
    save(history, [fog(15, 14), rate(0.3, 0.32)], name="main")
    save(history, [fog(15, 14)], name="main", commit="2b3c4d5")  # pytest -k fog --sal-save=main
    save(history, [fog(15, 14), rate(0.15, 0.17)], commit="3c4d5e6")  # the pull request: half the drop rate
    gated = compare_with_baseline(rate(0.15, 0.17), history, "main", TEN_PERCENT)
    assert gated.comparison == "main (run 0001, commit 1a2b3c4)"
    assert gated.regression == f"{HALVED} (-50 %, limit 10 %)"
    assert main(["compare", "main", "--fail", "boundary:10%", "--history-dir", str(folder)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert (
        out[0]
        == f"run 0003 commit 3c4d5e6 against 'main', each test against the newest of its runs holding it (runs 0001, 0002) in {folder}"
    )
    assert f"REGRESSED {DROP}: {HALVED} (-50 %, limit 10 %)" in out
    assert out[-1] == "1 regression in 2 tests"


def test_without_a_check_the_drop_is_a_regression_said_not_failed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--sal-compare`` alone passes the test and says the regression the default check
    (boundary:10%) finds; ``sal compare`` without ``--fail`` lists and counts it, exit 0."""
    folder = tmp_path / "h"
    history = History(folder)
    save(history, [rate(0.3, 0.32)], name="main")
    save(history, [rate(0.15, 0.17)], commit="2b3c4d5")
    gated = compare_with_baseline(rate(0.15, 0.17), history, "main", [])
    assert gated.regression is None and gated.passed
    assert gated.comparison == (
        "main (run 0001, commit 1a2b3c4); regressed (the default check boundary:10%; --sal-compare-fail fails it): "
        f"{HALVED} (-50 %, limit 10 %)"
    )
    assert main(["compare", "main", "--history-dir", str(folder)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert f"REGRESSED {DROP}: {HALVED} (-50 %, limit 10 %)" in out
    assert out[-2:] == [
        "1 regression in 1 tests",
        "note: 1 found by the default check boundary:10%, which does not fail; give --fail CHECK to fail on a regression",
    ]
    row = next(line for line in out if line.startswith(DROP))
    assert row.endswith("REGRESSED") and "pass 0.3 -> 0.15, -50 % (worse)" in row


def test_sal_compare_never_compares_a_run_with_itself(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The newest run is a regressed one saved as 'main' (no gate on that session): ``sal
    compare main`` compares it with the 'main' before it, not with itself."""
    folder = tmp_path / "h"
    history = History(folder)
    save(history, [rate(0.3, 0.32)], name="main")
    save(history, [rate(0.15, 0.17)], name="main", commit="2b3c4d5")
    assert main(["compare", "main", "--fail", "boundary:10%", "--history-dir", str(folder)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"run 0002 'main' commit 2b3c4d5 against run 0001 'main' commit 1a2b3c4 in {folder}"
    assert f"REGRESSED {DROP}: {HALVED} (-50 %, limit 10 %)" in out
    assert main(["compare", "0002", "0002", "--history-dir", str(folder)]) == 0  # a run alone: nothing to compare with
    assert "not in the baseline" in capsys.readouterr().out
