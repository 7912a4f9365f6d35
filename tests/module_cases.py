"""Test parameters for every registered perturbation module (registry-driven tests).

Each family's cases live in ``tests/cases_<family>.py`` as ``CASES = {name: ModuleCase}``;
``test_module_contract.py`` fails when a registered module has no case here.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any

__all__ = ["ModuleCase", "all_cases"]

FAMILIES = ("transport", "weather", "light", "optics", "motion")


@dataclass(frozen=True)
class ModuleCase:
    """How the generic tests exercise one module.

    Attributes:
        params: parameters with a clearly visible effect.
        scene: synthetic world scene the module is tried on (``urban`` or ``indoor``).
        sensor: synthetic sensor (``None``: the scene's default).
        ladder: for every searchable parameter, values from weak to strong (at least 3);
            the difference from the clean frame must grow along it.
        random: another seed gives another pattern.
        frames: frames of the synthetic sequence the generic tests use.
    """

    params: dict[str, Any]
    scene: str = "urban"
    sensor: str | None = None
    ladder: dict[str, list[Any]] = field(default_factory=dict)
    random: bool = True
    frames: int = 3


def all_cases() -> dict[str, ModuleCase]:
    """Every family's cases, merged."""
    cases: dict[str, ModuleCase] = {}
    for family in FAMILIES:
        try:
            module = importlib.import_module(f"cases_{family}")
        except ModuleNotFoundError as exc:
            if exc.name != f"cases_{family}":
                raise
            continue
        cases.update(module.CASES)
    return cases
