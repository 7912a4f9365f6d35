"""Shared fixtures: the real data excerpts in ../shared/data and an isolated cache folder."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

pytest_plugins = ["pytester"]

#: The real KITTI / EuRoC / TUM excerpts; override with SAL_TEST_DATA.
SHARED_DATA = Path(os.environ.get("SAL_TEST_DATA", Path(__file__).resolve().parents[1].parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Root of the real dataset excerpts; tests that need it skip when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real dataset excerpts not found at {SHARED_DATA} (set SAL_TEST_DATA to the shared/data folder)")
    return SHARED_DATA


@pytest.fixture(scope="session", autouse=True)
def isolated_sal_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Every test session renders and caches into its own folders, never the user's cache nor
    the checkout: ``sal`` commands run without ``--cache-dir`` use ``./.sal/cache``, which is
    redirected here (the plugin's ``<rootdir>/.sal/cache`` is left as it is)."""
    import pytest_sal.cache

    root = tmp_path_factory.mktemp("sal-cache")
    commands_cache = tmp_path_factory.mktemp("commands-trial-cache")
    default = pytest_sal.cache.default_cache_dir
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("SAL_CACHE_DIR", str(root))
        patch.setattr(pytest_sal.cache, "default_cache_dir", lambda rootdir=None: commands_cache if rootdir is None else default(rootdir))
        yield root


@pytest.fixture(scope="session")
def orb_vocabulary(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The default ORB-SLAM3 vocabulary (k=10, L=6; or ``$SAL_ORB_VOCABULARY``), built at most
    once per test run: xdist workers share the folder beside their basetemps and its lock."""
    from sal_wrappers.vocabulary import ensure_vocabulary

    base = tmp_path_factory.getbasetemp()
    folder = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "orb-vocabulary"
    return ensure_vocabulary(cache_dir=folder)
