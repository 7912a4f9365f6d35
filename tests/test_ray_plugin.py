"""The plugin with ``--sal-executor ray`` end to end (inner sessions in subprocesses): under
``pytest -n 2`` both xdist workers submit to the one local Ray their controller started, the
outcomes equal the local executor's, and a second, cached session sends nothing.
``sal evaluate --executor ray`` refuses ``--no-cache`` (its workers read frames from the cache)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from plugin_suites import calls, project, run
from ray_clusters import TOKEN

TESTS = """
@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25)
def test_fog(sal_outcome): pass


@sal.require(tracking_rate >= 0.9, fog.visibility_m >= 30, tolerance=2)
def test_fog_strict(sal_outcome): pass
"""


def boundaries(pytester: pytest.Pytester, history: str) -> dict[str, tuple[float | None, float | None, str]]:
    """Each test's boundary and verdict from the newest run in the history folder ``history``."""
    newest = sorted((pytester.path / history).glob("*.json"))[-1]
    outcomes = json.loads(newest.read_text())["outcomes"]
    return {o["test_id"]: (o["boundary"]["pass_value"], o["boundary"]["fail_value"], o["verdict"]) for o in outcomes}


def test_xdist_workers_share_the_controllers_ray_and_match_the_local_executor(
    pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("RAY_AUTH_TOKEN", TOKEN)  # no token file in the home folder
    monkeypatch.delenv("RAY_AUTH_MODE", raising=False)
    project(pytester, TESTS)
    local = run(pytester, ["-n", "2"], "--sal-history-dir=local-history", "--sal-cache-dir=local-cache")
    local.assert_outcomes(passed=1, failed=1)
    local_calls = calls(pytester)

    on_ray = run(pytester, ["-n", "2"], "--sal-executor", "ray", "--sal-history-dir=ray-history", "--sal-cache-dir=ray-cache")
    on_ray.assert_outcomes(passed=1, failed=1)
    on_ray.stdout.fnmatch_lines(["pytest-sal: runs on ray (local, starts on the first run)"])
    assert boundaries(pytester, "ray-history") == boundaries(pytester, "local-history")
    lines = [json.loads(line) for line in (pytester.path / "calls.jsonl").read_text().splitlines()]
    ray_runs = lines[local_calls:]
    assert len(ray_runs) >= 4
    # every run happened in a Ray worker of one raylet: the workers joined the controller's Ray
    assert len({run["parent"] for run in ray_runs}) == 1
    assert not {run["pid"] for run in ray_runs} & {run["pid"] for run in lines[:local_calls]}

    # the same searches again (a fresh history: no warm start to refine from) are served by the cache
    cached = run(pytester, ["-n", "2"], "--sal-executor", "ray", "--sal-history-dir=again-history", "--sal-cache-dir=ray-cache")
    cached.assert_outcomes(passed=1, failed=1)
    assert calls(pytester) == len(lines)  # a cached suite sends nothing
    assert boundaries(pytester, "again-history") == boundaries(pytester, "local-history")


def test_sal_evaluate_on_ray_needs_the_cache(capsys: pytest.CaptureFixture[str]) -> None:
    from pytest_sal.cli.main import main

    config = Path(__file__).parents[1] / "example_suites" / "configs" / "fog_rain_urban.yaml"
    code = main(["evaluate", str(config), "--slam", "reference_vo", "--executor", "ray", "--no-cache"])
    assert code != 0
    assert "sal evaluate --executor ray needs the cache: its workers read the perturbed frames from it; drop --no-cache" in (
        capsys.readouterr().err
    )


def test_sal_boundary_on_ray_finds_the_local_interval(tmp_path: Path) -> None:
    """``sal boundary --executor ray`` (a local Ray for the command) brackets the fake's known
    20 m boundary exactly as the local executor does; its trial path is the sequential one.
    Each command runs in its own interpreter, as a user runs it (the fake registered first)."""
    import os
    import subprocess
    import sys

    from test_boundary_command import STEP, boundary, read_summary, write_config

    config = write_config(tmp_path)
    folder = tmp_path / "results" / "fogb" / "robustness_boundary" / "fake" / "fog_sweep_visibility_m"
    register = (
        "import sys; from pytest_sal.testing import FakeSlam; from sal_wrappers import SYSTEMS; SYSTEMS.register('fake', FakeSlam); "
        "from pytest_sal.cli.main import main; raise SystemExit(main(sys.argv[1:]))"
    )
    environment = dict(os.environ, RAY_AUTH_TOKEN=TOKEN)
    environment.pop("RAY_AUTH_MODE", None)
    outcomes = []
    for name, extra in (("local", []), ("ray", ["--executor", "ray"])):
        command = [sys.executable, "-c", register, *boundary(tmp_path / name, "--slam-option", STEP, config=config), *extra]
        done = subprocess.run(command, capture_output=True, text=True, env=environment, timeout=300)
        assert done.returncode == 0, done.stderr[-2000:]
        outcomes.append(read_summary(folder).outcome)
    local, on_ray = outcomes
    assert (on_ray.boundary.pass_value, on_ray.boundary.fail_value, on_ray.termination) == (
        local.boundary.pass_value,
        local.boundary.fail_value,
        local.termination,
    )
    assert [t.value for t in on_ray.trials if not t.speculative] == [t.value for t in local.trials]
    assert not any(t.cached for t in on_ray.trials)  # its own cache: every trial ran on Ray
