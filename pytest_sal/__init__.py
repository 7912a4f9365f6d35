"""pytest-sal: SLAM robustness requirements as pytest tests."""

from sal_adapters.errors import SalError

__all__ = ["SalError", "__version__"]

__version__ = "0.1.0"
