"""YAML experiments as library functions: the config schema and its safe loader, and the perturb,
evaluate, boundary and features workflows (no argparse: the ``sal`` commands in
:mod:`pytest_sal.cli` call these)."""

__all__: list[str] = []
