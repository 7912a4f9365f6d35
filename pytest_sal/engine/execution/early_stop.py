"""Early stop: a run whose requirement can no longer hold is stopped before its last frame.

A requirement holds when every criterion holds, so one criterion that the frames run so far
already decide as failed decides the run failed, whatever the remaining frames do. Of the
requirement metrics (``pytest_sal.engine.requirements.METRICS``) only ``tracking_rate`` (frames
OK / frames given, ``RunResult.tracking_rate``) is decided by a prefix of per-frame states:
after ``k`` of ``N`` frames, ``ok`` of them tracked and ``k - ok`` not (lost or not yet
initialised), the run's rate will lie in ``[ok / N, (N - k + ok) / N]``. A criterion on it can
no longer hold when it holds at neither end of that interval: ``tracking_rate >= 0.9`` on 140
frames once 15 are not tracked (125/140 = 0.893), which also stops a system that has not
initialised by frame 15; ``tracking_rate <= t`` once ``ok / N`` exceeds ``t``. The criterion itself
is asked (``Criterion.holds``) with the rate computed as ``RunResult.tracking_rate`` computes it
(an int over an int), so the decision and the full run's verdict share their arithmetic: at
126/140 ``>= 0.9`` still holds, at 125/140 it does not.

The other metrics are not decided by a prefix: ATE, RPE, scale and the KITTI errors depend on
poses not yet estimated (a run is scored on its largest map segment, which a later frame may
start), and ``first_tracked`` and ``maps`` are reported, not judged.

``StopRule`` is what a system is given (``SlamSystem.run(..., stop=rule)``): picklable, so that
ORB-SLAM3's child process applies it itself, and cheap per frame (one vectorised count).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pytest_sal.engine.outcomes.quantity import num
from pytest_sal.engine.requirements import Criterion, Requirement
from sal_wrappers.base import TrackState

__all__ = ["DECIDED_BY_STATES", "StopRule"]

#: The requirement metrics that a prefix of per-frame states decides.
DECIDED_BY_STATES = ("tracking_rate",)


@dataclass(frozen=True, eq=False)
class StopRule:
    """The criteria of a requirement that the states of the frames run so far can decide.

    Attributes:
        criteria: criteria on a metric of ``DECIDED_BY_STATES``, in the requirement's order.
    """

    criteria: tuple[Criterion, ...]

    @classmethod
    def of(cls, requirement: Requirement) -> StopRule | None:
        """The rule of ``requirement``, or ``None`` when no criterion of it can stop a run."""
        decided = tuple(c for c in requirement.criteria if c.metric.name in DECIDED_BY_STATES)
        return cls(decided) if decided else None

    def key(self) -> list[list[Any]]:
        """What decides which runs this rule stops, for cache keys: ``[metric, op, threshold]``
        per criterion, sorted (the requirement's other criteria do not matter)."""
        return sorted([c.metric.name, c.op, c.threshold] for c in self.criteria)

    def check(self, states: np.ndarray, frames: int) -> str | None:
        """Why the run can no longer meet the requirement, in words, or ``None`` while it can.

        Args:
            states: ``TrackState`` values of the first frames, those whose state is final.
            frames: frames the run is given in all (``N``).
        """
        if frames <= 0:
            return None
        seen = len(states)
        ok = int(np.count_nonzero(np.asarray(states) == TrackState.OK))
        lowest, highest = ok / frames, (frames - seen + ok) / frames  # as RunResult.tracking_rate: int / int
        for criterion in self.criteria:
            if criterion.holds({"tracking_rate": highest}) or criterion.holds({"tracking_rate": lowest}):
                continue
            if criterion.op in ("<", "<="):
                done = f"{ok} of {frames} frames tracked by frame {seen} ({num(lowest)} at least)"
            elif ok == 0:
                done = f"not initialised by frame {seen} of {frames} ({num(highest)} at best)"
            else:
                done = f"{seen - ok} of {frames} frames not tracked by frame {seen} ({num(highest)} at best)"
            return f"{criterion} can no longer hold: {done}"
        return None

    #: a rule is the ``stop`` callable ``SlamSystem.run`` takes
    __call__ = check

    def __str__(self) -> str:
        return " and ".join(str(c) for c in self.criteria)
