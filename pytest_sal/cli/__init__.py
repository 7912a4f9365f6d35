"""The ``sal`` command: argparse and printing only; the work is done by the library below
(:mod:`pytest_sal.experiment`, :mod:`pytest_sal.report`, :mod:`pytest_sal.history`)."""

__all__: list[str] = []
