"""Perturbation modules in physical units (registry: entry-point group ``sal.perturbations``)."""

from sal_adapters.plugins import EntryPointRegistry

__all__ = ["PERTURBATIONS"]

#: Perturbation modules by name; built-ins and plug-ins register in ``sal.perturbations``.
PERTURBATIONS: EntryPointRegistry[type] = EntryPointRegistry("sal.perturbations", "perturbation module")
