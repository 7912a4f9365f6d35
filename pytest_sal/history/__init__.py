"""Run history above the engine: one file per test session, the regression checks against it,
and the gate that compares a run with its baseline."""

__all__: list[str] = []
