"""Run history: one JSON file per test session (the regression checks against it are in
``pytest_sal.history.regression``, the machine and commit each run records in
``pytest_sal.history.provenance``).

A run is written by ``History.append_run`` as ``NNNN_<commit>_<UTC time>[_<name>].json`` under
the history root (default ``.sal/history``)::

    {"version": 1, "created": "2025-05-01T12:00:00+00:00", "commit": "1a2b3c4", "dirty": false,
     "machine": {"hostname": ..., "platform": ..., "cpu_count": ..., "python": ...},
     "name": "nightly", "outcomes": [Outcome.to_dict(), ...]}

Writers never collide and readers never see half a file: the run number is reserved by an
exclusive create of ``.numbers/NNNN`` (retried with the next number on ``FileExistsError``, so
parallel sessions get distinct numbers and a number is never reused), and the JSON is written to a
temporary file in the same folder, then moved into place with ``os.replace``.

An outcome is identified across runs by its key ``(test_id, system, dataset)``; ``previous``
finds the outcome a new one is compared with.

The run history is user-owned: commit ``.sal/history`` to keep the robustness of each commit on
record, or add it to ``.gitignore`` to keep it per machine.
"""

from __future__ import annotations

import json
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from pytest_sal.engine.outcomes.outcome import Outcome
from pytest_sal.history.provenance import commit_info, machine_info
from pytest_sal.history.run_file import FORMAT_VERSION, read_document, read_outcomes
from sal_adapters.common.errors import SalError
from sal_adapters.common.json_values import json_safe
from sal_adapters.common.textfiles import atomic_write_text

__all__ = [
    "DEFAULT_ROOT",
    "FORMAT_VERSION",
    "History",
    "OutcomeKey",
    "RunRecord",
    "outcome_key",
]

#: where runs are kept unless configured otherwise (relative to the working directory)
DEFAULT_ROOT = Path(".sal/history")
#: identifies an outcome across runs
OutcomeKey = tuple[str, str, str]

_RUN_FILE = re.compile(r"^(\d{4,})_.*\.json$")
_NUMBERS = ".numbers"  # reservations of run numbers, one empty file each


def outcome_key(outcome: Outcome) -> OutcomeKey:
    """``(test_id, system, dataset)``: what makes two outcomes of different runs comparable."""
    return (outcome.test_id, outcome.system, outcome.dataset)


@dataclass
class RunRecord:
    """One saved session run.

    Attributes:
        number: the run number (``label`` is its four-digit form, ``"0003"``).
        path: the JSON file.
        created: ISO 8601 UTC time of writing.
        commit, dirty: the git commit (``""`` when unknown) and whether the tree had changes.
        machine: ``machine_info()`` (or what the caller gave).
        name: the run's name (``--sal-save=NAME``), or ``None``.
        outcomes: the outcomes of the run, in the order given.
    """

    number: int
    path: Path
    created: str
    commit: str
    dirty: bool
    machine: dict[str, Any]
    name: str | None
    outcomes: list[Outcome] = field(default_factory=list)

    @property
    def label(self) -> str:
        return f"{self.number:04d}"

    def get(self, key: Sequence[str]) -> Outcome | None:
        """The outcome with ``key`` (``(test_id, system, dataset)``, a list read from JSON too) in
        this run (the last one, should it appear twice)."""
        wanted = tuple(key)
        found = None
        for outcome in self.outcomes:
            if outcome_key(outcome) == wanted:
                found = outcome
        return found


