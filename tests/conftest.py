"""Shared fixtures: the real data excerpts in ../shared/data and an isolated cache folder."""

from __future__ import annotations

import os
import re
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

import pytest_sal.engine.execution.trial_runner
import pytest_sal.testing  # noqa: F401

# Loaded here, before any test: pytester's in-process runs (runpytest without a subprocess)
# unload the modules first imported inside them, and numpy cannot be imported twice in one
# process. The plugin is light (it loads none of numpy, scipy, OpenCV, evo), so without these
# imports a test module whose inner sessions run a search in process failed whenever it was
# the first to run in its process (test_plugin_history.py alone, or first on an xdist worker).
pytest_plugins = ["pytester"]

#: Helper modules that test modules load with ``pytest_plugins`` for the fixtures they share:
#: registered for assertion rewriting before a test module imports their helpers too.
FIXTURE_MODULES = ("command_programs", "depth_sequences", "euroc_excerpt", "transport_sequences")
pytest.register_assert_rewrite(*FIXTURE_MODULES)

#: The real KITTI / EuRoC / TUM excerpts; override with SAL_TEST_DATA.
SHARED_DATA = Path(os.environ.get("SAL_TEST_DATA", Path(__file__).resolve().parents[1].parent / "shared" / "data"))


#: Test modules marked ``slow`` (``-m "not slow"`` leaves them out: .ci/lowest runs the rest).
#: Serial times on the busy 2-core machine (load average about 4). The fast rest sums to about
#: 190 s of test time; ``-m "not slow" -n 2`` took 110 s on the quiet 2-core machine.
SLOW_MODULES = {
    "test_experiment_e2e.py",  # end-to-end experiments: perturb, evaluate, features (~70 s)
    "test_experiment_e2e_boundary.py",  # boundary searches with both real systems (~55 s)
    "test_experiment_fuzz.py",  # the config fuzz test, hundreds of generated and mutated configs (~45 s)
    "test_early_stop_real.py",  # reference_vo on KITTI 07 and EuRoC at night, stopped and full (18 s; test_early_stop.py stays)
    "test_ray_executor.py",  # a local Ray (4-6 s to start), searches on it, killed and hung workers (~25 s)
    "test_ray_cluster.py",  # a two-node Ray cluster (3-5 s to start), searches and runs on both nodes (~23 s)
    "test_ray_plugin.py",  # pytest -n 2 --sal-executor ray sessions in subprocesses, each starting a Ray (~25 s)
}
#: Single tests marked ``slow`` in otherwise fast modules, as ``module::name`` (``module::Class::name``
#: in a class) patterns: ``*`` matches any text, and a name without its parameter ids matches
#: every parametrisation. Each module keeps a faster test of the same behaviour in the fast lane.
SLOW_TESTS = {
    "test_ci_recipe.py::TestGateScript::*",  # sal-gate.sh: 6 CI runs of an inner suite under -n 2 (51 s)
    # inner sessions under -n 2 (their [serial] twins stay fast)
    "test_plugin_history.py::test_history_warm_start_and_compare_fail[xdist]",  # (34 s)
    "test_plugin_requirements.py::*[xdist]",  # verdicts 20 s, cache 7.5 s, flaky 5.1 s, sweep 2.6 s, systems 2.6 s
    "test_pytest_html.py::*[xdist]",  # (5.0 s)
    "test_plugin_live.py::*[xdist]",  # (3.4 s)
    "test_outputs_commands.py::test_kill_9_of_a_rerun_keeps_the_previous_output",  # (16 s)
    "test_outputs_commands.py::test_outputs_and_caches_get_the_umask_permissions[umask-077]",  # (4.0 s; umask 022 stays)
    # the experiment folder the page tests share: sal perturb, evaluate, boundary and features (13 s setup)
    "test_experiment_report.py::test_page_*",
    "test_experiment_report.py::test_example_frames_show_the_same_moment_of_every_sequence",
    "test_experiment_report.py::test_report_folder_can_be_moved_and_written_elsewhere",
    "test_experiment_report.py::test_broken_and_missing_parts_are_named_and_the_rest_is_built",
    "test_vocabulary.py::test_default_vocabulary",  # builds the k=10 L=6 ORB-SLAM3 vocabulary (10 s)
    # every module on real frames (each module's physics stays in the fast lane on synthetic
    # frames, test_module_contract.py): 14 + 14 parametrisations (10.1 s in all)
    "test_modules_real_data.py::test_every_module_on_euroc_stereo",
    "test_modules_real_data.py::test_every_module_on_kitti_mono_with_a_monocular_depth_model",
    "test_features.py::test_compare_features_writes_json_and_pngs",  # (3.6 s)
    "test_reference_vo.py::test_kitti_07_mono",  # 140 real KITTI frames (3.5 s)
    # reference_vo's accuracy per sensor (14.3 s in all; test_two_runs_give_identical_results stays)
    "test_reference_vo.py::test_indoor_rgbd",
    "test_reference_vo.py::test_urban_stereo",
    "test_reference_vo.py::test_euroc_stereo_tracks_the_almost_static_camera",
    "test_reference_vo.py::test_mono_runs_are_identical_too",
    "test_reference_vo.py::test_indoor_mono_sim3",
    "test_evaluate_command.py::test_perturbed_frames_come_from_the_cache_sal_perturb_filled",  # (3.4 s)
    "test_evaluate_command.py::test_a_failed_or_raising_run_is_recorded_and_the_rest_continues",  # (2.6 s)
    "test_metrics.py::test_rpe_matches_evo_rpe_command_line[kitti00-orb-100m]",  # (2.0 s)
    # every shipped config perturbed end to end (17 s in all; test_robustness_boundary_is_searchable
    # and the configs' validation stay)
    "test_example_configs_perturb.py::test_perturb_synthetic",
    "test_example_configs_perturb.py::test_perturb_real_data",
    # H.264 at several targets and on real KITTI (5.4 s; lower rate gives lower PSNR, identical bytes stay)
    "test_transport_bandwidth.py::test_bandwidth_hits_the_target_rate_on_the_synthetic_street",
    "test_transport_bandwidth.py::test_bandwidth_hits_the_target_on_real_kitti_at_its_own_frame_rate",
    "test_transport_bandwidth.py::test_bandwidth_h265_and_capped_variable_rate",
    "test_plugin_usage.py::*[xdist]",  # misuse under -n 2 (6.9 s; the [serial] twins stay)
    "test_interrupt.py::test_ctrl_c_during_the_search_is_pytests_interrupted_summary[test_fog]",  # (3.1 s; test_point stays)
}
#: Tests that run the real ORB-SLAM3 (pyorbslam3), marked ``real_slam`` and ``slow``, as patterns
#: like ``SLOW_TESTS``'s.
REAL_SLAM_TESTS = {
    "test_orbslam3.py::*",  # synthetic, KITTI and EuRoC sequences, failures (~110 s)
    "test_experiment_e2e.py::TestEvaluateOrbslam3::*",  # sal evaluate --slam orbslam3
    "test_experiment_e2e_boundary.py::TestBoundaryOrbslam3::*",  # sal boundary --slam orbslam3
    "test_plugin_orbslam3.py::*",  # a boundary search through the plugin (~55 s)
    "test_early_stop_orbslam3.py::*",  # stopped and full runs on KITTI 07 and EuRoC (30 s, and 9 s to build the vocabulary)
}


