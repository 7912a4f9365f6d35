"""The ``command`` system's name, version and depends: what goes into the cache key (the
script, the executable on PATH, depends files and folders), what a crash after writing keeps, and
the clear errors for bad values."""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import pytest

from sal_adapters import open_dataset
from sal_wrappers import SlamSystemError, create

#: the shared fixtures (indoor, scripts, short)
pytest_plugins = ["command_programs"]


# -- name, version, depends and the cache key ------------------------------------------------------
DRIFT_SLAM = textwrap.dedent(
    """\
    import sys
    from pathlib import Path

    DRIFT = {drift}  # metres of x error added per frame
    sequence, out = Path(sys.argv[1]), Path(sys.argv[2])
    rows = [line.split() for line in (sequence / "groundtruth.txt").read_text().splitlines() if line.strip() and not line.startswith("#")]
    with out.open("w") as fh:
        for i, r in enumerate(rows):
            fh.write(" ".join([r[0], repr(float(r[1]) + DRIFT * i * i), *r[2:8]]) + "\\n")
    """
)


def drift_script(path: Path, drift: float) -> Path:
    path.write_text(DRIFT_SLAM.format(drift=drift))
    return path


def trial_runner(tmp_path: Path, system):
    from pytest_sal import ate_rmse
    from pytest_sal.engine.execution.trial_runner import TrialRunner
    from pytest_sal.engine.requirements import Requirement
    from pytest_sal.store.content_cache import ContentCache
    from sal_modules import fog

    dataset = open_dataset("synthetic", scene="indoor", frames=8, sensor="rgbd")
    requirement = Requirement.build([ate_rmse < 0.5, fog.visibility_m >= 25])
    return TrialRunner(
        dataset,
        fog.visibility_m.ref(),
        system,
        requirement,
        runs=1,
        cache=ContentCache(tmp_path / "cache"),
        workdir=tmp_path / "work",
        timeout=60,
    )


def test_editing_the_script_invalidates_cached_trials(tmp_path):
    script = drift_script(tmp_path / "myslam.py", 0.0001)
    argv = [sys.executable, str(script), "{sequence}", "{output}"]
    first = trial_runner(tmp_path, create("command", argv=argv, layout="tum")).run_trial(30.0)
    assert not first.cached and first.runs[0]["failure"] is None, first.runs
    again = trial_runner(tmp_path, create("command", argv=argv, layout="tum")).run_trial(30.0)
    assert again.cached and again.metrics == first.metrics
    drift_script(script, 0.01)  # a worse SLAM program under the same argv
    edited = trial_runner(tmp_path, create("command", argv=argv, layout="tum")).run_trial(30.0)
    assert not edited.cached
    assert edited.metrics["ate_rmse"] > 10 * first.metrics["ate_rmse"]


@pytest.mark.parametrize(
    ("crash", "words"),
    [
        pytest.param("import os, signal; os.kill(os.getpid(), signal.SIGSEGV)", "killed by SIGSEGV (segmentation fault)", id="segfault"),
        pytest.param("import sys; sys.exit(139)", "exit status 139", id="exit-139"),
    ],
)
def test_a_crash_after_writing_the_trajectory_keeps_it_and_its_ate(tmp_path, crash, words):
    """Issue 12 point 8: the README's promise, end to end through a trial."""
    clean = drift_script(tmp_path / "clean.py", 0.0001)
    crashing = drift_script(tmp_path / "crashing.py", 0.0001)
    crashing.write_text(crashing.read_text() + crash + "\n")

    def trial(script: Path):
        system = create("command", argv=[sys.executable, str(script), "{sequence}", "{output}"], layout="tum", deterministic=True)
        return trial_runner(tmp_path / script.stem, system).run_trial(30.0)

    good, crashed = trial(clean), trial(crashing)
    run = crashed.runs[0]
    assert run["failure"] == f"{words} after writing its trajectory (8 poses: kept and scored)"
    assert run["ate_rmse"] is not None and run["ate_rmse"] == pytest.approx(good.runs[0]["ate_rmse"])
    assert run["tracking_rate"] == 1.0 and run["passed"]
    assert crashed.passed and crashed.metrics["ate_rmse"] == pytest.approx(good.metrics["ate_rmse"])
    assert crashed.metrics["failures"] == [run["failure"]] and good.metrics["failures"] == []


def test_a_crash_after_writing_an_unreadable_trajectory_is_not_scored(scripts, short, tmp_path):
    """Only a trajectory that this run wrote, that reads back and that matches the frames is scored."""
    from pytest_sal.analysis.metrics import evaluate

    argv = ["sh", "-c", f'"{sys.executable}" "$0" "$1"; kill -SEGV $$', str(scripts / "garbage.py"), "{output}"]
    result = create("command", argv=argv, sensor="mono", layout="folder").run(short, tmp_path / "w", timeout=30)
    assert result.exit_status == -11 and result.failure == "killed by SIGSEGV (segmentation fault)"
    assert "written_before_failure" not in result.info and result.info["output_error"].startswith("unparsable output")
    assert evaluate(result, short.groundtruth).ate_rmse is None


