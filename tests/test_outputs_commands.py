"""The ``sal`` commands' outputs are replaced whole or not at all, with the umask's permissions,
and a write that fails names its path (issue 12, points 2, 3, 6 and 7), on ``sal perturb`` over a
small synthetic experiment:

* ``sal perturb --dry-run`` leaves the caches, the output folder and HOME as they were;
* ``kill -9`` of a ``sal perturb`` rerun at 0.3 s, 1 s, 2 s, when its first staging folder
  appears and just before it renames: the previous output is intact, byte for byte; the next
  run cleans the leftovers;
* a full disk or a file where a folder belongs: one ``sal: error: cannot write PATH: ...``;
* ``sal evaluate`` and ``sal report`` stopped midway: the previous results stay whole;
* files 0644 and folders 0755 under umask 022, private under 077."""

from __future__ import annotations

import errno
import hashlib
import os
import shutil
import signal
import stat
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from output_leftovers import LEFTOVER, leftovers

from pytest_sal.cli.main import main
from pytest_sal.testing import FakeSlam
from sal_adapters import SalError
from sal_wrappers import SYSTEMS

NAME = "outputs"


CONFIG = """\
experiment: {{name: {name}, seed: 3}}
dataset:
  type: synthetic
  options: {{scene: urban, frames: {frames}, sensor: mono}}
perturbations:
  - {{name: fog, type: fog, parameters: {{visibility_m: {visibility}}}}}
  - {{name: rain, type: rain, parameters: {{intensity_mm_h: 40}}}}
  - {{name: drop, type: frame_drop, parameters: {{drop_rate: 0.3}}}}
output: {{base_dir: {base_dir}}}
"""


def write_config(folder: Path, *, visibility: float = 60, frames: int = 8, base_dir: str = "results") -> Path:
    path = folder / f"{NAME}-{visibility:g}.yaml"
    path.write_text(CONFIG.format(name=NAME, frames=frames, visibility=visibility, base_dir=base_dir))
    return path


def snapshot(root: Path) -> dict[str, str]:
    """Every visible file and folder under ``root``: relative path -> SHA-256 (``dir`` for
    folders); staging and old copies left by a killed run are not part of the output."""
    found = {}
    for path in sorted(root.rglob("*")):
        rel = path.relative_to(root).as_posix()
        if any(mark in rel for mark in LEFTOVER):
            continue
        found[rel] = "dir" if path.is_dir() else hashlib.sha256(path.read_bytes()).hexdigest()
    return found


def sal(*args: str | Path, cwd: Path, **kwargs: object) -> subprocess.Popen[bytes]:
    """``sal ARGS`` in a child process (the environment of this session: its isolated caches)."""
    return subprocess.Popen(
        [sys.executable, "-m", "pytest_sal.cli.main", *map(str, args)], cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, **kwargs
    )  # type: ignore[call-overload]


def error_line(capsys: pytest.CaptureFixture[str]) -> str:
    """The one ``sal: error:`` line on stderr (progress bars may come before it)."""
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("sal: error:") == 1, err
    return err.splitlines()[-1]


def finished(process: subprocess.Popen[bytes]) -> None:
    _, err = process.communicate(timeout=300)
    assert process.returncode == 0, err.decode()


# ---------------------------------------------------------------------------------------- dry run


def test_dry_run_touches_nothing_on_disk(tmp_path: Path) -> None:
    home = tmp_path / "home"
    env = {**os.environ, "HOME": str(home), "XDG_CACHE_HOME": str(home / ".cache"), "XDG_CONFIG_HOME": str(home / ".config")}
    env["SAL_CACHE_DIR"] = str(home / "sal-cache")
    work = tmp_path / "work"
    work.mkdir()
    config = write_config(work)
    before = snapshot(tmp_path)  # a fresh home: not even matplotlib's font list may appear

    out = subprocess.run(
        [sys.executable, "-m", "pytest_sal.cli.main", "perturb", str(config), "--dry-run", "--cache-dir", str(tmp_path / "trials")],
        cwd=work,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )

    assert out.returncode == 0, out.stderr
    assert "dry run: nothing written" in out.stdout
    assert "synthetic" in out.stdout and "8 frames" in out.stdout  # the dataset was resolved
    assert snapshot(tmp_path) == before
    assert leftovers(tmp_path) == []


# ------------------------------------------------------------------------------- kill -9 of a rerun


