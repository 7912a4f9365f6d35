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

from pytest_sal.engine.search.bisection import TERMINATIONS
from pytest_sal.experiment.boundary import TRACKING_FAIL_RATE, linear_sweep_trials

SUMMARY = "robustness_boundary/{system}/" + BOUNDARY["name"] + "/boundary_summary.json"


def verdict(metrics: dict[str, Any]) -> str:
    """The block's requirement: ate_rmse < ate_rmse_fail and tracking_rate >= 0.5."""
    ate_rmse, rate = metrics.get("ate_rmse"), metrics.get("tracking_rate")
    ok = ate_rmse is not None and ate_rmse < BOUNDARY["ate_rmse_fail"] and rate is not None and rate >= TRACKING_FAIL_RATE
    return "pass" if ok else "fail"


def without_cache_fields(trials: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Trials as compared between a run and its cached rerun (``cached`` and timing differ)."""
    return [{k: v for k, v in t.items() if k not in ("cached", "wall_time_s", "runs")} for t in trials]


def votes(trial: dict[str, Any]) -> tuple[int, int]:
    """(runs that agree with the trial's verdict, runs) of a trial of ``Outcome.to_dict``."""
    return sum(r["passed"] == trial["passed"] for r in trial["runs"]), len(trial["runs"])


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

    @property
    def outcome(self) -> dict[str, Any]:
        """The summary's ``Outcome.to_dict()``."""
        return self.summary["outcome"]

    @property
    def experiment(self) -> dict[str, Any]:
        """What only the experiment knows: the config's bounds, the linear sweep, the plot."""
        return self.summary["experiment"]


@pytest.fixture(scope="class")
def searched(tmp_path_factory: pytest.TempPathFactory, request: pytest.FixtureRequest) -> Searched:
    """``sal boundary`` with the test class's ``system``, then again on the same cache, once per class."""
    system = request.cls.system
    config = write_config(tmp_path_factory.mktemp(f"e2e-boundary-{system}"))
    # ORB-SLAM3 with one run per trial (--runs 1): the bisection whose tree and summary these classes check; the
    # noisy search's curve is checked through the plugin (test_plugin_orbslam3.py, test_plugin_requirements.py)
    once = ["--runs", "1"] if system == "orbslam3" else []
    args = ["boundary", str(config), "--slam", system, "--cache-dir", str(config.parent / "cache"), *once, *slam_options(system, request)]
    summary = SUMMARY.format(system=system)
    first = sal(config, args, keep=(summary,))
    return Searched(system, first, first.kept[summary], sal(config, args, keep=(summary,)))


class BoundaryChecks:
    """What ``sal boundary`` did with ``system`` (the subclasses name it)."""

    system = ""

    def test_tree_holds_the_summary_the_plot_and_a_folder_per_slam_run(self, searched: Searched) -> None:
        """One run per trial for the deterministic reference VO, at least 2 runs a trial for ORB-SLAM3 (noisy)."""
        first, system = searched.first, searched.system
        assert set(searched.summary) == {"outcome", "experiment"}  # Outcome.to_dict(), and what only the experiment knows
        where = f"robustness_boundary/{system}/{BOUNDARY['name']}/"
        assert all(f.startswith(where) for f in first.files)
        trials = searched.outcome["trials"]
        runs = run_dirs(first, system)
        assert len(runs) == sum(len(t["runs"]) for t in trials) == len(first.slam_calls)
        assert all(len(t["runs"]) == 1 for t in trials)  # one run per trial: reference_vo is deterministic, ORB-SLAM3 runs with --runs 1
        assert {f for f in first.files if not f.startswith(where + "runs/")} == {
            where + "boundary_summary.json",
            where + "boundary_plot.png",
        }
        assert all(f"{where}runs/{d}/{system}.log" in first.files for d in runs)
        assert png_size(first.results / where / "boundary_plot.png")
        assert searched.experiment["plot"] == str(first.results / where / "boundary_plot.png")

    def test_summary_describes_the_search(self, searched: Searched) -> None:
        outcome, experiment = searched.outcome, searched.experiment
        assert outcome["system"] == searched.system and outcome["parameter"] == "fog.visibility_m" and outcome["boundary"]["unit"] == "m"
        assert outcome["worse"] == "lower" and outcome["edge"] == BOUNDARY["upper"]
        assert (
            outcome["requirement"]
            == f"ate_rmse < {BOUNDARY['ate_rmse_fail']:g} m and tracking_rate >= 0.5 wherever fog.visibility_m >= {BOUNDARY['upper']} m"
        )
        limits = (BOUNDARY["lower"], BOUNDARY["upper"], BOUNDARY["tolerance"], BOUNDARY["max_trials"])
        assert (experiment["lower_bound"], experiment["upper_bound"], experiment["tolerance"], experiment["max_trials"]) == limits
        assert outcome["seed"] == SEED and outcome["dataset"] == "synthetic/urban-seed0"
        assert experiment["linear_sweep_trials"] == linear_sweep_trials(BOUNDARY["lower"], BOUNDARY["upper"], BOUNDARY["tolerance"]) == 101
        assert len(outcome["trials"]) <= BOUNDARY["max_trials"]

    def test_each_trial_verdict_is_the_requirement_on_its_metrics(self, searched: Searched) -> None:
        """The mild end passes (clean-looking air), the severe end fails (2 m: nothing tracked)."""
        trials = searched.outcome["trials"]
        for t in trials:
            assert set(t) >= {"value", "metrics", "passed", "failed", "cached", "runs"}
            assert BOUNDARY["lower"] <= t["value"] <= BOUNDARY["upper"]
            agreeing, voting = votes(t)
            if agreeing == voting:  # unanimous: the median run agrees
                assert ("pass" if t["passed"] else "fail") == verdict(t["metrics"]), t
            assert (not t["passed"]) == bool(t["failed"]) and t["cached"] is False
        assert (trials[0]["value"], trials[0]["passed"]) == (BOUNDARY["upper"], True)
        assert (trials[1]["value"], trials[1]["passed"]) == (BOUNDARY["lower"], False)
        assert trials[1]["metrics"]["tracking_rate"] == 0.0 and trials[1]["metrics"]["ate_rmse"] is None
        assert searched.outcome["verdict"] == "passed"

    def test_pass_and_fail_values_bracket_the_failure_on_the_worse_side(self, searched: Searched) -> None:
        outcome = searched.outcome
        trials = outcome["trials"]
        passing = [t["value"] for t in trials if t["passed"]]
        failing = [t["value"] for t in trials if not t["passed"]]
        pass_value, fail_value = outcome["boundary"]["pass_value"], outcome["boundary"]["fail_value"]
        assert BOUNDARY["lower"] <= fail_value < pass_value <= BOUNDARY["upper"]
        assert pass_value in passing and fail_value in failing
        assert not [t["value"] for t in trials if fail_value < t["value"] < pass_value]  # the tightest bracket
        assert outcome["termination"] in TERMINATIONS
        if pass_value - fail_value > BOUNDARY["tolerance"]:
            assert outcome["termination"] == "max_trials" and len(trials) == BOUNDARY["max_trials"]

    def test_prints_a_step_per_trial_and_the_count_against_a_linear_sweep(self, searched: Searched) -> None:
        first, trials = searched.first, searched.outcome["trials"]
        n, runs = len(trials), sum(len(t["runs"]) for t in trials)
        assert f"{n} trials, {runs} runs (0 trials cached) vs 101 for a linear sweep" in first.out
        assert len([line for line in first.out.splitlines() if line.lstrip().startswith("step ")]) >= n

    def test_rerun_reads_every_trial_from_the_cache(self, searched: Searched) -> None:
        first, outcome, system = searched.first, searched.outcome, searched.system
        again = searched.again
        assert again.slam_calls == []  # no SLAM run at all
        assert run_dirs(again, system) == run_dirs(first, system)
        rerun = again.kept[SUMMARY.format(system=system)]["outcome"]
        assert all(t["cached"] for t in rerun["trials"])
        assert without_cache_fields(rerun["trials"]) == without_cache_fields(outcome["trials"])
        assert [votes(t) for t in rerun["trials"]] == [votes(t) for t in outcome["trials"]]
        assert (rerun["boundary"], rerun["termination"]) == (outcome["boundary"], outcome["termination"])
        n, runs = len(outcome["trials"]), sum(len(t["runs"]) for t in outcome["trials"])
        assert f"{n} trials, {runs} runs ({n} trials cached)" in again.out


class TestBoundaryOrbslam3(BoundaryChecks):
    system = "orbslam3"


class TestBoundaryReferenceVo(BoundaryChecks):
    system = "reference_vo"
