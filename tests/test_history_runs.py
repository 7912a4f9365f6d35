"""Run history files: appending and listing runs, plain JSON values, numbering with parallel
writers, atomic writes, unreadable or edited entries skipped with a warning, lookups of a
previous run by number, name and commit, and the machine and commit recorded."""

from __future__ import annotations

import json
import os
import subprocess
import threading
from pathlib import Path

import numpy as np
import pytest
from history_outcomes import DROP, FOG, drop, fog, save

from pytest_sal.engine.outcomes.outcome import Outcome
from pytest_sal.history.provenance import commit_info, machine_info
from pytest_sal.history.run_history import History, outcome_key
from sal_adapters import SalError

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
