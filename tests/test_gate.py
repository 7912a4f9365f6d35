"""The regression gate outside an inner pytest session: the baseline lookup (``last`` skips a
run that failed the gate), what a comparison says (another machine, another system version, no
baseline), ``sal compare``'s exit status, ``sal history prune``, what the machine record holds,
and the space-form check of path options."""

from __future__ import annotations

import json
import os
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from history_outcomes import FOG, drop, fog, save

from pytest_sal.cli.main import main
from pytest_sal.history.gate import NOT_COMPARED, compare_with_baseline
from pytest_sal.history.provenance import machine_info, machine_text
from pytest_sal.history.regression import BoundaryCheck
from pytest_sal.history.run_history import History
from pytest_sal.option_table import space_form_problem
from sal_wrappers import create

TEN_PERCENT = [BoundaryCheck(10.0, True)]


def test_last_skips_an_outcome_that_failed_the_gate(tmp_path: Path) -> None:
    history = History(tmp_path / "h")
    save(history, [fog(15, 14)])
    save(history, [fog(22, 20, regression="boundary moved +47 %")])  # a regressed run, saved
    run, outcome = history.baseline((FOG, "orbslam3", "kitti-07"), "last")
    assert run.label == "0001" and outcome.boundary.pass_value == 15
    assert history.previous((FOG, "orbslam3", "kitti-07"), "0002").boundary.pass_value == 22  # named: as asked
    retried = compare_with_baseline(fog(22, 20), history, "last", TEN_PERCENT)
    assert retried.regression and "passed down to 15 m before, now only down to 22 m" in retried.regression


def test_comparison_names_the_baseline_and_another_machine_or_system(tmp_path: Path) -> None:
    history = History(tmp_path / "h")
    save(history, [fog(15, 14, machine="Xeon Gold 6230 (16 cores)", system_version="orbslam3 (pyorbslam3 0.1.1) #aaaa0000")], name="main")
    same = compare_with_baseline(
        fog(15, 14, machine="Xeon Gold 6230 (16 cores)", system_version="orbslam3 (pyorbslam3 0.1.1) #aaaa0000"),
        history,
        "main",
        TEN_PERCENT,
    )
    assert same.comparison == "main (run 0001, commit 1a2b3c4)" and same.regression is None and same.previous.pass_value == 15
    moved = compare_with_baseline(
        fog(16, 15, machine="EPYC 7763 (2 cores)", system_version="orbslam3 (pyorbslam3 0.1.1) #bbbb1111"), history, "main", TEN_PERCENT
    )
    assert moved.comparison == (
        "main (run 0001, commit 1a2b3c4); on another machine: baseline Xeon Gold 6230 (16 cores), this run EPYC 7763 (2 cores); "
        "system orbslam3 (pyorbslam3 0.1.1) #aaaa0000 -> orbslam3 (pyorbslam3 0.1.1) #bbbb1111"
    )
    assert moved.regression is None  # +6.7 % is within the 10 % limit


@pytest.mark.parametrize("missing", ["pass", "fail"])
def test_nothing_to_compare_is_said_and_fails_only_when_asked(tmp_path: Path, missing: str) -> None:
    history = History(tmp_path / "h")
    nothing = compare_with_baseline(fog(15, 14), history, "main", TEN_PERCENT, missing=missing)
    assert (
        nothing.comparison
        == NOT_COMPARED
        + f"no run 'main' in the history {tmp_path / 'h'}: give 'last', a run number, a run name or a commit prefix (latest runs: none yet)"
    )
    save(history, [drop(30, 32)], name="main")  # a baseline without this test
    lacking = compare_with_baseline(fog(15, 14), history, "main", TEN_PERCENT, missing=missing)
    assert lacking.comparison == NOT_COMPARED + f"no outcome of this test (orbslam3 on kitti-07) in the baseline 'main' of {tmp_path / 'h'}"
    for outcome in (nothing, lacking):
        assert outcome.previous is None
        assert (
            (outcome.regression == f"{outcome.comparison} (--sal-compare-missing=fail)")
            if missing == "fail"
            else outcome.regression is None
        )
        assert outcome.passed is (missing == "pass")