def listed(item: pytest.Item, patterns: set[str]) -> bool:
    """Whether ``module::name`` (``module::Class::name``) of ``item``, with or without its
    parameter ids, matches one of ``patterns``, in which ``*`` matches any text."""
    *classes, _ = item.nodeid.split("::")[1:]
    where = "::".join([item.path.name, *classes])
    names = {f"{where}::{item.name}", f"{where}::{getattr(item, 'originalname', item.name)}"}
    return any(re.fullmatch(".*".join(map(re.escape, pattern.split("*"))), name) for name in names for pattern in patterns)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark the ``REAL_SLAM_TESTS`` ``real_slam`` and ``slow``, and the items of ``SLOW_MODULES``
    and the ``SLOW_TESTS`` ``slow``."""
    for item in items:
        real_slam = listed(item, REAL_SLAM_TESTS)
        if real_slam:
            item.add_marker(pytest.mark.real_slam)
        if real_slam or item.path.name in SLOW_MODULES or listed(item, SLOW_TESTS):
            item.add_marker(pytest.mark.slow)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """Under ``-n`` (xdist's ``--dist load``), send a test class, or a module's test functions, to
    one worker (``loadscope``): a class-scoped fixture, such as the one real command of an
    end-to-end test class, then runs once, not once per worker. Only for this suite (the example
    suites keep xdist's default), and an explicit ``--dist`` other than load is kept."""
    if config.getoption("dist") != "load":
        return None
    from xdist.scheduler import LoadScopeScheduling

    return LoadScopeScheduling(config, log)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Root of the real dataset excerpts; tests that need it skip when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real dataset excerpts not found at {SHARED_DATA} (set SAL_TEST_DATA to the shared/data folder)")
    return SHARED_DATA


@pytest.fixture(scope="session", autouse=True)
def isolated_sal_cache(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """Every test session renders and caches into its own folders, never the user's cache nor
    the checkout: ``sal`` commands run without ``--cache-dir`` use ``./.sal/cache``, which is
    redirected here (the plugin's ``<rootdir>/.sal/cache`` is left as it is)."""
    import pytest_sal.store.content_cache

    root = tmp_path_factory.mktemp("sal-cache")
    commands_cache = tmp_path_factory.mktemp("commands-trial-cache")
    default = pytest_sal.store.content_cache.content_cache_dir
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("SAL_CACHE_DIR", str(root))
        patch.setattr(
            pytest_sal.store.content_cache,
            "content_cache_dir",
            lambda rootdir=None: commands_cache if rootdir is None else default(rootdir),
        )
        yield root


@pytest.fixture(scope="session")
def orb_vocabulary(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The default ORB-SLAM3 vocabulary (k=10, L=6; or ``$SAL_ORB_VOCABULARY``), built at most
    once per test run: xdist workers share the folder beside their basetemps and its lock."""
    from sal_wrappers.orbslam3.vocabulary import ensure_vocabulary

    base = tmp_path_factory.getbasetemp()
    folder = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "orb-vocabulary"
    return ensure_vocabulary(cache_dir=folder)


@pytest.fixture
def ch7_folder(shared_data: Path, tmp_path: Path) -> Path:
    """The two real colour + depth pairs as a freiburg2 sequence, with a little ground truth."""
    src = shared_data / "tum_rgbd_samples" / "slambook2_tum_like"
    folder = tmp_path / "rgbd_dataset_freiburg2_desk"
    (folder / "rgb").mkdir(parents=True)
    (folder / "depth").mkdir()
    stamps = ["1311868164.363181", "1311868164.399454"]
    dstamps = ["1311868164.373557", "1311868164.407867"]
    for k, (t, td) in enumerate(zip(stamps, dstamps), start=1):
        shutil.copy(src / f"ch7_{k}.png", folder / "rgb" / f"{t}.png")
        shutil.copy(src / f"ch7_{k}_depth.png", folder / "depth" / f"{td}.png")
    (folder / "rgb.txt").write_text("# color images\n" + "".join(f"{t} rgb/{t}.png\n" for t in stamps))
    (folder / "depth.txt").write_text("# depth maps\n" + "".join(f"{t} depth/{t}.png\n" for t in dstamps))
    (folder / "groundtruth.txt").write_text(
        "# timestamp tx ty tz qx qy qz qw\n"
        "1311868164.3500 -0.1166 -1.3880 1.3881 0.6566 0.6010 -0.2994 -0.3413\n"
        "1311868164.3800 -0.1164 -1.3879 1.3880 0.6567 0.6008 -0.2993 -0.3415\n"
        "1311868164.4100 -0.1160 -1.3877 1.3878 0.6568 0.6007 -0.2991 -0.3417\n"
    )
    return folder
