"""``sal history``: the run listing, change text, one test's history and its plot (log scale
for wide ranges, worse-higher metrics), errors, and a history in an old search unit."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import pytest
from history_outcomes import DROP, FOG, drop, fog, save

from pytest_sal.cli.history import history_figure
from pytest_sal.cli.main import main
from pytest_sal.engine.outcomes.outcome import Boundary, Outcome
from pytest_sal.history.regression import BoundaryCheck, regressions
from pytest_sal.history.run_history import History
from sal_adapters import SalError


def cells(line: str) -> list[str]:
    """The columns of a table line (separated by two spaces or more)."""
    return re.split(r"\s{2,}", line.strip())


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