def test_sal_compare_exits_1_on_a_regression_and_0_otherwise(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "h"
    history = History(folder)
    save(history, [fog(15, 14), drop(30, 32)], name="main")
    save(history, [fog(22, 20), drop(31, 33)], commit="2b3c4d5")  # fog got worse by 47 %, drop better
    save(history, [fog(15.5, 15), drop(29, 31), fog(None, 25, verdict="failed", test_id="tests/test_fog.py::test_dense")], commit="3c4d5e6")
    common = ["--history-dir", str(folder)]
    assert main(["compare", "main", "0002", *common]) == 0  # no --fail check, no verdict change: the default check's +47 % is said
    assert capsys.readouterr().out.splitlines()[-2] == "1 regression in 2 tests"
    assert main(["compare", "main", "0002", "--fail", "boundary:10%", *common]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"run 0002 commit 2b3c4d5 against run 0001 'main' commit 1a2b3c4 in {folder}"
    rows = [line for line in out if line.startswith("tests/")]
    assert rows[0].startswith(FOG) and "REGRESSED" in rows[0] and "pass 15 -> 22 m, +47 % (worse)" in rows[0]  # regressions first
    assert "REGRESSED" not in rows[1]
    assert (
        f"REGRESSED {FOG}: fog.visibility_m boundary moved toward the requirement: passed down to 15 m before, now only down to 22 m (+47 %, limit 10 %)"
        in out
    )
    assert out[-1] == "1 regression in 2 tests"
    assert main(["compare", "main", *common, "--fail", "boundary:10%"]) == 0  # the last run: within 10 %, a new test is listed
    out = capsys.readouterr().out
    assert "not in the baseline" in out and "0 regressions in 3 tests" in out
    save(history, [fog(None, 25, verdict="failed")], commit="4d5e6f7")  # fails at the edge now: a regression without any check
    assert main(["compare", "main", *common]) == 1
    assert "REGRESSED tests/test_fog.py::test_fog_visibility: passed in 0001, failed now" in capsys.readouterr().out
    assert main(["compare", "nightly", *common]) == 2
    assert "sal: error: no run 'nightly' in the history" in capsys.readouterr().err
    with pytest.raises(SystemExit, match="2"):
        main(["compare", "main", "--fail", "speed:3", *common])
    assert "argument --fail: 'speed:3': unknown quantity 'speed'" in capsys.readouterr().err


def test_sal_compare_says_when_the_runs_come_from_different_machines(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    history = History(tmp_path / "h")
    history.append_run([fog(15, 14)], name="main", commit="1a2b3c4", dirty=False, machine={"cpu_model": "Xeon Gold 6230", "cpu_count": 16})
    history.append_run([fog(15, 14)], commit="2b3c4d5", dirty=False, machine={"cpu_model": "EPYC 7763", "usable_cpus": 2, "cpu_count": 64})
    assert main(["compare", "main", "--history-dir", str(tmp_path / "h")]) == 0
    assert "note: the runs come from different machines (Xeon Gold 6230 (16 cores); EPYC 7763 (2 cores))" in capsys.readouterr().out


def test_history_prune_keeps_baselines_and_the_newest_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "h"
    history = History(folder)
    for number in range(1, 9):
        save(history, [fog(15 + number, 14 + number)], name={2: "release-1", 3: "main", 5: "main"}.get(number))
    old = datetime.now(UTC) - timedelta(days=40)
    for path in sorted(folder.glob("000[1-4]_*.json")):  # runs 1-4 were written 40 days ago
        data = json.loads(path.read_text())
        path.write_text(json.dumps(data | {"created": old.isoformat()}))
    assert main(["history", "prune", "--keep", "3", "--dry-run", "--history-dir", str(folder)]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == f"{folder}: would remove 3 of 8 runs; 5 kept"
    assert len(History(folder).runs()) == 8
    assert main(["history", "--history-dir", str(folder), "prune", "--older-than", "30d"]) == 0  # runs 1, 3, 4 (2 is release-1's newest)
    assert capsys.readouterr().out.splitlines()[-1] == f"{folder}: removed 3 of 8 runs; 5 kept"
    assert [r.label for r in History(folder).runs()] == ["0002", "0005", "0006", "0007", "0008"]
    assert main(["history", "prune", "--keep", "1", "--history-dir", str(folder)]) == 0  # each name's newest and run 8 stay
    assert [r.label for r in History(folder).runs()] == ["0002", "0005", "0008"]
    assert save(history, [fog(15, 14)]).name.startswith("0009_")  # numbers are never reused
    assert main(["history", "prune", "--history-dir", str(folder)]) == 2
    assert "give --keep N, --older-than AGE (e.g. 30d), or both" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["history", "prune", "--older-than", "soon", "--history-dir", str(folder)])
    assert "expected an age such as 30d, 12h, 90m or 2w, got 'soon'" in capsys.readouterr().err


def test_machine_record_and_system_version() -> None:
    info = machine_info()
    assert info["cpu_count"] == os.cpu_count() and 1 <= info["usable_cpus"] <= info["cpu_count"]
    assert len(info["load_avg"]) == 3 and all(x >= 0 for x in info["load_avg"])
    with open("/proc/cpuinfo", encoding="utf-8") as cpuinfo:
        first_model = next((line.split(":", 1)[1].strip() for line in cpuinfo if line.startswith("model name")), "")
    assert info["cpu_model"] == " ".join(first_model.split())
    assert machine_text(info) == f"{info['cpu_model']} ({info['usable_cpus']} cores)"
    vo = create("reference_vo")
    text = vo.version_text()
    assert text.startswith("reference_vo (opencv ") and len(text.rsplit("#", 1)[1]) == 8
    assert create("reference_vo").version_text() == text  # the same system, the same text
    assert create("reference_vo", features=500).version_text().rsplit("#", 1)[1] != text.rsplit("#", 1)[1]  # an option changes it


@pytest.mark.parametrize(
    ("args", "refused"),
    [
        (["--sal-history-dir", "/nonexistent/h"], True),  # a path option: always, even before the folder exists
        (["--sal-history-dir=/x/h"], False),
        (["-v", "--sal-report-html", "report"], True),
        (["--sal-save", "main"], False),  # a name: fine while no such path exists
        (["--sal-save", "."], True),
        (["--sal-compare", "tests", "-x"], False),  # 'tests' does not exist in the cwd of this check
        (["--sal-compare"], False),
    ],
)
def test_space_form_check(args: list[str], refused: bool, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    problem = space_form_problem(args, "/r", "/r/pytest.ini")
    assert (problem is not None) is refused
    if refused:
        assert problem.startswith(f"write {args[-2]}={args[-1]} with '='") and "(rootdir /r, ini file /r/pytest.ini)" in problem
