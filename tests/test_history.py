"""Run history: files, numbering with parallel writers, lookups, regression checks, ``sal history``."""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest

from pytest_sal.cli.history import history_figure
from pytest_sal.cli.main import main
from pytest_sal.engine.outcome import Boundary, Outcome, Trial
from pytest_sal.history.provenance import commit_info, machine_info
from pytest_sal.history.regression import BoundaryCheck, MetricCheck, edge_trial, parse_compare_fail, regressions, warm_start
from pytest_sal.history.run_history import History, outcome_key
from sal_adapters import SalError

FOG = "tests/test_fog.py::test_fog_visibility"
DROP = "tests/test_transport.py::test_frame_drop"


def fog(
    pass_value: float | None, fail_value: float | None, *, edge: float = 25.0, ate: float | None = 0.3, verdict: str = "passed", **kw
) -> Outcome:
    """fog.visibility_m gets more severe when lower; the system passed down to ``pass_value``."""
    trials = [Trial(edge, verdict == "passed", {"ate_rmse": ate, "tracking_rate": 0.97})]
    trials += [Trial(v, ok, {"ate_rmse": 0.5}) for v, ok in ((pass_value, True), (fail_value, False)) if v is not None]
    fields: dict = {
        "test_id": FOG,
        "system": "orbslam3",
        "dataset": "kitti-07",
        "parameter": "fog.visibility_m",
        "worse": "lower",
        "edge": edge,
        "requirement": "ate_rmse < 1.5 m wherever fog.visibility_m >= 25 m",
        "verdict": verdict,
        "criteria": [("ate_rmse", "<", 1.5)],
        "envelope": ">= 25 m",
        "boundary": Boundary(pass_value, fail_value, "m"),
        "termination": "tolerance",
        "trials": trials,
    }
    return Outcome(**(fields | kw))


def drop(pass_value: float | None, fail_value: float | None, *, edge: float = 10.0, rate: float = 0.95) -> Outcome:
    """frame_drop.drop_rate gets more severe when higher; passed up to ``pass_value`` %."""
    return Outcome(
        test_id=DROP,
        system="orbslam3",
        dataset="kitti-07",
        parameter="frame_drop.drop_rate",
        worse="higher",
        edge=edge,
        requirement="tracking_rate >= 0.9 wherever frame_drop.drop_rate <= 10 %",
        verdict="passed",
        criteria=[("tracking_rate", ">=", 0.9)],
        envelope="<= 10 %",
        boundary=Boundary(pass_value, fail_value, "%"),
        termination="tolerance",
        trials=[Trial(edge, True, {"ate_rmse": 0.4, "tracking_rate": rate})],
    )


def cells(line: str) -> list[str]:
    """The columns of a table line (separated by two spaces or more)."""
    return re.split(r"\s{2,}", line.strip())


def save(history: History, outcomes: list[Outcome], commit: str = "1a2b3c4", name: str | None = None, dirty: bool = False) -> Path:
    return history.append_run(outcomes, name=name, commit=commit, dirty=dirty, machine={"hostname": "box"})


# -- store ------------------------------------------------------------------------------------


def test_append_and_list_runs(tmp_path: Path) -> None:
    history = History(tmp_path / "h")
    assert history.runs() == []
    first = save(history, [fog(15, 14), drop(30, 32)])
    second = save(history, [fog(22, 20)], commit="", name="night ly/2", dirty=True)
    assert first.name.startswith("0001_1a2b3c4_") and first.name.endswith("Z.json")
    assert second.name.startswith("0002_nogit-dirty_") and second.name.endswith("_night-ly-2.json")
    data = json.loads(first.read_text())
    assert set(data) == {"version", "created", "commit", "dirty", "machine", "name", "outcomes"}
    assert data["version"] == 1 and data["commit"] == "1a2b3c4" and data["dirty"] is False and data["name"] is None
    assert data["outcomes"][0]["commit"] == "1a2b3c4" and data["outcomes"][0]["machine"] == "box"
    runs = History(tmp_path / "h").runs()
    assert [r.label for r in runs] == ["0001", "0002"] and runs[1].name == "night ly/2" and runs[1].dirty
    assert runs[0].outcomes[1] == Outcome.from_dict(drop(30, 32).to_dict() | {"commit": "1a2b3c4", "machine": "box"})
    assert [r.label for r, _ in history.trend(FOG)] == ["0001", "0002"]
    assert history.trend(FOG, system="other") == [] and len(history.trend(DROP, dataset="kitti-07")) == 1


