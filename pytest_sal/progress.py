"""Live progress of robustness tests: under ``pytest -v``, one line per trial as it finishes.

A boundary search can take minutes per test item; without this nothing shows until the item
ends. ``trial_printer`` gives the ``TrialRunner.progress`` callback that prints
``trial_line`` (the one rendering of a trial as text, also used by the report section of each
test) as each trial ends:

* without xdist, through the terminal reporter, between the item's id and its verdict (as
  pytest's live logging does);
* on an xdist worker, whose stdout is not the terminal (execnet points it at ``/dev/null``),
  on the worker's stderr, which it inherits from the controller: the line shows on the
  controller's terminal at once, prefixed with the worker's id (``[gw0]``).

Output capture is suspended around the write (``-s`` or not), so the line is never held back
until the test ends.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Sequence
from typing import Any

from pytest_sal.engine.outcomes.outcome import Trial
from pytest_sal.report.formatting import short_id, trial_line

__all__ = ["trial_printer"]


def trial_printer(config: Any, test_id: str, parameter: str, unit: str, metrics: Sequence[str]) -> Callable[[Trial], None] | None:
    """A ``TrialRunner.progress`` callback printing ``<short test id>  <trial_line>`` live
    (see the module text), or ``None`` without ``-v`` (``config``: the pytest config)."""
    if config.get_verbosity() < 1:
        return None
    capture = config.pluginmanager.getplugin("capturemanager")
    terminal = config.pluginmanager.getplugin("terminalreporter")
    worker = getattr(config, "workerinput", {}).get("workerid")
    prefix = f"[{worker}] " if worker else "  "
    name = short_id(test_id)

    def show(trial: Trial) -> None:
        line = f"{prefix}{name}  {trial_line(trial, parameter, unit, metrics)}"
        with capture.global_and_fixture_disabled() if capture is not None else contextlib.nullcontext():
            if worker is None and terminal is not None:
                terminal.write_line(line)
                terminal.flush()
            else:
                sys.stderr.write(line + "\n")
                sys.stderr.flush()

    return show