def _kill_after(seconds: float) -> Callable[[Path], None]:
    def wait(root: Path) -> None:
        time.sleep(seconds)

    return wait


def _kill_when_staging(root: Path) -> None:
    deadline = time.monotonic() + 120
    while not list(root.parent.glob(f".{root.name}.sal-tmp-*/images/*")):
        assert time.monotonic() < deadline, "no staging folder appeared"
        time.sleep(0.005)


#: the child pauses when its last output is staged, just before the renames
PAUSE_BEFORE_COMMIT = """
import sys, time
from pathlib import Path
from sal_adapters.common.atomic import Replacement
from pytest_sal.cli.main import main
from pytest_sal.testing import FakeSlam

def paused(self, target, text, write_text=Replacement.write_text):
    staged = write_text(self, target, text)
    if Path(target).name == "config.yaml":
        Path(sys.argv[1]).touch()
        time.sleep(300)
    return staged

Replacement.write_text = paused
sys.exit(main(sys.argv[2:]))
"""


@pytest.fixture
def children() -> Iterator[list[subprocess.Popen[bytes]]]:
    """Child processes a test starts; any still running at its end are killed."""
    started: list[subprocess.Popen[bytes]] = []
    yield started
    for process in started:
        if process.poll() is None:
            process.kill()
        process.communicate()