def test_numpy_and_nan_values_are_saved_as_plain_json(tmp_path: Path) -> None:
    outcome = fog(15, 14, ate=float("nan"))
    outcome.trials[0].metrics = {**outcome.trials[0].metrics, "maps": np.int64(2)}
    path = save(History(tmp_path), [outcome])
    text = path.read_text()
    assert "NaN" not in text
    assert json.loads(text)["outcomes"][0]["trials"][0]["metrics"] == {"ate_rmse": None, "tracking_rate": 0.97, "maps": 2}


def test_parallel_writers_get_distinct_numbers(tmp_path: Path) -> None:
    history_root = tmp_path / "h"
    paths: list[Path] = []
    barrier = threading.Barrier(8)

    def writer(i: int) -> None:
        barrier.wait()
        paths.append(save(History(history_root), [fog(15 + i, 14 + i)], name=f"w{i}"))

    threads = [threading.Thread(target=writer, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    numbers = sorted(p.name[:4] for p in paths)
    assert numbers == [f"{n:04d}" for n in range(1, 9)]
    assert len(History(history_root).runs()) == 8
    assert not [p for p in history_root.iterdir() if p.name.endswith(".tmp")]


def test_write_is_atomic(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    history = History(tmp_path)
    save(history, [fog(15, 14)])

    def broken_replace(src: str, dst: str) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk full"):
        save(history, [fog(22, 20)])
    monkeypatch.undo()
    files = [p.name for p in tmp_path.iterdir() if p.is_file()]
    assert len(files) == 1 and files[0].startswith("0001_")  # no partial file, no temp file left
    assert [r.label for r in history.runs()] == ["0001"]
    assert save(history, [fog(22, 20)]).name.startswith("0003_")  # number 2 stays spent, never reused


def test_unreadable_file_is_skipped_with_a_warning(tmp_path: Path) -> None:
    save(History(tmp_path), [fog(15, 14)])
    (tmp_path / "0002_x_y.json").write_text('{"version": 1, "outc')
    with pytest.warns(UserWarning, match=r"0002_x_y.json: not a readable pytest-sal run, skipped"):
        assert [r.label for r in History(tmp_path).runs()] == ["0001"]


@pytest.mark.parametrize(
    "edit, key",
    [
        (lambda o: o["boundary"].update(pass_value="abc"), "boundary.pass_value = 'abc' is not a finite number"),
        (lambda o: o["boundary"].update(fail_value=float("nan")), "boundary.fail_value = 'nan' is not a finite number"),
        (lambda o: o.update(edge=float("inf")), "edge = 'inf' is not a finite number"),
        (lambda o: o["trials"][0].update(value=[1]), "trials[0].value = '[1]' is not a finite number"),
        (lambda o: o["trials"][0].update(metrics=[0.3]), "trials[0].metrics is not a mapping"),
        (lambda o: o.update(boundary=7), "not an outcome (no boundary)"),
    ],
    ids=["text", "nan", "inf", "list", "metrics-list", "no-boundary"],
)
def test_an_edited_outcome_is_skipped_with_a_warning_naming_the_key(tmp_path: Path, edit, key: str) -> None:
    """A hand-edited history number (``pass_value: "abc"``, NaN) used to raise TypeError in
    the search or print ``+nan %``: the outcome is skipped, the run's others are kept, and the
    comparison falls back on the newest readable run."""
    save(History(tmp_path), [fog(20, 18)])
    path = save(History(tmp_path), [fog(22, 20), drop(0.3, 0.33)])
    data = json.loads(path.read_text())
    edit(data["outcomes"][0])
    path.write_text(json.dumps(data))
    with pytest.warns(UserWarning) as caught:
        runs = History(tmp_path).runs()
    assert [str(w.message) for w in caught] == [f"{path}: outcome 1 ({FOG}) skipped: {key}"]
    assert [len(r.outcomes) for r in runs] == [1, 1]  # the frame-drop outcome of run 2 is kept
    with pytest.warns(UserWarning):
        previous = History(tmp_path).previous(outcome_key(fog(1, 2)))
    assert previous is not None and previous.boundary.pass_value == 20


def test_a_nan_metric_in_the_history_reads_as_not_available(tmp_path: Path) -> None:
    path = save(History(tmp_path), [fog(22, 20)])
    path.write_text(path.read_text().replace('"ate_rmse": 0.3', '"ate_rmse": NaN'))
    (outcome,) = History(tmp_path).runs()[0].outcomes
    assert outcome.trials[0].metrics["ate_rmse"] is None


def test_previous_by_last_number_name_and_commit(tmp_path: Path) -> None:
    history = History(tmp_path)
    save(history, [fog(15, 14)], commit="aaaa111", name="baseline")
    save(history, [fog(18, 17), drop(30, 32)], commit="bbbb222")
    save(history, [drop(28, 30)], commit="cccc333")
    key = outcome_key(fog(0, 0))
    assert history.previous(key).boundary.pass_value == 18  # newest run holding the key
    assert history.previous(key, "last").boundary.pass_value == 18
    assert history.previous(key, "0001").boundary.pass_value == 15
    assert history.previous(key, "2").boundary.pass_value == 18
    assert history.previous(key, "baseline").boundary.pass_value == 15
    assert history.previous(key, "bbbb").boundary.pass_value == 18
    assert history.previous(key, "cccc333") is None  # that run did not hold the test
    assert history.previous(("tests/other.py::t", "orbslam3", "kitti-07")) is None
    with pytest.raises(SalError, match=r"no run 'nope' in the history .*latest runs: 0001 \(baseline\), 0002, 0003"):
        history.previous(key, "nope")


def test_machine_and_commit_info(tmp_path: Path) -> None:
    info = machine_info()
    assert set(info) >= {"hostname", "platform", "cpu_count", "python"} and info["cpu_count"] >= 1
    assert commit_info(tmp_path) == ("", False)  # not a repository
    env = {**os.environ, "GIT_AUTHOR_NAME": "t", "GIT_AUTHOR_EMAIL": "t@t", "GIT_COMMITTER_NAME": "t", "GIT_COMMITTER_EMAIL": "t@t"}
    repo = tmp_path / "repo"
    repo.mkdir()

    def git(*args: str) -> None:
        subprocess.run(["git", *args], cwd=repo, env=env, check=True, capture_output=True)

    git("init", "-q")
    assert commit_info(repo) == ("", False)  # no commit yet
    (repo / "f.txt").write_text("1")
    git("add", "f.txt")
    git("commit", "-qm", "one")
    commit, dirty = commit_info(repo)
    assert len(commit) >= 7 and not dirty
    (repo / "untracked.txt").write_text("x")
    assert commit_info(repo) == (commit, False)
    (repo / "f.txt").write_text("2")
    assert commit_info(repo) == (commit, True)


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


# -- sal history ------------------------------------------------------------------------------


@pytest.fixture
def filled(tmp_path: Path) -> Path:
    root = tmp_path / "hist"
    history = History(root)
    save(history, [fog(15, 14, trials=[]), drop(30, 32)], commit="aaaa111", name="baseline")
    save(history, [fog(12, 11.5), drop(28, 30)], commit="bbbb222")
    save(history, [fog(22, 20), drop(28, 30)], commit="cccc333", dirty=True)
    save(history, [fog(None, 60, verdict="failed", regression="boundary regressed")], commit="dddd444")
    save(history, [fog(18, 16)], commit="eeee555")
    return root


def test_history_listing(filled: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["history", "--history-dir", str(filled)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"{filled}: 5 runs, 0001 (") and ") .. 0005 (" in lines[0]
    assert lines[1].split() == ["test", "system", "dataset", "run", "boundary", "verdict", "change", "since", "the", "run", "before"]
    assert cells(lines[2]) == [FOG, "orbslam3", "kitti-07", "0005", "16-18 m", "passed", "passes now (failed everywhere searched before)"]
    assert cells(lines[3]) == [DROP, "orbslam3", "kitti-07", "0003", "0.28-0.3", "passed", "unchanged"]


def test_history_change_text(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    save(History(tmp_path), [fog(15, 14), drop(30, 32)])
    save(History(tmp_path), [fog(22, 20), drop(33, 35)])
    assert main(["history", "--history-dir", str(tmp_path), "--system", "orbslam3"]) == 0
    out = capsys.readouterr().out
    assert "pass 15 -> 22 m, +47 % (worse)" in out and "pass 0.3 -> 0.33, +10 % (better)" in out


def test_history_of_one_test_and_its_plot(
    filled: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["history", "fog", "--history-dir", str(filled)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"{FOG}  (orbslam3 on kitti-07)"
    assert (
        lines[1]
        == "fog.visibility_m, more severe when lower, envelope edge 25 m; requirement: ate_rmse < 1.5 m wherever fog.visibility_m >= 25 m"
    )
    assert lines[2].split() == ["run", "commit", "date", "boundary", "verdict", "trials"]
    assert lines[3].split()[:2] == ["0001", "aaaa111"] and lines[3].split()[4:] == ["14-15", "m", "passed", "0", "name", "baseline"]
    assert lines[5].split()[1] == "cccc333+dirty"
    assert "beyond 60 m (failed everywhere searched)  failed (regressed)  2" in lines[6]
    assert lines[6].endswith("regression: boundary regressed")
    assert lines[8] == f"plot: sal-history-{FOG.replace('/', '_').replace('::', '_')}.png"
    image = cv2.imread(str(tmp_path / lines[8].removeprefix("plot: ")))
    assert image is not None and image.shape[0] == 550 and image.std() > 10


def test_history_plot_option_and_worse_higher(filled: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "plots" / "drop.png"
    assert main(["history", DROP, "--history-dir", str(filled), "-o", str(out)]) == 0
    assert capsys.readouterr().out.endswith(f"plot: {out}\n")
    image = cv2.imread(str(out))
    assert image is not None and image.size > 0


def test_history_errors(filled: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["history", "--history-dir", str(tmp_path / "none")]) == 2
    assert f"sal: error: no runs saved in {tmp_path / 'none'}" in capsys.readouterr().err
    assert main(["history", "test_", "--history-dir", str(filled)]) == 2
    assert capsys.readouterr().err == f"sal: error: 'test_' matches 2 tests; give more of the node id:\n  {FOG}\n  {DROP}\n"
    assert main(["history", "rain", "--history-dir", str(filled)]) == 2
    assert capsys.readouterr().err.startswith("sal: error: no test matching 'rain' in")
    assert main(["history", "--history-dir", str(filled), "--system", "dso"]) == 2
    assert capsys.readouterr().err == f"sal: error: no outcome in {filled} for --system dso\n"
    save(History(filled), [fog(15, 14, system="dso")])
    assert main(["history", "fog", "--history-dir", str(filled), "-o", str(tmp_path / "x.png")]) == 2
    assert capsys.readouterr().err == (
        f"sal: error: {FOG} ran with 2 systems/datasets in the history (dso on kitti-07; orbslam3 on kitti-07): "
        "choose one with --system and --dataset\n"
    )
    assert main(["history", "fog", "--history-dir", str(filled), "--system", "dso", "-o", str(tmp_path / "x.png")]) == 0


def test_history_figure_has_log_scale_for_wide_ranges(filled: Path) -> None:
    trend = History(filled).trend(FOG)
    assert history_figure(trend).axes[0].get_yscale() == "linear"
    wide = [(trend[0][0], fog(3, 2, edge=1000.0)), (trend[1][0], fog(5000, 3000, edge=1000.0))]
    assert history_figure(wide).axes[0].get_yscale() == "log"
    with pytest.raises(SalError, match="nothing to plot"):
        history_figure([])


def test_history_in_an_old_search_unit_is_converted_and_another_unit_is_refused() -> None:
    # night.illuminance_lux was stored in log10 lx: 0.699 is 5 lx, a pass at 1.5 is 31.6 lx
    old = {
        "test_id": "t::night",
        "system": "orbslam3",
        "dataset": "kitti/07",
        "parameter": "night.illuminance_lux",
        "worse": "lower",
        "edge": 0.69897,
        "requirement": "tracking_rate >= 0.9 wherever night.illuminance_lux >= 0.699 log10 lx",
        "envelope": ">= 0.699 log10 lx",
        "verdict": "failed",
        "termination": "tolerance",
        "boundary": {"pass_value": 1.5, "fail_value": 1.4, "unit": "log10 lx"},
        "trials": [{"value": 0.69897, "passed": False, "repeat": False}],
    }
    outcome = Outcome.from_dict(old)
    assert outcome.boundary.unit == "lx" and outcome.boundary.pass_value == pytest.approx(10**1.5)
    assert outcome.edge == pytest.approx(5.0, rel=1e-4) and outcome.trials[0].value == pytest.approx(5.0, rel=1e-4)
    assert outcome.envelope == ">= 5 lx" and outcome.requirement.endswith("wherever night.illuminance_lux >= 5 lx")
    assert outcome.margin == pytest.approx(5.0 - 10**1.5, rel=1e-4)
    # a unit the converter does not know is never compared silently
    now = fog(15, 14)
    before = fog(15, 14, boundary=Boundary(15, 14, "ft"))
    assert regressions([BoundaryCheck(10.0, True)], now, before) == [
        "not compared: the history has fog.visibility_m in 'ft', this run in 'm'; save a new baseline with --sal-save"
    ]