def test_depends_files_and_folders_are_part_of_the_key(tmp_path):
    script = drift_script(tmp_path / "myslam.py", 0.0)
    lib = tmp_path / "lib"
    (lib / "sub").mkdir(parents=True)
    (lib / "sub" / "model.py").write_text("A = 1\n")
    (lib / "__pycache__").mkdir()
    config = tmp_path / "config.yaml"
    config.write_text("a: 1\n")
    system = create("command", argv=[sys.executable, str(script), "{sequence}", "{output}"], depends=[str(lib), config])
    before = system.identity()
    assert set(before["files"]) == {sys.executable, str(script), str(lib.resolve()), str(config.resolve())}
    assert "{sequence}" not in before["files"]
    (lib / "__pycache__" / "model.cpython-311.pyc").write_bytes(b"\0")  # running the program writes caches
    assert system.identity() == before
    (lib / "sub" / "model.py").write_text("A = 2\n")
    after_lib = system.identity()
    assert after_lib["files"][str(lib.resolve())] != before["files"][str(lib.resolve())]
    config.write_text("a: 2\n")
    assert system.identity()["files"][str(config.resolve())] != after_lib["files"][str(config.resolve())]


def test_the_executable_is_found_on_path_and_hashed(tmp_path):
    program = tmp_path / "bin" / "myslam"
    program.parent.mkdir()
    program.write_text("#!/bin/sh\nexit 0\n")
    program.chmod(0o755)
    system = create("command", argv=["myslam", "{sequence}"], env={"PATH": str(program.parent)})
    first = system.identity()["files"]["myslam"]
    assert first is not None and len(first) == 64
    program.write_text("#!/bin/sh\nexit 1\n")
    assert system.identity()["files"]["myslam"] != first
    assert create("command", argv=["no-such-slam-program-xyz"]).identity()["files"] == {"no-such-slam-program-xyz": None}


def test_name_is_shown_in_results_and_outcomes(scripts, tmp_path):
    from pytest_sal.engine.search.requirement_search import single_outcome

    system = create(
        "command", argv=[sys.executable, str(drift_script(tmp_path / "s.py", 0.0)), "{sequence}", "{output}"], name="myslam", layout="tum"
    )
    assert system.name == "myslam" and type(system).name == "command"
    runner = trial_runner(tmp_path, system)
    result = system.run(runner.dataset.select(range(4)), tmp_path / "w", timeout=60)
    assert result.ok and result.system == "myslam"
    outcome = single_outcome(runner, runner.requirement, "test_x", 30.0)
    assert outcome.system == "myslam" and outcome.trials[0].runs[0]["system"] == "myslam"
    assert create("command", argv=["slam"]).name == "command"
    assert system.identity()["name"] == "myslam"


def test_name_and_version_change_the_key(tmp_path):
    from pytest_sal.store.cache_keys import cache_key

    def key(**options):
        return cache_key(system=create("command", argv=["slam", "{sequence}"], **options).identity())

    assert key() == key() != key(version="2.1") != key(version="2.2")
    assert key(version="2.1") == key(version="2.1")
    assert key(name="myslam") != key()
    assert create("command", argv=["slam"], version="2.1").options()["version"] == "2.1"


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"name": ""}, "option name='' is not allowed: give 1 to 64 letters, digits"),
        ({"name": "my slam"}, "option name='my slam' is not allowed"),
        ({"name": "a/b"}, "option name='a/b' is not allowed"),
        ({"name": "x" * 65}, "is not allowed: give 1 to 64"),
        ({"name": 3}, "option name=3 is not allowed"),
        ({"version": ""}, "option version='' is not allowed"),
        ({"version": ["1"]}, "option version=\\['1'\\] is not allowed"),
        ({"depends": ["/no/such/lib"]}, "depends: /no/such/lib does not exist"),
        ({"depends": "lib.py"}, "depends must be a list of strings"),
    ],
)
def test_bad_name_version_depends(options, match):
    with pytest.raises(SlamSystemError, match=match):
        create("command", argv=["slam"], **options)


def test_a_depends_file_removed_after_creation_is_a_clear_error(tmp_path):
    lib = tmp_path / "lib.py"
    lib.write_text("A = 1\n")
    system = create("command", argv=["slam"], depends=[str(lib)])
    lib.unlink()
    with pytest.raises(SlamSystemError, match=r"cannot read the depends file .*lib\.py to hash it for the cache key"):
        system.identity()


def test_a_too_big_depends_folder_is_a_clear_error(tmp_path, monkeypatch):
    import sal_wrappers.command.files as command_files

    lib = tmp_path / "lib"
    lib.mkdir()
    for i in range(3):
        (lib / f"m{i}.py").write_text("x\n")
    monkeypatch.setattr(command_files, "DEPENDS_MAX_FILES", 2)
    with pytest.raises(SlamSystemError, match="depends folder .* holds more than 2 files"):
        create("command", argv=["slam"], depends=[str(lib)]).identity()


def test_a_command_system_is_noisy_unless_it_says_it_is_deterministic() -> None:
    from pytest_sal.engine.execution.trial_runner import RunPolicy

    noisy = create("command", argv=["true"])
    steady = create("command", argv=["true"], deterministic=True)
    assert RunPolicy.for_system(noisy, None).max_runs == 5 and RunPolicy.for_system(steady, None).max_runs == 1
    assert RunPolicy.for_system(noisy, None).noisy and not RunPolicy.for_system(steady, None).noisy
    assert steady.options()["deterministic"] and steady.identity() != noisy.identity()
    with pytest.raises(SlamSystemError, match="deterministic must be True or False, got 'yes'"):
        create("command", argv=["true"], deterministic="yes")
