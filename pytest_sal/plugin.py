"""The pytest plugin (entry point ``pytest11: sal``): markers and options; grows with the
requirement language and boundary search. Heavy imports happen inside hooks, never here."""

from __future__ import annotations

import pytest

__all__ = ["pytest_configure"]


def pytest_configure(config: pytest.Config) -> None:
    """Register the ``sal`` marker so that ``-m sal`` selects robustness tests."""
    config.addinivalue_line("markers", "sal: a SLAM robustness test run by pytest-sal (select with -m sal)")
