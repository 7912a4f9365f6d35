"""make_executor: the executor --sal-executor names, and the one usage error without Ray; what
a RayExecutor says before it connects (nothing here starts Ray)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from pytest_sal.engine.execution.executor import ExecutorError, LocalExecutor
from pytest_sal.engine.execution.executor_factory import make_executor
from sal_wrappers import create


def test_local_is_the_in_process_executor_and_takes_no_options() -> None:
    assert isinstance(make_executor("local"), LocalExecutor)
    assert make_executor("local", address="ray://ignored:10001").describe() == "local"
    with pytest.raises(ExecutorError, match="the local executor takes no options; got num_cpus"):
        make_executor("local", num_cpus=2)


def test_an_unknown_executor_names_the_valid_ones() -> None:
    with pytest.raises(ExecutorError, match=r"unknown executor 'dask'; valid: local, ray"):
        make_executor("dask")


def test_ray_without_ray_installed_is_one_usage_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray now fails as if it were not installed
    monkeypatch.delitem(sys.modules, "pytest_sal.engine.execution.ray_executor", raising=False)
    with pytest.raises(ExecutorError) as error:
        make_executor("ray")
    assert str(error.value) == "--sal-executor ray needs Ray: pip install 'pytest-sal[ray]'"
    assert error.value.__cause__ is None and error.value.__suppress_context__


def test_a_ray_executor_starts_nothing_until_its_first_run() -> None:
    executor = make_executor("ray", num_cpus=3, max_retries=1)
    assert executor.name == "ray" and executor.describe() == "ray (local, starts on the first run)"
    assert executor.address == "" and executor.submitted == 0
    reference_vo, droid = create("reference_vo"), create("command", argv=["true"], num_cpus=2, num_gpus=1)
    assert executor.slots(reference_vo) == 3  # a local Ray's 3 CPUs, estimated without starting it
    assert executor.slots(droid) == 1  # 3 // 2 = 1 (the GPUs are not known before it starts)
    remote = make_executor("ray", "ray://head.example:10001")
    assert remote.describe() == "ray at ray://head.example:10001 (joined on the first run)"
    assert remote.slots(reference_vo) == 1 and remote.address == "ray://head.example:10001"
    executor.close()  # nothing to shut down
    remote.close()


def test_a_local_rays_token_file_is_private_to_its_user(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Ray wrote ~/.ray/auth_token 0644 in a 0755 folder, and another local user connected
    with it and ran a task as the CI user (issue 23, item 11): the plugin writes it 0600 in a
    0700 folder, and makes an existing one 0600."""
    pytest.importorskip("ray", reason="the ray extra is not installed")
    from pytest_sal.engine.execution.ray_executor import private_home_token

    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.delenv("RAY_AUTH_TOKEN", raising=False)
    monkeypatch.delenv("RAY_AUTH_TOKEN_PATH", raising=False)
    path = private_home_token()
    assert path == tmp_path / ".ray" / "auth_token"
    assert path.stat().st_mode & 0o777 == 0o600 and path.parent.stat().st_mode & 0o777 == 0o700
    token = path.read_text()
    assert len(token) >= 32
    path.chmod(0o644)  # written by Ray before this fix
    assert private_home_token() == path and path.stat().st_mode & 0o777 == 0o600 and path.read_text() == token
    monkeypatch.setenv("RAY_AUTH_TOKEN", "given")  # the environment gives the token: no file is made
    path.unlink()
    assert private_home_token() is None and not path.exists()
