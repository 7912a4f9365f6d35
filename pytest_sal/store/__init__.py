"""Storage below the engine: the content-addressed cache of runs and its keys.

The run history, which stores outcomes the engine produced, is one layer up in
:mod:`pytest_sal.history`."""

__all__: list[str] = []
