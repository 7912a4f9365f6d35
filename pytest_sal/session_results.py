"""What a pytest session leaves behind, on its controller (or in a session without xdist): the
outcomes its test reports carry, the run history and reports written at the end, and the
summary in the terminal."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from pytest_sal.history.gate import NOT_COMPARED
from pytest_sal.options import SalOptions

if TYPE_CHECKING:
    from pytest_sal.engine.outcomes.outcome import Outcome

__all__ = ["SessionResults", "outcome_of"]


def outcome_of(report: pytest.TestReport) -> Outcome | None:
    """The ``Outcome`` a report carries (its ``sal_outcome`` user property), or ``None``."""
    for name, value in report.user_properties:
        if name == "sal_outcome":
            from pytest_sal.engine.outcomes.outcome import Outcome

            return Outcome.from_dict(json.loads(str(value)))
    return None


class SessionResults:
    """The outcomes of one session's robustness tests and what becomes of them at its end."""

    def __init__(self, config: pytest.Config, options: SalOptions) -> None:
        self.config = config
        self.options = options
        self.load_at_start = os.getloadavg() if hasattr(os, "getloadavg") else None
        self.outcomes: list[Outcome] = []
        self.unwritten: list[str] = []  # outputs finish() could not write, said in the summary
        self.written: list[Path] = []  # the files finish() wrote, named in the summary
        self.notes: list[str] = []  # said at the end of the summary (a run saved without its name)

    def collect(self, report: pytest.TestReport) -> None:
        """Keep the outcome of a call-phase ``report`` (on the controller only: under xdist the
        workers' reports reach it)."""
        if report.when == "call" and not hasattr(self.config, "workerinput"):  # controller or plain session
            outcome = outcome_of(report)
            if outcome is not None:
                self.outcomes.append(outcome)

    def terminal_summary(self, terminal: Any) -> None:
        """The boundaries table, then the outputs written or not and the notes."""
        if not self.outcomes:
            return
        from pytest_sal.report.outcome_report import terminal_table

        terminal.section("pytest-sal robustness boundaries")
        for line in terminal_table(self.outcomes, width=max(self.config.get_terminal_writer().fullwidth, 120)):
            terminal.write_line(line)
        for problem in self.unwritten:
            terminal.write_line(f"pytest-sal: {problem}", red=True)
        for path in self.written:
            terminal.write_line(f"pytest-sal: wrote {_shown(path)}")
        for note in self.comparison_notes() + self.notes:
            terminal.write_line(f"pytest-sal: {note}", yellow=True)

    def comparison_notes(self) -> list[str]:
        """What the gate could not compare, in one line (``--sal-compare-missing`` says what
        that did to the tests)."""
        missing = [o for o in self.outcomes if o.comparison.startswith(NOT_COMPARED)]
        if not missing:
            return []
        effect = (
            "failed" if self.options.compare_missing == "fail" else "passed without a comparison; --sal-compare-missing=fail fails them"
        )
        return [
            f"{len(missing)} of {len(self.outcomes)} tests not compared with {self.options.compare!r} ({effect}): "
            f"{missing[0].comparison[len(NOT_COMPARED) :]}"
        ]

    def finish(self) -> None:
        """Write the history and the reports; ``terminal_summary`` then names each file written
        (``pytest-sal: wrote report/index.html``)."""
        if not self.outcomes:
            return
        from pytest_sal.history.provenance import commit_info, machine_info
        from pytest_sal.history.run_history import History

        commit, dirty = commit_info(self.config.rootpath)
        machine = dict(machine_info(), load_avg_start=self.load_at_start)
        for outcome in self.outcomes:
            outcome.commit = commit + ("+dirty" if dirty else "")
        from pytest_sal.report.outcome_page import write_html_report
        from pytest_sal.report.outcome_report import write_markdown
        from sal_adapters.common.atomic import writing
        from sal_adapters.common.errors import WriteError

        name = self._save_name()
        history = History(self.options.history_dir)
        writes: list[tuple[str, Path, Callable[[], Path]]] = []
        if self.options.save_history:
            writes.append(("history", self.options.history_dir, lambda: history.append_run(self.outcomes, name=name, machine=machine)))
        if (markdown := self.options.report_md) is not None:
            writes.append(("--sal-report-md", markdown, lambda: write_markdown(self.outcomes, markdown)))
        if (html := self.options.report_html) is not None:
            writes.append(("--sal-report-html", html, lambda: write_html_report(self.outcomes, html)))
        for what, path, write in writes:
            try:  # a full disk or a read-only folder costs that output, not the tests' results
                with writing(path):
                    self.written.append(write())
            except WriteError as exc:
                self.unwritten.append(f"{what} not written: {exc}")

    def _save_name(self) -> str | None:
        """``--sal-save``'s name, unless a test of this run failed the gate: a regressed run is
        saved without the name, so it cannot replace the baseline (said in the summary)."""
        name = self.options.save_name
        failed = [o for o in self.outcomes if o.regression]
        if name and failed:
            self.notes.append(
                f"this run is saved without the name {name!r}: {len(failed)} test(s) failed the --sal-compare gate, so it cannot become the baseline"
            )
            return None
        return name


def _shown(path: Path) -> str:
    """``path`` for a message: as the user gave it when relative, else relative to the working
    directory when it lies below it, else whole."""
    if path.is_absolute() and path.is_relative_to(Path.cwd()):
        return str(path.relative_to(Path.cwd()))
    return str(path)
