"""The pytest plugin loads through its entry point and registers its marker."""

from __future__ import annotations

from importlib.metadata import entry_points


def test_entry_point_groups_hold_the_builtins():
    pytest11 = {ep.name: ep.value for ep in entry_points(group="pytest11")}
    assert pytest11["sal"] == "pytest_sal.plugin"
    datasets = {ep.name for ep in entry_points(group="sal.datasets")}
    assert datasets == {"kitti", "tum", "euroc", "folder", "synthetic", "rosbag", "video"}


def test_plugin_is_loaded_and_marker_registered(pytester):
    pytester.makepyfile(
        """
        import pytest

        @pytest.mark.sal
        def test_robust():
            pass

        def test_plain():
            pass
        """
    )
    result = pytester.runpytest("--strict-markers", "-m", "sal", "-v")
    result.assert_outcomes(passed=1, deselected=1)
    result.stdout.fnmatch_lines(["*test_robust PASSED*"])
    markers = pytester.runpytest("--markers")
    markers.stdout.fnmatch_lines(["@pytest.mark.sal: a SLAM robustness test*"])


def test_plugin_can_be_disabled(pytester):
    pytester.makepyfile("def test_x(): pass")
    result = pytester.runpytest("-p", "no:sal", "--markers")
    assert "a SLAM robustness test" not in result.stdout.str()
