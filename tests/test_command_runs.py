"""Running a ``command`` system's program: crashes, exit(-1), timeouts that kill the process
group, children left behind, garbage or missing output, prefix, env, settings templates, glob
outputs, and bad use that is an error at construction."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import pytest
from command_programs import NI, assert_states, fake

from sal_wrappers import SlamSystemError, create

#: the shared fixtures (indoor, scripts, short, tiny)
pytest_plugins = ["command_programs"]


# -- failures of the program come back in words --------------------------------------------------------
def test_segfault(scripts, tiny, tmp_path):
    result = create("command", argv=[sys.executable, str(scripts / "segfault.py")], sensor="mono", layout="folder").run(
        tiny, tmp_path / "w", timeout=60
    )
    assert result.exit_status == -11
    assert "SIGSEGV" in result.failure and "segmentation fault" in result.failure
    assert "about to crash" in result.log_tail
    assert_states(result, [NI] * 2)


def test_exit_255(scripts, tiny, tmp_path):
    result = create("command", argv=[sys.executable, str(scripts / "exit255.py")], sensor="mono", layout="folder").run(
        tiny, tmp_path / "w", timeout=60
    )
    assert result.exit_status == 255 and result.failure.startswith("exit status 255")
    assert "Failed to open settings file" in result.log_tail
    assert result.log_path == tmp_path / "w" / "run.log"


def test_timeout_kills_the_process_group(scripts, tiny, tmp_path):
    pid_file = tmp_path / "child.pid"
    system = create("command", argv=[sys.executable, str(scripts / "hang.py"), str(pid_file)], sensor="mono", layout="folder")
    result = system.run(tiny, tmp_path / "w", timeout=1.0)
    assert result.failure == "timed out after 1 s and was killed"  # seconds to the result: benchmarks/bench_time_limits.py
    assert "tracking forever" in result.log_tail
    assert_gone(int(pid_file.read_text()))


def test_children_left_behind_are_killed(scripts, tiny, tmp_path):
    pid_file = tmp_path / "child.pid"
    argv = [sys.executable, str(scripts / "leave_child.py"), str(pid_file), "{output}"]
    result = create("command", argv=argv, sensor="mono", layout="folder").run(tiny, tmp_path / "w", timeout=30)
    assert result.exit_status == 0
    assert "no pose in the trajectory" in result.failure  # an empty file: nothing tracked
    assert_gone(int(pid_file.read_text()))


def assert_gone(pid: int) -> None:
    """``pid`` is dead (gone, or a zombie of a parent that does not reap); SIGKILL lands at once
    but the kernel may take a moment to act on it."""
    status = Path(f"/proc/{pid}/status")
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
            text = status.read_text()
        except (ProcessLookupError, FileNotFoundError):
            return
        if "\nState:\tZ" in text:
            return
        time.sleep(0.02)
    raise AssertionError(f"process {pid} still runs")


def test_garbage_output(scripts, tiny, tmp_path):
    result = create("command", argv=[sys.executable, str(scripts / "garbage.py"), "{output}"], sensor="mono", layout="folder").run(
        tiny, tmp_path / "w", timeout=30
    )
    out = tmp_path.resolve() / "w" / "trajectory.txt"
    assert result.exit_status == 0
    assert result.failure.startswith(f"unparsable output: {out}:2: expected 8 values")


def test_garbage_json(scripts, tiny, tmp_path):
    system = create(
        "command",
        argv=[sys.executable, str(scripts / "garbage.py"), "{output}"],
        output="out.json",
        output_format="json",
        sensor="mono",
        layout="folder",
    )
    result = system.run(tiny, tmp_path / "w", timeout=30)
    assert "unparsable output" in result.failure and "out.json:1: not valid JSON" in result.failure


def test_missing_output(scripts, tiny, tmp_path):
    result = create("command", argv=[sys.executable, str(scripts / "nothing.py")], sensor="mono", layout="folder").run(
        tiny, tmp_path / "w", timeout=30
    )
    assert result.exit_status == 0
    assert result.failure.startswith("no trajectory written:") and "trajectory.txt not found" in result.failure


def test_stale_output_outside_workdir_is_not_taken(scripts, tiny, tmp_path):
    cwd = tmp_path / "checkout"
    cwd.mkdir()
    (cwd / "CameraTrajectory.txt").write_text("0.0 0 0 0 0 0 0 1\n")
    system = create(
        "command",
        argv=[sys.executable, str(scripts / "nothing.py")],
        cwd=str(cwd),
        output="CameraTrajectory.txt",
        sensor="mono",
        layout="folder",
    )
    result = system.run(tiny, tmp_path / "w", timeout=30)
    assert "is left from before this run" in result.failure
    assert result.info["cwd"] == str(cwd)


@pytest.mark.parametrize(("argv0", "words"), [("/no/such/slam", "no such file"), ("no-such-slam-program-xyz", "not on PATH")])
def test_executable_not_found(tiny, tmp_path, argv0, words):
    result = create("command", argv=[argv0, "{sequence}"], sensor="mono", layout="folder").run(tiny, tmp_path / "w", timeout=30)
    assert result.failure == f"executable not found: {argv0!r} ({words})"
    assert result.exit_status is None and result.tracked == 0


# -- prefix, env, settings, glob output ------------------------------------------------------------
def test_prefix_and_env(scripts, short, tmp_path):
    workdir = tmp_path / "w"
    argv = fake(scripts, "--need-env", "FOO=1", "--need-env", f"WHERE={workdir.resolve()}")
    without = create("command", argv=argv, env={"WHERE": "{workdir}"}, sensor="mono", layout="tum").run(short, workdir, timeout=60)
    assert without.exit_status == 7 and "environment FOO=None" in without.log_tail
    system = create("command", argv=argv, prefix=["env", "FOO=1"], env={"WHERE": "{workdir}"}, sensor="mono", layout="tum")
    result = system.run(short, workdir, timeout=60)
    assert result.ok, (result.failure, result.log_tail)
    assert result.info["argv"][:2] == ["env", "FOO=1"]


def test_settings_template_is_rendered(scripts, short, tmp_path):
    template = tmp_path / "Synthetic.yaml"
    template.write_text(
        "%YAML:1.0\nCamera.fx: {camera_fx}\nCamera.fps: {fps}\nsize: {camera_width}x{camera_height}\nbf: {camera_bf}\nliteral: {{x}}\n"
    )
    system = create("command", argv=fake(scripts, "--need-file", "{settings}"), settings=str(template), sensor="mono", layout="tum")
    result = system.run(short, tmp_path / "w", timeout=60)
    assert result.ok, result.failure
    rendered = Path(result.info["settings"])
    assert rendered.parent == tmp_path.resolve() / "w" / "settings"
    assert rendered.read_text() == "%YAML:1.0\nCamera.fx: 525.0\nCamera.fps: 30\nsize: 640x480\nbf: 0.0\nliteral: {x}\n"


def test_glob_output_and_helper_files(scripts, short, tmp_path):
    argv = [*fake(scripts, "--need-file", "{timestamps}", "--need-file", "{associations}")]
    argv[argv.index("{output}")] = "{workdir}/logs/run/short.txt"
    system = create("command", argv=argv, output="logs/*/*.txt", layout="tum")
    result = system.run(short, tmp_path / "w", timeout=60)
    assert result.ok, (result.failure, result.log_tail)
    assert result.info["output"] == str(tmp_path.resolve() / "w" / "logs" / "run" / "short.txt")
    assert result.sensor == "rgbd"
    pairs = (tmp_path / "w" / "associations.txt").read_text().splitlines()
    assert len(pairs) == 6 and pairs[0].split()[1] == "rgb/000000.png" and pairs[0].split()[3] == "depth/000000.png"
    ns = (tmp_path / "w" / "timestamps_ns.txt").read_text().split()
    assert ns[:2] == ["0", "33333333"]


def test_mono_mode_stages_no_depth(scripts, short, tmp_path):
    system = create("command", argv=fake(scripts), sensor="mono", layout="tum", stage_dir="data/tum/fr3")
    result = system.run(short, tmp_path / "w", timeout=60)
    staged = Path(result.info["staged"])
    assert staged == tmp_path.resolve() / "w" / "data" / "tum" / "fr3"
    assert (staged / "rgb.txt").is_file() and not (staged / "depth.txt").exists()


def test_exit_127_from_a_prefix(tiny, tmp_path):
    system = create("command", argv=["no-such-slam-program-xyz"], prefix=["env", "FOO=1"], sensor="mono", layout="folder")
    result = system.run(tiny, tmp_path / "w", timeout=30)
    assert result.failure == "exit status 127 (command not found by the shell or prefix)"
    assert "no-such-slam-program-xyz" in result.log_tail


# -- bad use is an error at construction --------------------------------------------------------------
@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"argv": ["slam", "{sequnce}"]}, r"unknown placeholder \{sequnce\} in argv\[1\].*known: \{sequence\}, \{workdir\}"),
        ({"argv": ["slam"], "prefix": ["docker", "-v", "{wrkdir}:/w"]}, r"unknown placeholder \{wrkdir\} in prefix\[2\]"),
        (
            {"argv": "slam {sequence} {output}"},
            r"argv must be a list of strings, not a shell string: pass \['slam', '\{sequence\}', '\{output\}'\]",
        ),
        ({"argv": []}, "argv is empty"),
        ({}, "argv is required"),
        ({"argv": ["slam", 3]}, r"argv\[1\] must be a string"),
        ({"argv": ["slam", "{settings}"]}, "no settings template was given"),
        ({"argv": ["slam"], "settings": "/no/such.yaml"}, "settings template not found: /no/such.yaml"),
        ({"argv": ["slam"], "output_format": "csv"}, "output_format 'csv' is not known; allowed: tum, kitti, euroc, json"),
        ({"argv": ["slam"], "time_unit": "min"}, "time_unit 'min' is not known"),
        (
            {"argv": ["slam"], "layout": "kiti"},
            "layout 'kiti' is not a dataset layout; allowed: euroc, folder, kitti, rosbag, synthetic, tum, video",
        ),
        ({"argv": ["slam"], "layout": "kitti", "sensor": "rgbd"}, "the kitti layout cannot hold rgbd data"),
        ({"argv": ["slam"], "sensor": "lidar"}, "sensor 'lidar' is not known"),
        ({"argv": ["slam", "{output}"], "output": "logs/*.txt"}, "is a glob pattern"),
        ({"argv": ["slam"], "features": 2000}, "unknown option 'features'; allowed: argv, prefix, output"),
        ({"argv": ["slam"], "env": {"A": 1}}, "env must map variable names to strings"),
        ({"argv": ["slam"], "output": "{output_times}"}, r"output cannot use \{output_times\}"),
        ({"argv": ["slam"], "stage_dir": "../elsewhere"}, "stage_dir must be a relative folder"),
        ({"argv": ["slam"], "stage_dir": "settings"}, "stage_dir must be a relative folder"),
    ],
)
def test_bad_options(options, match):
    with pytest.raises(SlamSystemError, match=match):
        create("command", **options)


def test_unknown_placeholder_in_settings_names_file_and_line(tmp_path):
    template = tmp_path / "s.yaml"
    template.write_text("a: 1\nb: {camera_fz}\n")
    with pytest.raises(SlamSystemError, match=rf"{template}:2: unknown placeholder \{{camera_fz\}}"):
        create("command", argv=["slam", "{settings}"], settings=str(template))


def test_stereo_mode_on_a_mono_sequence_is_bad_use(indoor, tmp_path):
    with pytest.raises(SlamSystemError, match="cannot run in 'stereo' mode"):
        create("command", argv=["slam"], sensor="stereo").run(indoor, tmp_path / "w")


# -- an empty sequence is a failed run, not an exception (issue 23, item 2) ------------------------------
def test_an_empty_sequence_is_a_failed_run_with_the_reason(scripts, tiny, tmp_path):
    """frame_drop at drop_rate = 1 leaves no frame: staging used to raise ``DatasetError: ...:
    no frames to write`` out of ``run()``, failing every team's frame-drop search."""
    empty = tiny.select([])
    result = create("command", argv=fake(scripts), sensor="mono", layout="folder").run(empty, tmp_path / "w", timeout=60)
    assert result.failure == "the sequence has no frames (every frame dropped?): nothing to run on"
    assert len(result.states) == 0 and result.exit_status is None


def test_a_search_that_drops_every_frame_fails_those_runs_for_every_system(scripts, indoor, tmp_path):
    """Through the trial runner (``run_job``), whatever the system: the run at drop_rate = 1
    fails with the reason and the trial is a failed trial, not an error."""
    from pytest_sal import tracking_rate
    from pytest_sal.engine.execution.trial_runner import TrialRunner
    from pytest_sal.engine.requirements import Requirement
    from pytest_sal.testing import FakeSlam
    from sal_modules import frame_drop

    requirement = Requirement.build([tracking_rate >= 0.5, frame_drop.drop_rate <= 0.3])
    command = create("command", argv=fake(scripts), sensor="mono", layout="folder")
    for system in (command, FakeSlam()):
        runner = TrialRunner(indoor.select(range(6)), frame_drop.drop_rate.ref(), system, requirement, workdir=tmp_path / system.name)
        trial = runner.run_trial(1.0)
        assert not trial.passed, system.name
        assert trial.runs[0]["failure"] == "the sequence has no frames (every frame dropped?): nothing to run on", trial.runs[0]
