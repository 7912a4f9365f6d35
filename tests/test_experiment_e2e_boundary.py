"""``sal boundary`` end to end through ``pytest_sal.cli.main.main`` with the REAL systems on the
synthetic urban stereo world (the experiment of experiment_e2e.py; the other commands are in
test_experiment_e2e.py): the search runs once per system and again on the same cache, in a
class-scoped fixture, and the class's tests assert one thing each on the two runs.

Boundary (fog.visibility_m in 2 .. 500 m, log bisection, 4 trials): orbslam3 7.95-31.6 m,
reference_vo 31.6-125.7 m (at 31.6 m it tracks 40 % of the frames); ~16 s / ~7 s.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import pytest
from experiment_e2e import BOUNDARY, SEED, Command, png_size, sal, slam_options, write_config

from pytest_sal.cli.boundary import TRACKING_FAIL_RATE, linear_sweep_trials
from pytest_sal.engine.boundary_search import TERMINATIONS

SUMMARY = "robustness_boundary/{system}/" + BOUNDARY["name"] + "/boundary_summary.json"


def verdict(metrics: dict[str, Any]) -> str:
    """The block's requirement: ate_rmse < ate_rmse_fail and tracking_rate >= 0.5."""
    ate_rmse, rate = metrics.get("ate_rmse"), metrics.get("tracking_rate")
    ok = ate_rmse is not None and ate_rmse < BOUNDARY["ate_rmse_fail"] and rate is not None and rate >= TRACKING_FAIL_RATE
    return "pass" if ok else "fail"