def test_kill_9_of_a_rerun_keeps_the_previous_output(tmp_path: Path, children: list[subprocess.Popen[bytes]]) -> None:
    old_config, new_config = (write_config(tmp_path, visibility=v, frames=24) for v in (60, 25))  # a rerun: ~5 s
    root = tmp_path / "results" / NAME
    finished(sal("perturb", old_config, "--cache-dir", tmp_path / "trials-old", cwd=tmp_path))
    before = snapshot(root)
    assert {"pipeline_results.json", "config.yaml", "images/fog/sal_sequence.json", "images/drop/dropped_frames.txt"} <= set(before)

    moments = {"0.3 s": _kill_after(0.3), "1 s": _kill_after(1.0), "2 s": _kill_after(2.0), "staging appears": _kill_when_staging}
    for k, (moment, wait) in enumerate(moments.items()):
        process = sal("perturb", new_config, "--cache-dir", tmp_path / f"trials-{k}", cwd=tmp_path)  # nothing cached: seconds of work
        children.append(process)
        wait(root)
        assert process.poll() is None, f"the rerun ended before the kill at {moment}"
        process.send_signal(signal.SIGKILL)
        process.wait()
        assert snapshot(root) == before, f"kill -9 at {moment} changed the previous output"

    flag = tmp_path / "staged"
    process = subprocess.Popen(
        [sys.executable, "-c", PAUSE_BEFORE_COMMIT, str(flag), "perturb", str(new_config), "--cache-dir", str(tmp_path / "trials-old")],
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    children.append(process)
    while not flag.exists():  # no clock: the child stages its outputs or ends
        assert process.poll() is None, "the child ended without staging its outputs"
        time.sleep(0.01)
    staged = root.parent / leftovers(root.parent)[0]  # one staged copy of the experiment folder
    assert leftovers(root.parent) == [staged.name] and {"fog", "rain", "drop"} <= set(os.listdir(staged / "images"))
    process.send_signal(signal.SIGKILL)
    process.wait()
    assert snapshot(root) == before, "kill -9 just before the renames changed the previous output"

    finished(sal("perturb", new_config, "--cache-dir", tmp_path / "trials-old", cwd=tmp_path))
    after = snapshot(root)
    assert leftovers(root.parent) == []  # the killed runs' staging folders are gone
    assert set(after) == set(before) and after["images/rain/sal_sequence.json"] == before["images/rain/sal_sequence.json"]
    assert after["images/fog/image_left/000000.png"] != before["images/fog/image_left/000000.png"]  # the new fog
    assert "visibility_m: 25" in (root / "config.yaml").read_text()


# ------------------------------------------------------------------------ disk full, no folder


def test_disk_full_is_one_line_naming_the_path_and_keeps_the_output(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    config = write_config(tmp_path, frames=4)
    monkeypatch.chdir(tmp_path)
    assert main(["perturb", str(config)]) == 0
    root = tmp_path / "results" / NAME
    before = snapshot(root)
    capsys.readouterr()

    def full_disk(source: str, target: str | Path) -> None:
        with open(target, "wb") as handle:
            handle.write(b"\x89PNG part")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # what write(2) raises: no path

    monkeypatch.setattr(shutil, "copyfile", full_disk)
    assert main(["perturb", str(config)]) == 2

    assert error_line(capsys) == f"sal: error: cannot write {Path('results') / NAME / 'images' / 'fog'}: No space left on device"
    assert snapshot(root) == before
    assert leftovers(root) == []


def test_a_file_where_the_output_folder_belongs_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "taken").write_text("a file, not a folder\n")
    config = write_config(tmp_path, frames=4, base_dir="taken/results")
    monkeypatch.chdir(tmp_path)

    assert main(["perturb", str(config)]) == 2

    assert error_line(capsys) == f"sal: error: cannot write {Path('taken/results') / NAME / 'images' / 'fog'}: Not a directory"

    (tmp_path / "taken").unlink()
    (tmp_path / "taken" / "results" / NAME).mkdir(parents=True)
    (tmp_path / "taken" / "results" / NAME / "images").write_text("a file, not a folder\n")
    assert main(["perturb", str(config)]) == 2
    images = Path("taken/results") / NAME / "images"
    assert error_line(capsys) == f"sal: error: cannot write {images / 'fog'}: {images} is a file, not a folder"


class StoppingSlam(FakeSlam):
    """FakeSlam that stops the evaluation (a ``SalError``) when it meets the rain."""

    def run(self, sequence: Any, workdir: Path, timeout: float | None = None) -> Any:
        if sequence.name.endswith("+rain"):
            raise SalError("stopped in the rain")
        return super().run(sequence, workdir, timeout)


def test_evaluate_and_report_stopped_midway_keep_the_previous_results(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    config = write_config(tmp_path, frames=4)
    monkeypatch.chdir(tmp_path)
    root = tmp_path / "results" / NAME
    SYSTEMS.register("fake", FakeSlam)
    try:
        assert main(["evaluate", str(config), "--slam", "fake"]) == 0
        assert main(["report", str(config)]) == 0
        evaluated, reported = snapshot(root / "slam_results"), snapshot(root / "report")
        assert "fake/metrics/summary.json" in evaluated and "assets" in reported
        capsys.readouterr()
        SYSTEMS.unregister("fake")
        SYSTEMS.register("fake", StoppingSlam)

        assert main(["evaluate", str(config), "--slam", "fake"]) == 2
        assert error_line(capsys) == "sal: error: stopped in the rain"
        assert snapshot(root / "slam_results") == evaluated and leftovers(root) == []

        monkeypatch.setattr(
            shutil, "copyfile", lambda source, target: (_ for _ in ()).throw(OSError(errno.ENOSPC, os.strerror(errno.ENOSPC)))
        )
        assert main(["report", str(config)]) == 2
        err = error_line(capsys)
        assert err.startswith(f"sal: error: cannot write {Path('results') / NAME / 'report' / 'assets'}/") and err.endswith(
            ".png: No space left on device"
        )
        assert snapshot(root / "report") == reported and leftovers(root) == []
    finally:
        SYSTEMS.unregister("fake")


# ------------------------------------------------------------------------------------ file modes


@pytest.mark.parametrize(("umask", "file_mode", "dir_mode"), [(0o022, 0o644, 0o755), (0o077, 0o600, 0o700)], ids=["umask-022", "umask-077"])
def test_outputs_and_caches_get_the_umask_permissions(tmp_path: Path, umask: int, file_mode: int, dir_mode: int) -> None:
    config = write_config(tmp_path, frames=3)
    env = {**os.environ, "SAL_CACHE_DIR": str(tmp_path / "renders")}  # rendered under this umask
    trials = tmp_path / "trials"
    process = sal("perturb", config, "--cache-dir", trials, cwd=tmp_path, env=env, umask=umask)
    finished(process)

    entries = [marker.parent for marker in trials.rglob("sal_sequence.json")]
    assert entries, "no cached sequence"
    checked = 0
    for top in [tmp_path / "results", tmp_path / "renders", *entries]:
        for path in [top, *top.rglob("*")]:
            mode = stat.S_IMODE(path.stat().st_mode)
            assert mode == (dir_mode if path.is_dir() else file_mode), f"{path}: {mode:o}"
            checked += 1
    assert checked > 50
