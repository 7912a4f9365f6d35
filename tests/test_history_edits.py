"""A hand-edited run file breaks nothing (issue 23, item 3): every history reader (the gate,
``sal history``, ``sal compare``) skips what is wrong, an outcome or a file whose top level is
wrong, with one warning naming the file, the test and the key, and keeps the rest."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path

import pytest
from history_outcomes import DROP, FOG, drop, fog, save

from pytest_sal.cli.main import main
from pytest_sal.history.gate import compare_with_baseline
from pytest_sal.history.regression import BoundaryCheck
from pytest_sal.history.run_history import History

NESTED = "[" * 100_000 + "]" * 100_000


def edit(path: Path, change: Callable[[str], str]) -> None:
    path.write_text(change(path.read_text()))


def outcome_edit(key: str, value: str) -> Callable[[str], str]:
    """The first outcome's ``key`` (the fog test's) set to ``value``, as JSON text."""
    return lambda text: text.replace(f'"{key}": ', f'"{key}": {value}, "_was": ', 1)


# (edit of run 2, what the warning says, run 2's outcomes still read)
EDITS = {
    "name-list": (
        lambda t: t.replace('"name": "main"', '"name": ["main"]'),
        "not a readable pytest-sal run, skipped (name = \"['main']\" is not a text)",
        None,
    ),
    "nested-file": (
        lambda t: t.replace('"dirty": false', f'"dirty": {NESTED}'),
        "not a readable pytest-sal run, skipped (nests 100001 levels",
        None,
    ),
    "test-id-int": (outcome_edit("test_id", "5"), "outcome 1 (5) skipped: test_id = '5' is not a text", 1),
    "nan": (outcome_edit("seed", "NaN"), f"outcome 1 ({FOG}) skipped: seed = 'nan' is not a finite number", 1),
    "1e999": (outcome_edit("margin", "1e999"), f"outcome 1 ({FOG}) skipped: margin = 'inf' is not a finite number", 1),
    "huge-int": (outcome_edit("seed", "9" * 5000), f"outcome 1 ({FOG}) skipped: seed = 'inf' is not a finite number", 1),
    "nested-outcome": (
        outcome_edit("system_options", "[" * 60 + "]" * 60),
        f"outcome 1 ({FOG}) skipped: system_options" + "[0]" * 31 + " nests deeper than 32 levels",
        1,
    ),
}


@pytest.mark.parametrize("attack", EDITS)
def test_an_edited_run_file_is_skipped_where_it_is_wrong(attack: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    change, said, kept = EDITS[attack]
    folder = tmp_path / "h"
    history = History(folder)
    save(history, [fog(15, 14), drop(30, 32)], name="main")
    edited = save(history, [fog(22, 20), drop(31, 33)], name="main", commit="2b3c4d5")
    edit(edited, change)
    with pytest.warns(UserWarning) as caught:
        runs = History(folder).runs()
    assert len(caught) == 1 and str(caught[0].message).startswith(f"{edited}: {said}")
    assert [len(r.outcomes) for r in runs] == ([2] if kept is None else [2, kept])
    with warnings.catch_warnings(record=True) as gate_warnings:  # the gate: compares with the last readable outcome
        warnings.simplefilter("always")
        gated = compare_with_baseline(fog(22, 20), History(folder), "main", [BoundaryCheck(10.0, True)])
    assert len(gate_warnings) == 1 and gated.comparison == "main (run 0001, commit 1a2b3c4)" and gated.regression
    for command in (["history"], ["history", "test_frame_drop", "-o", str(tmp_path / "p.png")], ["compare", "main"]):
        assert main([*command, "--history-dir", str(folder)]) in (0, 1)
        err = capsys.readouterr().err.splitlines()
        assert len(err) == 1 and err[0].startswith(f"sal: warning: {edited}: {said[:60]}"), err  # one warning, no traceback
    assert DROP in {o.test_id for run in runs for o in run.outcomes}
