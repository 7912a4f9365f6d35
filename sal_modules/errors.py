"""Errors raised by perturbation modules and depth providers."""

from __future__ import annotations

from sal_adapters.common.errors import SalError

__all__ = ["DepthUnavailable", "ModuleError", "ParameterError"]


class ModuleError(SalError):
    """A perturbation module was misused or could not run (missing extra, bad model file)."""


class ParameterError(ModuleError, ValueError):
    """A parameter name or value is wrong; the message names module, parameter, unit and range."""


class DepthUnavailable(ModuleError):
    """A module needs depth and no provider applies to the sequence."""
