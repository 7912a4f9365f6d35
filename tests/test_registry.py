"""Dataset registry: options validated, plug-ins registered in code, load errors named."""

from __future__ import annotations

import pytest

from sal_adapters import DATASETS, DatasetError, open_dataset
from sal_adapters.common.plugins import EntryPointRegistry, PluginError
from sal_modules import PERTURBATIONS
from sal_wrappers import SYSTEMS


def test_unknown_option_lists_what_is_allowed(shared_data):
    with pytest.raises(DatasetError) as info:
        open_dataset("kitti", shared_data / "kitti", sequense="07")
    assert "unknown option 'sequense' for dataset kind 'kitti'; allowed: start, max_frames, sequence, stereo, color" in str(info.value)


@pytest.mark.parametrize(
    ("start", "max_frames", "message"),
    [(-1, None, "start must be >= 0"), (0, 0, "max_frames must be >= 1"), (500, None, "start=500 is past the last frame")],
)
def test_window_options_are_checked(shared_data, start, max_frames, message):
    with pytest.raises(DatasetError, match=message):
        open_dataset("kitti", shared_data / "kitti", sequence="07", start=start, max_frames=max_frames)


def test_a_plugin_kind_registered_in_code_is_used_and_removed():
    class Echo:
        name = "echo"
        description = "test kind"

        def option_names(self):
            return ["word"]

        def open(self, path, *, word="hi"):
            return word

    DATASETS.register("echo", Echo())
    try:
        assert "echo" in DATASETS.names()
        assert open_dataset("echo", word="hello") == "hello"
    finally:
        DATASETS.unregister("echo")
    assert "echo" not in DATASETS.names()


def test_broken_entry_point_is_reported_by_name(monkeypatch):
    from importlib.metadata import EntryPoint

    registry = EntryPointRegistry("sal.test", "widget")
    broken = EntryPoint(name="broken", value="no_such_module_xyz:Thing", group="sal.test")
    monkeypatch.setattr(registry, "_entry_points", lambda: {"broken": broken})
    with pytest.raises(PluginError, match=r"widget 'broken' \(no_such_module_xyz:Thing\) failed to load: ModuleNotFoundError"):
        registry.get("broken")
    with pytest.raises(PluginError, match="unknown widget 'nope'; known: broken"):
        registry.get("nope")


def test_perturbation_and_system_registries_read_their_groups():
    assert PERTURBATIONS.group == "sal.perturbations"
    assert SYSTEMS.group == "sal.systems"
    with pytest.raises(PluginError, match="unknown SLAM system 'orbslam9'"):
        SYSTEMS.get("orbslam9")
