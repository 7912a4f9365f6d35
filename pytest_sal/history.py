"""Run history: one JSON file per test session, and the regression checks against it.

A run is written by ``History.append_run`` as ``NNNN_<commit>_<UTC time>[_<name>].json`` under
the history root (default ``.sal/history``)::

    {"version": 1, "created": "2025-05-01T12:00:00+00:00", "commit": "1a2b3c4", "dirty": false,
     "machine": {"hostname": ..., "platform": ..., "cpu_count": ..., "python": ...},
     "name": "nightly", "outcomes": [Outcome.to_dict(), ...]}

Writers never collide and readers never see half a file: the run number is reserved by an
exclusive create of ``.numbers/NNNN`` (retried with the next number on ``FileExistsError``, so
parallel sessions get distinct numbers and a number is never reused), and the JSON is written to a
temporary file in the same folder, then moved into place with ``os.replace``.

An outcome is identified across runs by its key ``(test_id, system, dataset)``. ``previous``
finds the outcome a new one is compared with; ``--sal-compare-fail`` texts are parsed by
``parse_compare_fail`` into ``RegressionCheck`` objects whose ``fails`` says, in words, how the
boundary or a metric at the envelope's edge got worse.

The run history is user-owned: commit ``.sal/history`` to keep the robustness of each commit on
record, or add it to ``.gitignore`` to keep it per machine.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import re
import subprocess
import warnings
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from pytest_sal.outcome import Outcome, Trial
from pytest_sal.requirements import METRICS
from sal_adapters.errors import SalError
from sal_adapters.textfiles import atomic_write_text

__all__ = [
    "DEFAULT_ROOT",
    "FORMAT_VERSION",
    "BoundaryCheck",
    "History",
    "MetricCheck",
    "OutcomeKey",
    "RegressionCheck",
    "RunRecord",
    "commit_info",
    "edge_trial",
    "machine_info",
    "outcome_key",
    "parse_compare_fail",
    "regressions",
    "warm_start",
]

#: where runs are kept unless configured otherwise (relative to the working directory)
DEFAULT_ROOT = Path(".sal/history")
#: the ``version`` written into every run file
FORMAT_VERSION = 1
#: identifies an outcome across runs
OutcomeKey = tuple[str, str, str]

_RUN_FILE = re.compile(r"^(\d{4,})_.*\.json$")
_NUMBERS = ".numbers"  # reservations of run numbers, one empty file each
_EPS = 1e-9  # "more than the limit": a change equal to it (up to rounding) does not fail


def outcome_key(outcome: Outcome) -> OutcomeKey:
    """``(test_id, system, dataset)``: what makes two outcomes of different runs comparable."""
    return (outcome.test_id, outcome.system, outcome.dataset)


# -- where a run was made ---------------------------------------------------------------------


def machine_info() -> dict[str, Any]:
    """``hostname``, ``platform``, ``machine`` (CPU architecture), ``cpu_count``, ``python``."""
    return {
        "hostname": platform.node(),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        "python": f"{platform.python_implementation()} {platform.python_version()}",
    }


def commit_info(cwd: str | Path | None = None) -> tuple[str, bool]:
    """``(short commit, dirty)`` of the git work tree at ``cwd`` (default: the working directory).

    ``dirty``: tracked files differ from the commit (``git status --porcelain
    --untracked-files=no``; untracked files, the history itself among them, do not count).
    Without git, outside a repository, or before the first commit: ``("", False)``, no error.
    """
    def git(*args: str) -> str | None:
        try:
            done = subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, timeout=20, check=False)
        except (OSError, subprocess.SubprocessError):
            return None
        return done.stdout if done.returncode == 0 else None

    commit = git("rev-parse", "--short", "HEAD")
    if not commit or not commit.strip():
        return "", False
    status = git("status", "--porcelain", "--untracked-files=no")
    return commit.strip(), bool(status and status.strip())


# -- the store --------------------------------------------------------------------------------


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

    def get(self, key: OutcomeKey) -> Outcome | None:
        """The outcome with ``key`` in this run (the last one, should it appear twice)."""
        found = None
        for outcome in self.outcomes:
            if outcome_key(outcome) == key:
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
        text = json.dumps(_json_safe(document), indent=2, allow_nan=False) + "\n"
        self.root.mkdir(parents=True, exist_ok=True)
        number = self._reserve_number()
        stem = f"{number:04d}_{commit or 'nogit'}{'-dirty' if dirty else ''}_{now:%Y%m%dT%H%M%SZ}"
        path = self.root / (f"{stem}_{_safe_name(name)}.json" if name else f"{stem}.json")
        _write_atomic(path, text)
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
        """The outcome with ``outcome_key`` (``(test_id, system, dataset)``) to compare with.

        Args:
            ref: ``None`` or ``"last"``: the newest run holding the key; a run number
                (``"0003"``), a run name or a commit prefix: the newest of the runs it names that
                holds the key.

        Returns:
            the outcome, or ``None`` when no (named) run holds the key.

        Raises:
            SalError: ``ref`` names no run at all (a typo should not silently compare nothing).
        """
        runs = self.runs() if ref in (None, "last") else self.find_runs(ref)
        for run in reversed(runs):
            outcome = run.get(tuple(outcome_key))  # type: ignore[arg-type]
            if outcome is not None:
                return outcome
        return None

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


def _read_run(path: Path) -> RunRecord | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        if data.get("version") != FORMAT_VERSION:
            raise ValueError(f"format version {data.get('version')!r}, this pytest-sal reads {FORMAT_VERSION}")
        return RunRecord(
            number=int(path.name.split("_")[0]),
            path=path,
            created=str(data.get("created", "")),
            commit=str(data.get("commit") or ""),
            dirty=bool(data.get("dirty", False)),
            machine=dict(data.get("machine") or {}),
            name=data.get("name"),
            outcomes=[Outcome.from_dict(o) for o in data.get("outcomes", [])],
        )
    except (OSError, ValueError, TypeError, KeyError, AttributeError) as exc:
        warnings.warn(f"{path}: not a readable pytest-sal run, skipped ({exc})", stacklevel=3)
        return None


def _write_atomic(path: Path, text: str) -> None:
    atomic_write_text(path, text)


def _safe_name(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "-", name).strip("-") or "run"


def _json_safe(value: Any) -> Any:
    """Plain JSON: numpy scalars and arrays as Python values, paths as text, NaN and
    infinities as ``null`` (a metric that is not a number counts as not available)."""
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, bool) or value is None or isinstance(value, (str, int)):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Path):
        return str(value)
    if hasattr(value, "tolist"):  # numpy scalar or array
        return _json_safe(value.tolist())
    raise TypeError(f"cannot save {type(value).__name__} {value!r} in the run history")


# -- regression checks ------------------------------------------------------------------------

COMPARE_FAIL_FORMS = (
    "boundary:10% (the boundary's pass value moved toward the mild side by more than 10 % of its previous value), "
    "boundary:2.5 (... by more than 2.5 in the parameter's unit), "
    "METRIC:0.2 (the metric at the envelope's edge got worse by more than 0.2 in its unit), "
    "METRIC:15% (... by more than 15 % of its previous value); METRIC is one of " + ", ".join(METRICS)
)


class RegressionCheck(ABC):
    """One ``--sal-compare-fail`` check; ``str(check)`` is its text (``boundary:10%``)."""

    limit: float
    relative: bool

    @abstractmethod
    def fails(self, current: Outcome, previous: Outcome) -> str | None:
        """Why ``current`` regressed against ``previous``, in words, or ``None``.

        Improvements never fail. Outcomes that are not comparable (a different parameter, search
        direction or envelope edge: the test changed) give ``None``.
        """
        raise NotImplementedError(f"{type(self).__name__}.fails")

    def _exceeds(self, change: float) -> bool:
        return change > self.limit * (1 + _EPS) + _EPS * 1e-3

    def _limit_text(self, unit: str) -> str:
        return f"{self.limit:g} %" if self.relative else _quantity(self.limit, unit)

    def _moved(self, before: float, now: float, worse_by: float, unit: str) -> str | None:
        """The change from ``before`` to ``now`` in words (``+47 %``, ``+7 m``) when getting
        worse by ``worse_by`` exceeds the limit, else ``None``."""
        if worse_by <= 0:
            return None
        change = worse_by if not self.relative else (math.inf if before == 0 else 100.0 * worse_by / abs(before))
        if not self._exceeds(change):
            return None
        if self.relative:
            return "from 0" if before == 0 else _percent(100.0 * (now - before) / abs(before))
        return _quantity(now - before, unit, sign=True)


@dataclass(frozen=True)
class BoundaryCheck(RegressionCheck):
    """``boundary:LIMIT`` / ``boundary:LIMIT%``: the boundary moved toward the mild side.

    Compared is the boundary's ``pass_value``, the most severe value at which the system still
    met its requirement. It regressed when it moved toward the mild side (for ``worse='lower'``,
    such as ``fog.visibility_m``, it got larger): by more than ``limit`` in the parameter's unit,
    or, relative, by more than ``limit`` percent of ``|previous pass_value|``.

    The relative change is the scale-free change of the pass value itself, not of the margin to
    the envelope's edge: the margin is undefined for tests without an edge, tiny (and its relative
    change huge) when the boundary sits near the edge, and changes meaning when the edge is
    moved; the pass value's relative change reads the same on geometric scales (visibility 1 m
    to 100 km: 15 m -> 22 m is +47 % wherever the edge is). At a previous pass value of 0 any
    move toward the mild side counts as exceeding a relative limit.

    A boundary that now failed everywhere searched (no pass value) regressed, unless it did
    before too. A previous boundary without a pass value cannot get worse.
    """

    limit: float
    relative: bool

    def __str__(self) -> str:
        return f"boundary:{self.limit:g}{'%' if self.relative else ''}"

    def fails(self, current: Outcome, previous: Outcome) -> str | None:
        if not _comparable(current, previous):
            return None
        before, now = previous.boundary.pass_value, current.boundary.pass_value
        unit = current.boundary.unit or previous.boundary.unit
        where = "down to" if current.worse == "lower" else "up to"
        label = f"{current.parameter} boundary"
        if before is None:
            return None
        if now is None:
            return (
                f"{label} moved toward the mild side: passed {where} {_quantity(before, unit)} before, "
                f"now failed everywhere searched (limit {self._limit_text(unit)})"
            )
        moved = self._moved(before, now, (now - before) if current.worse == "lower" else (before - now), unit)
        if moved is None:
            return None
        toward = "toward the requirement" if _at_or_beyond_edge(now, current) else "toward the mild side, past the requirement"
        return (
            f"{label} moved {toward}: passed {where} {_quantity(before, unit)} before, now only {where} "
            f"{_quantity(now, unit)} ({moved}, limit {self._limit_text(unit)})"
        )


@dataclass(frozen=True)
class MetricCheck(RegressionCheck):
    """``METRIC:LIMIT`` / ``METRIC:LIMIT%``: the metric at the envelope's edge got worse.

    Compared are the aggregated metrics of each outcome's edge trial (its first trial at the
    ``edge`` value, see ``edge_trial``). Worse follows the metric: larger for ``ate_rmse``,
    smaller for ``tracking_rate``; by more than ``limit`` in the metric's unit, or by more than
    ``limit`` percent of ``|previous value|``. A metric that is now missing (the run failed,
    nothing tracked) regressed when it was there before. Outcomes whose edges differ, or without
    an edge trial, are not compared.
    """

    metric: str
    limit: float
    relative: bool

    def __str__(self) -> str:
        return f"{self.metric}:{self.limit:g}{'%' if self.relative else ''}"

    def fails(self, current: Outcome, previous: Outcome) -> str | None:
        if not _comparable(current, previous) or current.edge is None:
            return None
        trial_now, trial_before = edge_trial(current), edge_trial(previous)
        if trial_now is None or trial_before is None:
            return None
        before, now = _number(trial_before.metrics.get(self.metric)), _number(trial_now.metrics.get(self.metric))
        metric = METRICS[self.metric]
        at = f"{self.metric} at the envelope's edge ({current.parameter} = {_quantity(current.edge, current.boundary.unit)})"
        if before is None:
            return None
        if now is None:
            return f"{at} got worse: {_quantity(before, metric.unit)} before, now not available (the runs failed)"
        moved = self._moved(before, now, (now - before) if metric.better == "lower" else (before - now), metric.unit)
        if moved is None:
            return None
        return (
            f"{at} got worse: {_quantity(before, metric.unit)} before, now {_quantity(now, metric.unit)} "
            f"({moved}, limit {self._limit_text(metric.unit)})"
        )


def parse_compare_fail(text: str) -> RegressionCheck:
    """argparse type for ``--sal-compare-fail``: ``boundary:10%``, ``boundary:2.5``,
    ``ate_rmse:0.2``, ``ate_rmse:15%`` (any metric of ``METRICS``).

    >>> parse_compare_fail("boundary:10%")
    BoundaryCheck(limit=10.0, relative=True)
    >>> str(parse_compare_fail(" ATE_RMSE : 0.2 "))
    'ate_rmse:0.2'

    Raises:
        argparse.ArgumentTypeError: the text is none of the forms; the message lists them.
    """
    what, sep, amount = str(text).partition(":")
    what, amount = what.strip().lower(), amount.strip().replace(" ", "")

    def bad(reason: str) -> argparse.ArgumentTypeError:
        return argparse.ArgumentTypeError(f"{text!r}: {reason}; valid forms: {COMPARE_FAIL_FORMS}")

    if not sep:
        raise bad("expected WHAT:LIMIT")
    if what != "boundary" and what not in METRICS:
        raise bad(f"unknown quantity {what!r}")
    relative = amount.endswith("%")
    number = amount[:-1] if relative else amount
    try:
        limit = float(number)
    except ValueError:
        raise bad(f"the limit {amount!r} is not a number") from None
    if not math.isfinite(limit) or limit < 0:
        raise bad(f"the limit must be a finite number >= 0, got {amount!r}")
    return BoundaryCheck(limit, relative) if what == "boundary" else MetricCheck(what, limit, relative)


def regressions(checks: list[RegressionCheck], current: Outcome, previous: Outcome | None) -> list[str]:
    """The messages of the ``checks`` that fail ``current`` against ``previous`` (none without
    a previous outcome)."""
    if previous is None:
        return []
    return [message for check in checks if (message := check.fails(current, previous)) is not None]


def warm_start(
    previous: Outcome | None,
    *,
    parameter: str | None = None,
    edge: float | None = None,
    worse: str | None = None,
) -> tuple[float | None, float | None] | None:
    """The previous boundary ``(pass_value, fail_value)`` to try first (``boundary_search``'s
    ``warm_start``), or ``None``: no previous outcome, no value in its boundary, or, when
    ``parameter`` / ``edge`` / ``worse`` of the current search are given, a previous search of a
    different parameter, edge or direction."""
    if previous is None:
        return None
    if parameter is not None and previous.parameter != parameter:
        return None
    if worse is not None and previous.worse != worse:
        return None
    if edge is not None and (previous.edge is None or not math.isclose(previous.edge, edge, rel_tol=1e-9, abs_tol=1e-12)):
        return None
    pair = (previous.boundary.pass_value, previous.boundary.fail_value)
    return None if pair == (None, None) else pair


def edge_trial(outcome: Outcome) -> Trial | None:
    """The first (not repeated) trial at the outcome's edge value, or ``None``."""
    if outcome.edge is None:
        return None
    for trial in outcome.trials:
        if not trial.repeat and math.isclose(trial.value, outcome.edge, rel_tol=1e-9, abs_tol=1e-12):
            return trial
    return None


def _comparable(current: Outcome, previous: Outcome) -> bool:
    if current.parameter != previous.parameter or current.worse != previous.worse:
        return False
    if (current.edge is None) != (previous.edge is None):
        return False
    return current.edge is None or math.isclose(current.edge, previous.edge, rel_tol=1e-9, abs_tol=1e-12)  # type: ignore[arg-type]


def _at_or_beyond_edge(value: float, outcome: Outcome) -> bool:
    """``value`` is the edge or more severe (still meets the requirement there)."""
    if outcome.edge is None:
        return True
    return value <= outcome.edge if outcome.worse == "lower" else value >= outcome.edge


def _number(value: Any) -> float | None:
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if math.isfinite(number) else None


def _quantity(value: float, unit: str, *, sign: bool = False) -> str:
    text = f"{value:+.4g}" if sign else f"{value:.4g}"
    return f"{text} {unit}" if unit else text


def _percent(value: float) -> str:
    return f"{value:+.0f} %" if abs(value) >= 9.95 else f"{value:+.1f} %"
