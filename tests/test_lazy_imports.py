"""pytest imports the plugin in every session of an environment with pytest-sal installed: the
plugin, the packages and ``sal --help`` load no numpy, OpenCV, scipy, matplotlib, evo or tqdm
until a robustness test or a command needs them (``sal_adapters.common.lazy``)."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys
from pathlib import Path

import pytest

#: Imports a session without robustness tests must not pay for (top-level module names).
HEAVY = frozenset({"numpy", "cv2", "scipy", "matplotlib", "evo", "tqdm", "yaml", "PIL"})
#: The lazy package namespaces.
PACKAGES = ("pytest_sal", "sal_adapters", "sal_modules", "sal_wrappers")

#: A conftest that writes the top-level names of every loaded module when the session ends.
DUMP_CONFTEST = """
import json, sys

def pytest_unconfigure(config):
    with open("loaded.json", "w") as f:
        json.dump(sorted({name.split(".")[0] for name in sys.modules}), f)
"""


def loaded_after(code: str, cwd: Path) -> set[str]:
    """Top-level names of the modules a fresh interpreter (in ``cwd``: the packages come from
    the environment, not from the folder pytest runs in) has loaded after running ``code``."""
    dump = "\nimport json, sys\nprint(json.dumps(sorted({name.split('.')[0] for name in sys.modules})))"
    done = subprocess.run([sys.executable, "-c", code + dump], capture_output=True, text=True, check=True, cwd=cwd)
    return set(json.loads(done.stdout.splitlines()[-1]))


@pytest.mark.parametrize(
    ("code", "allowed"),
    [
        ("import pytest_sal.plugin", frozenset()),
        ("import pytest_sal as sal; sal.__version__", frozenset()),
        ("import sal_adapters, sal_modules, sal_wrappers; sal_wrappers.SYSTEMS.names()", frozenset()),
        ("from pytest_sal.cli.main import build_parser; build_parser().format_help()", frozenset({"yaml"})),  # the experiment config parser
    ],
    ids=["plugin", "pytest_sal", "packages", "sal --help"],
)
def test_importing_loads_no_heavy_module(code: str, allowed: frozenset[str], tmp_path: Path) -> None:
    assert loaded_after(code, tmp_path) & HEAVY <= allowed


def test_a_plain_pytest_session_loads_no_heavy_module(pytester: pytest.Pytester) -> None:
    # header (ORB-SLAM3 as the system: the load warning), collection, run, summary and finish
    pytester.makeconftest(DUMP_CONFTEST)
    pytester.makepyfile(test_plain="def test_x():\n    assert True\n")
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "-o", "sal_system=orbslam3", "-v")
    result.assert_outcomes(passed=1)
    loaded = set(json.loads((pytester.path / "loaded.json").read_text()))
    assert "pytest_sal" in loaded  # the plugin was there
    assert not loaded & HEAVY


def test_a_robustness_test_file_loads_what_it_needs(pytester: pytest.Pytester) -> None:
    # the counter-check: the same dump sees numpy once a test names a perturbation module
    pytester.makeconftest(DUMP_CONFTEST)
    pytester.makepyfile(
        test_fog=(
            "import pytest_sal as sal\nfrom pytest_sal import tracking_rate\nfrom sal_modules import fog\n\n"
            "@sal.require(tracking_rate >= 0.5, fog.visibility_m >= 25)\ndef test_fog(sal_outcome):\n    pass\n"
        )
    )
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "--collect-only", "-q")
    result.stdout.fnmatch_lines(["test_fog.py::test_fog"])
    loaded = set(json.loads((pytester.path / "loaded.json").read_text()))
    assert {"numpy", "cv2"} <= loaded


@pytest.mark.parametrize("package", PACKAGES)
def test_every_public_name_resolves_and_is_listed(package: str) -> None:
    module = importlib.import_module(package)
    for name in module.__all__:
        assert getattr(module, name) is not None, f"{package}.{name}"
        assert name in vars(module), f"{package}.{name} is not kept after the first read"
    assert set(module.__all__) <= set(dir(module))


@pytest.mark.parametrize("package", PACKAGES)
def test_an_unknown_name_is_an_attribute_error_naming_the_package(package: str) -> None:
    module = importlib.import_module(package)
    with pytest.raises(
        AttributeError, match=rf"^module '{package}' has no attribute 'no_such_name'; (did you mean|names|modules and names): "
    ):
        module.no_such_name
    with pytest.raises(ImportError, match="no_such_name"):
        exec(f"from {package} import no_such_name")


def test_a_registered_module_class_is_a_name_of_sal_modules() -> None:
    import sal_modules

    assert sal_modules.fog is sal_modules.module_class("fog")
    assert sal_modules.fog.visibility_m.unit == "m"
