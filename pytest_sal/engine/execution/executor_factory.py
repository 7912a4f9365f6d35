"""``make_executor``: the executor ``--sal-executor`` names, with its options.

A module of its own so that ``pytest_sal.engine.execution.ray_executor`` (which imports Ray) is imported
only when ``ray`` is asked for, and without an import cycle: it builds on ``executor``.
"""

from __future__ import annotations

from typing import Any

from pytest_sal.engine.execution.executor import EXECUTORS, Executor, ExecutorError, LocalExecutor

__all__ = ["make_executor"]


def make_executor(name: str, address: str = "", **options: Any) -> Executor:
    """The executor called ``name``: ``local`` (``LocalExecutor``; ``address`` does not apply to
    it) or ``ray`` (``RayExecutor(address, **options)``: its keyword options ``num_cpus``,
    ``max_retries``, ``temp_dir``). Nothing connects here: Ray starts or is joined on the first
    run.

    Raises:
        ExecutorError: an unknown name (naming the valid ones), options ``local`` does not
            take, or ``ray`` without Ray installed.
    """
    if name == "local":
        if options:
            raise ExecutorError(f"the local executor takes no options; got {', '.join(sorted(options))}")
        return LocalExecutor()
    if name == "ray":
        try:
            from pytest_sal.engine.execution.ray_executor import RayExecutor
        except ModuleNotFoundError as exc:
            if exc.name != "ray" and not (exc.name or "").startswith("ray."):
                raise
            raise ExecutorError("--sal-executor ray needs Ray: pip install 'pytest-sal[ray]'") from None
        return RayExecutor(address, **options)
    raise ExecutorError(f"unknown executor {name!r}; valid: {', '.join(EXECUTORS)}")