def without_cache_fields(trials: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Trials as compared between a run and its cached rerun (``cached`` and timing differ)."""
    return [{k: v for k, v in t.items() if k not in ("cached", "wall_time_s")} for t in trials]


def run_dirs(command: Command, system: str) -> list[str]:
    """The work folders of the SLAM runs after ``command``: ``runs/NAME`` in its results."""
    prefix = f"robustness_boundary/{system}/{BOUNDARY['name']}/runs/"
    return sorted({f[len(prefix) :].split("/")[0] for f in command.files if f.startswith(prefix)})


@dataclass
class Searched:
    """``sal boundary`` with ``system``, and the same command again on its cache."""

    system: str
    first: Command
    summary: dict[str, Any]
    again: Command


@pytest.fixture(scope="class")
def searched(tmp_path_factory: pytest.TempPathFactory, request: pytest.FixtureRequest) -> Searched:
    """``sal boundary`` with the test class's ``system``, then again on the same cache, once per class."""
    system = request.cls.system
    config = write_config(tmp_path_factory.mktemp(f"e2e-boundary-{system}"))
    args = ["boundary", str(config), "--slam", system, "--cache-dir", str(config.parent / "cache"), *slam_options(system, request)]
    summary = SUMMARY.format(system=system)
    first = sal(config, args, keep=(summary,))
    return Searched(system, first, first.kept[summary], sal(config, args, keep=(summary,)))


class BoundaryChecks:
    """What ``sal boundary`` did with ``system`` (the subclasses name it)."""

    system = ""

    def test_tree_holds_the_summary_the_plot_and_a_folder_per_slam_run(self, searched: Searched) -> None:
        """One run per trial for the deterministic reference VO, a vote of at least 2 for ORB-SLAM3."""
        first, summary, system = searched.first, searched.summary, searched.system
        where = f"robustness_boundary/{system}/{BOUNDARY['name']}/"
        assert all(f.startswith(where) for f in first.files)
        trials = summary["trials"]
        runs = run_dirs(first, system)
        assert len(runs) == sum(t["runs"] for t in trials) == summary["runs_used"] == len(first.slam_calls)
        assert all(t["runs"] == 1 for t in trials) if system == "reference_vo" else all(t["runs"] >= 2 for t in trials)
        assert {f for f in first.files if not f.startswith(where + "runs/")} == {
            where + "boundary_summary.json",
            where + "boundary_plot.png",
        }
        assert all(f"{where}runs/{d}/{system}.log" in first.files for d in runs)
        assert png_size(first.results / where / "boundary_plot.png")
        assert summary["plot"] == str(first.results / where / "boundary_plot.png")

    def test_summary_describes_the_search(self, searched: Searched) -> None:
        summary = searched.summary
        assert summary["system"] == searched.system and summary["parameter"] == "fog.visibility_m" and summary["unit"] == "m"
        assert summary["worse"] == "lower" and summary["edge"] == BOUNDARY["upper"]
        assert (
            summary["requirement"]
            == f"ate_rmse < {BOUNDARY['ate_rmse_fail']:g} m and tracking_rate >= 0.5 wherever fog.visibility_m >= {BOUNDARY['upper']} m"
        )
        limits = (BOUNDARY["lower"], BOUNDARY["upper"], BOUNDARY["tolerance"], BOUNDARY["max_iters"])
        assert (summary["lower_bound"], summary["upper_bound"], summary["tolerance"], summary["max_iters"]) == limits
        assert summary["seed"] == SEED and summary["dataset"] == "synthetic/urban-seed0"
        assert summary["linear_sweep_trials"] == linear_sweep_trials(BOUNDARY["lower"], BOUNDARY["upper"], BOUNDARY["tolerance"]) == 101
        assert summary["trials_used"] == len(summary["trials"]) <= BOUNDARY["max_iters"]

    def test_each_trial_verdict_is_the_requirement_on_its_metrics(self, searched: Searched) -> None:
        """The mild end passes (clean-looking air), the severe end fails (2 m: nothing tracked)."""
        summary = searched.summary
        trials = summary["trials"]
        for t in trials:
            assert set(t) >= {"value", "metrics", "verdict", "failed", "cached", "runs", "votes"}
            assert BOUNDARY["lower"] <= t["value"] <= BOUNDARY["upper"]
            if t["votes"].startswith(f"{t['runs']} of {t['runs']} "):  # unanimous: the median run agrees
                assert t["verdict"] == verdict(t["metrics"]), t
            assert (t["verdict"] == "fail") == bool(t["failed"]) and t["cached"] is False
        assert (trials[0]["value"], trials[0]["verdict"]) == (BOUNDARY["upper"], "pass")
        assert (trials[1]["value"], trials[1]["verdict"]) == (BOUNDARY["lower"], "fail")
        assert trials[1]["metrics"]["tracking_rate"] == 0.0 and trials[1]["metrics"]["ate_rmse"] is None
        assert summary["edge_verdict"] == "passed"

    def test_pass_and_fail_values_bracket_the_failure_on_the_worse_side(self, searched: Searched) -> None:
        summary = searched.summary
        trials = summary["trials"]
        passing = [t["value"] for t in trials if t["verdict"] == "pass"]
        failing = [t["value"] for t in trials if t["verdict"] == "fail"]
        pass_value, fail_value = summary["pass_value"], summary["fail_value"]
        assert BOUNDARY["lower"] <= fail_value < pass_value <= BOUNDARY["upper"]
        assert pass_value in passing and fail_value in failing
        assert not [t["value"] for t in trials if fail_value < t["value"] < pass_value]  # the tightest bracket
        assert summary["termination"] in TERMINATIONS
        if pass_value - fail_value > BOUNDARY["tolerance"]:
            assert summary["termination"] == "max_trials" and len(trials) == BOUNDARY["max_iters"]

    def test_prints_a_step_per_trial_and_the_count_against_a_linear_sweep(self, searched: Searched) -> None:
        first, summary = searched.first, searched.summary
        n, runs = len(summary["trials"]), summary["runs_used"]
        assert f"{n} trials, {runs} runs (0 trials cached) vs 101 for a linear sweep" in first.out
        assert len([line for line in first.out.splitlines() if line.lstrip().startswith("step ")]) >= n

    def test_rerun_reads_every_trial_from_the_cache(self, searched: Searched) -> None:
        first, summary, system = searched.first, searched.summary, searched.system
        again = searched.again
        assert again.slam_calls == []  # no SLAM run at all
        assert run_dirs(again, system) == run_dirs(first, system)
        rerun = again.kept[SUMMARY.format(system=system)]
        assert all(t["cached"] for t in rerun["trials"])
        assert without_cache_fields(rerun["trials"]) == without_cache_fields(summary["trials"])
        assert (rerun["pass_value"], rerun["fail_value"], rerun["termination"]) == (
            summary["pass_value"],
            summary["fail_value"],
            summary["termination"],
        )
        n = len(summary["trials"])
        assert f"{n} trials, {summary['runs_used']} runs ({n} trials cached)" in again.out


class TestBoundaryOrbslam3(BoundaryChecks):
    system = "orbslam3"


class TestBoundaryReferenceVo(BoundaryChecks):
    system = "reference_vo"
