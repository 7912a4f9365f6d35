"""Shared setup of the example suites: which dataset is perturbed and which system is tested.

As shipped, nothing here is active: every test gets the plugin's defaults,

* ``sal_dataset``: the synthetic world suiting the perturbation: the urban street (60 stereo
  frames, 10 Hz) for fog, rain, snow, night, sun_glare and motion_blur, the indoor room
  (90 RGB-D frames, 30 Hz) for everything else;
* ``sal_system``: ORB-SLAM3 when ``pyorbslam3`` is installed (``pip install -e '.[orbslam3]'``),
  else the built-in ``reference_vo`` (ini ``sal_system`` names another by name);
* ``sal_runs``: 1 run per trial (ini ``sal_runs``, or ``runs=`` of ``sal.require``).

Uncomment one of the blocks below to point the suites at real data or another system. A
fixture defined here applies to every test below this folder; put one in
``weather/conftest.py`` to change only that suite. The cache key holds the dataset's
fingerprint and the system's name, version and options, so switching either never reuses old
results.
"""

# import pytest
#
# import pytest_sal as sal
# import sal_wrappers

# ---------------------------------------------------------------------------------------------
# Real data: ``sal.dataset_fixture(kind, path, **options)`` opens the dataset once per session
# (a missing folder is one clear error naming it). Options are those of
# ``sal_adapters.open_dataset`` (``sal dataset info KIND PATH`` shows what it finds). Every kind
# takes ``start`` and ``max_frames``: keep sequences short, every trial runs the whole of it.
# ---------------------------------------------------------------------------------------------

# KITTI odometry, sequence 07, grey stereo (image_0/1), the first 200 frames (20 s at 10 Hz):
# sal_dataset = sal.dataset_fixture("kitti", "/data/kitti", sequence="07", stereo=True, max_frames=200)
#
# KITTI without stereo=True is monocular (ATE after Sim(3) alignment):
# sal_dataset = sal.dataset_fixture("kitti", "/data/kitti", sequence="07", max_frames=200)

# TUM RGB-D: the folder holding rgb.txt (Freiburg 1/2/3 intrinsics from the folder name, or
# intrinsics=(fx, fy, cx, cy)); RGB-D with depth, 300 frames are 10 s at 30 Hz:
# sal_dataset = sal.dataset_fixture("tum", "/data/tum/rgbd_dataset_freiburg1_xyz", max_frames=300)

# EuRoC MAV: the folder holding mav0/, stereo from cam0 and cam1 (20 Hz):
# sal_dataset = sal.dataset_fixture("euroc", "/data/euroc/V1_01_easy", stereo=True, max_frames=400)

# A different synthetic world for every test (scene "urban" or "indoor", another seed):
# sal_dataset = sal.dataset_fixture("synthetic", scene="urban", frames=100, seed=3, sensor="stereo")

# The street for the weather suite and a room for the rest: a fixture that looks at the test
# (datasets opened once per session).
# @pytest.fixture(scope="session")
# def kitti07():
#     from sal_adapters import open_dataset
#     return open_dataset("kitti", "/data/kitti", sequence="07", stereo=True, max_frames=200)
#
# @pytest.fixture(scope="session")
# def tum_xyz():
#     from sal_adapters import open_dataset
#     return open_dataset("tum", "/data/tum/rgbd_dataset_freiburg1_xyz", max_frames=300)
#
# @pytest.fixture
# def sal_dataset(request):
#     name = "kitti07" if "weather" in request.node.nodeid else "tum_xyz"
#     return request.getfixturevalue(name)

# ---------------------------------------------------------------------------------------------
# Another system: ``sal_wrappers.create(name, **options)`` (names: orbslam3, reference_vo,
# command, and plug-ins of the entry-point group ``sal.systems``).
# ---------------------------------------------------------------------------------------------

# The built-in visual odometry (OpenCV only, deterministic, fast):
# @pytest.fixture
# def sal_system():
#     return sal_wrappers.create("reference_vo")

# ORB-SLAM3 with other settings (the options go into the cache key and the summary):
# @pytest.fixture
# def sal_system():
#     return sal_wrappers.create("orbslam3", features=2000)

# Any external SLAM program through the ``command`` system: an argv template (a list, no
# shell) with placeholders, the sequence staged in a dataset layout, the trajectory read back
# (see "Any SLAM program: the command system" in the top-level README):
# @pytest.fixture
# def sal_system():
#     return sal_wrappers.create(
#         "command",
#         argv=["/opt/ORB_SLAM3/Examples/Stereo/stereo_euroc", "/opt/ORB_SLAM3/Vocabulary/ORBvoc.txt",
#               "{settings}", "{sequence}", "{timestamps_ns}"],
#         settings="synthetic_stereo.yaml",   # an ORB-SLAM3 settings template beside this file
#         layout="euroc", sensor="stereo",
#         output="CameraTrajectory.txt", output_format="tum", time_unit="ns",
#     )

# Several systems: parametrise the fixture, and every test runs once per system
# (test_fog[orbslam3], test_fog[reference_vo]); the summary has one row per system and the
# history keeps their boundaries apart.
# @pytest.fixture(params=["orbslam3", "reference_vo"])
# def sal_system(request):
#     return sal_wrappers.create(request.param)

# ---------------------------------------------------------------------------------------------
# Runs per trial: ORB-SLAM3 is multi-threaded and not deterministic; with 3 runs each trial's
# metrics are the median (3x the time).
# ---------------------------------------------------------------------------------------------
# @pytest.fixture
# def sal_runs():
#     return 3