class History:
    """The runs saved under ``root`` (default ``.sal/history``), oldest first.

    Files are read when first needed and again when the folder's listing changes; a file that is
    not a readable run is skipped with a warning naming it.
    """

    def __init__(self, root: str | Path = DEFAULT_ROOT) -> None:
        self.root = Path(root)
        self._cache: dict[Path, RunRecord | None] = {}

    def __repr__(self) -> str:
        return f"History({str(self.root)!r})"

    # writing

    def append_run(
        self,
        outcomes: list[Outcome],
        *,
        name: str | None = None,
        commit: str | None = None,
        dirty: bool | None = None,
        machine: dict[str, Any] | None = None,
    ) -> Path:
        """Save ``outcomes`` as the next run; return its path.

        Args:
            outcomes: the session's outcomes.
            name: a name for the run (``previous(..., ref=name)`` finds it); in the file name,
                characters other than letters, digits, ``.``, ``-`` and ``_`` become ``-``.
            commit, dirty: default ``commit_info()`` of the working directory.
            machine: default ``machine_info()``.

        An outcome without ``commit`` or ``machine`` gets the run's (commit, hostname) in the
        file; the objects passed in are not changed.
        """
        if commit is None or dirty is None:
            found_commit, found_dirty = commit_info()
            commit = found_commit if commit is None else commit
            dirty = found_dirty if dirty is None else dirty
        machine = machine_info() if machine is None else dict(machine)
        now = datetime.now(UTC)
        records = []
        for outcome in outcomes:
            data = outcome.to_dict()
            data["commit"] = data.get("commit") or commit
            data["machine"] = data.get("machine") or str(machine.get("hostname", ""))
            records.append(data)
        document = {
            "version": FORMAT_VERSION,
            "created": now.isoformat(timespec="seconds"),
            "commit": commit,
            "dirty": bool(dirty),
            "machine": machine,
            "name": name,
            "outcomes": records,
        }
        text = json.dumps(json_safe(document), indent=2, allow_nan=False) + "\n"
        self.root.mkdir(parents=True, exist_ok=True)
        number = self._reserve_number()
        stem = f"{number:04d}_{commit or 'nogit'}{'-dirty' if dirty else ''}_{now:%Y%m%dT%H%M%SZ}"
        path = self.root / (f"{stem}_{_safe_name(name)}.json" if name else f"{stem}.json")
        atomic_write_text(path, text)
        return path

    def _reserve_number(self) -> int:
        """The next free run number, taken by an exclusive create (safe with parallel writers)."""
        numbers = self.root / _NUMBERS
        numbers.mkdir(exist_ok=True)
        taken = [int(m.group(1)) for p in self.root.iterdir() if (m := _RUN_FILE.match(p.name))]
        taken += [int(p.name) for p in numbers.iterdir() if p.name.isdigit()]
        number = max(taken, default=0) + 1
        while True:
            try:
                with open(numbers / f"{number:04d}", "x"):
                    return number
            except FileExistsError:
                number += 1

    # reading

    def runs(self) -> list[RunRecord]:
        """Every readable run, by run number."""
        if not self.root.is_dir():
            return []
        paths = sorted((p for p in self.root.iterdir() if _RUN_FILE.match(p.name)), key=lambda p: (int(p.name.split("_")[0]), p.name))
        self._cache = {p: self._cache[p] if p in self._cache else _read_run(p) for p in paths}
        return [run for run in self._cache.values() if run is not None]

    def find_runs(self, ref: str) -> list[RunRecord]:
        """The runs ``ref`` names, oldest first: ``"last"`` (the newest run), a run number
        (``"0003"``), else a run name, else a git commit prefix (4 characters or more).

        Raises:
            SalError: no run matches ``ref``.
        """
        runs = self.runs()
        if ref == "last":
            found = runs[-1:]
        else:
            found = [r for r in runs if ref.isdigit() and int(ref) == r.number]
            found = found or [r for r in runs if r.name is not None and ref in (r.name, _safe_name(r.name))]
            found = found or [r for r in runs if r.commit and len(ref) >= 4 and r.commit.startswith(ref.lower())]
        if not found:
            known = ", ".join(r.label + (f" ({r.name})" if r.name else "") for r in runs[-8:]) or "none yet"
            raise SalError(
                f"no run {ref!r} in the history {self.root}: give 'last', a run number, a run name or a "
                f"commit prefix (latest runs: {known})"
            )
        return found

    def previous(self, outcome_key: OutcomeKey, ref: str | None = None) -> Outcome | None:
        """The outcome with ``outcome_key`` (``(test_id, system, dataset)``) to compare with:
        ``baseline(...)``'s outcome, or ``None``."""
        found = self.baseline(outcome_key, ref)
        return None if found is None else found[1]

    def baseline(self, outcome_key: OutcomeKey, ref: str | None = None, *, exclude: int | None = None) -> tuple[RunRecord, Outcome] | None:
        """The run and outcome with ``outcome_key`` to compare with: the one rule of a test's
        baseline, for the plugin's gate, its warm start and ``sal compare``.

        The newest of the runs ``ref`` names that holds a readable outcome of the test; a run
        that lacks the test (a ``-k`` run, a test that errored) or whose outcome was skipped as
        unreadable is passed over for an older one, and the run being compared (``exclude``, a
        run number) is never its own baseline.

        Args:
            ref: ``None`` or ``"last"``: any run, and an outcome that failed a regression gate
                is passed over too (so rerunning a regressed commit compares with the last good
                run, not with itself); a run number (``"0003"``), a run name or a commit prefix:
                the runs it names.
            exclude: the number of the run being compared, when it is in the history.

        Returns:
            ``(run, outcome)``, or ``None`` when no (named) run holds the key.

        Raises:
            SalError: ``ref`` names no run at all (the message lists the latest runs).
        """
        last = ref in (None, "last")
        runs = self.runs() if last else self.find_runs(str(ref))
        for run in reversed(runs):
            outcome = run.get(outcome_key)
            if run.number != exclude and outcome is not None and not (last and outcome.regression):
                return run, outcome
        return None

    def prune(self, *, keep: int | None = None, older_than_s: float | None = None, dry_run: bool = False) -> list[RunRecord]:
        """Remove old runs; return those removed (or, with ``dry_run``, those that would be).

        A run goes when it matches every condition given: it is not among the newest ``keep``
        runs, and it was written more than ``older_than_s`` seconds ago. Never removed: the
        newest run of each name (a baseline such as ``main`` survives any prune) and the newest
        run. Run numbers are never reused: the newest reservation stays.
        """
        if keep is None and older_than_s is None:
            raise SalError("history prune: give --keep N, --older-than AGE (e.g. 30d), or both")
        runs = self.runs()
        newest_of_name = {run.name: run for run in runs if run.name}  # the last one wins
        protected = {run.number for run in [*runs[-1:], *newest_of_name.values()]}
        now = datetime.now(UTC)
        doomed = [
            run
            for index, run in enumerate(runs)
            if run.number not in protected
            and (keep is None or index < len(runs) - keep)
            and (older_than_s is None or (now - _created(run)).total_seconds() > older_than_s)
        ]
        if dry_run:
            return doomed
        for run in doomed:  # the newest run (and its reservation) stays, so numbers keep rising
            run.path.unlink(missing_ok=True)
            (self.root / _NUMBERS / run.label).unlink(missing_ok=True)
            self._cache.pop(run.path, None)
        return doomed

    def trend(self, test_id: str, system: str | None = None, dataset: str | None = None) -> list[tuple[RunRecord, Outcome]]:
        """``(run, outcome)`` of every run holding ``test_id`` (and ``system`` / ``dataset`` when
        given), oldest first."""
        return [
            (run, outcome)
            for run in self.runs()
            for outcome in run.outcomes
            if outcome.test_id == test_id
            and (system is None or outcome.system == system)
            and (dataset is None or outcome.dataset == dataset)
        ]

    def outcome_keys(self) -> list[OutcomeKey]:
        """Every outcome key in the history, in the order first seen."""
        return list(dict.fromkeys(outcome_key(o) for run in self.runs() for o in run.outcomes))


def _created(run: RunRecord) -> datetime:
    """When ``run`` was written (its ``created`` time; the file's mtime when that is unreadable)."""
    try:
        created = datetime.fromisoformat(run.created)
        return created if created.tzinfo else created.replace(tzinfo=UTC)
    except ValueError:
        return datetime.fromtimestamp(run.path.stat().st_mtime, UTC)


def _read_run(path: Path) -> RunRecord | None:
    """The run at ``path``, or ``None`` with a warning naming the file and what is wrong
    (``run_file``: an outcome that is wrong is left out of the run instead)."""
    try:
        data = read_document(path)
    except (OSError, ValueError) as exc:
        warnings.warn(f"{path}: not a readable pytest-sal run, skipped ({exc})", stacklevel=3)
        return None
    return RunRecord(
        number=int(path.name.split("_")[0]),
        path=path,
        created=data["created"],
        commit=data["commit"] or "",
        dirty=data["dirty"],
        machine=data["machine"],
        name=data["name"],
        outcomes=read_outcomes(path, data["outcomes"]),
    )


def _safe_name(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "-", name).strip("-") or "run"
