"""pytest-sal: SLAM robustness requirements as pytest tests.

>>> import pytest_sal as sal
>>> from pytest_sal import ate_rmse, tracking_rate
>>> from sal_modules import fog
>>> @sal.require(ate_rmse < 1.5, fog.visibility_m >= 25)
... def test_fog(sal_outcome):
...     assert sal_outcome.boundary.fail_value < 25

pytest imports this package in every session (entry point ``pytest11: sal``), so each name
loads its module on first use (``sal_adapters.common.lazy``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sal_adapters.common.lazy import lazy_exports

if TYPE_CHECKING:  # what type checkers see; at run time each name loads on first use
    from pytest_sal.api import at, dataset_fixture, require, sweep
    from pytest_sal.engine.requirements import (
        InvalidRequirement,
        Metric,
        ate_rmse,
        r_rel,
        rpe_rot,
        rpe_trans,
        scale_error,
        t_rel,
        tracking_rate,
    )
    from sal_adapters.common.errors import SalError

__all__ = [
    "InvalidRequirement",
    "Metric",
    "SalError",
    "__version__",
    "at",
    "ate_rmse",
    "dataset_fixture",
    "r_rel",
    "require",
    "rpe_rot",
    "rpe_trans",
    "scale_error",
    "sweep",
    "t_rel",
    "tracking_rate",
]

__version__ = "0.1.0"

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "pytest_sal.api": ["at", "dataset_fixture", "require", "sweep"],
        "pytest_sal.engine.requirements": [
            "InvalidRequirement",
            "Metric",
            "ate_rmse",
            "r_rel",
            "rpe_rot",
            "rpe_trans",
            "scale_error",
            "t_rel",
            "tracking_rate",
        ],
        "sal_adapters.common.errors": ["SalError"],
    },
)
