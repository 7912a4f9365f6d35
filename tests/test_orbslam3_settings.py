"""The ``orbslam3`` system without ORB-SLAM3: its settings files, option checks, state mapping
and final-trajectory reader. None of these needs ``pyorbslam3``, so this module runs (and must
pass) where the ``orbslam3`` extra is not installed; the runs are in test_orbslam3.py."""

from __future__ import annotations

import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

from sal_adapters import Camera
from sal_adapters.datasets import open_dataset
from sal_wrappers import SlamSystemError, TrackState, create
from sal_wrappers.orbslam3.settings import (
    VIEWER_KEYS,
    Matrix,
    OrbParameters,
    format_value,
    settings_entries,
    settings_yaml,
    write_settings,
)
from sal_wrappers.orbslam3.states import ORB_STATES, map_states, read_final_trajectory, segment_ids

OK, RL, LOST = ORB_STATES["OK"], ORB_STATES["RECENTLY_LOST"], ORB_STATES["LOST"]
NI, NIY = ORB_STATES["NOT_INITIALIZED"], ORB_STATES["NO_IMAGES_YET"]

REAL_KEYS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2")
INT_KEYS = (
    "Camera.width",
    "Camera.height",
    "Camera.fps",
    "Camera.RGB",
    "ORBextractor.nFeatures",
    "ORBextractor.nLevels",
    "ORBextractor.iniThFAST",
    "ORBextractor.minThFAST",
)


# -- helpers ---------------------------------------------------------------------------------
def read_back(path: Path) -> cv2.FileStorage:
    """The settings file as ORB-SLAM3 reads it (cv::FileStorage: real and int are distinct)."""
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert storage.isOpened()
    return storage


def assert_types(storage: cv2.FileStorage, text: str) -> None:
    """Every key of the file has the type ORB-SLAM3 insists on."""
    keys = [line.split(":")[0] for line in text.splitlines()[1:] if line and not line.startswith(" ")]
    for key in keys:
        node = storage.getNode(key)
        assert not node.empty(), key
        if key in INT_KEYS:
            assert node.isInt(), key
        elif key in ("File.version", "Camera.type"):
            assert node.isString(), key
        elif key == "Stereo.T_c1_c2":
            assert node.isMap(), key
        else:
            assert node.isReal(), key


# -- settings files --------------------------------------------------------------------------
def test_format_value_reals_ints_strings() -> None:
    assert format_value(500.0) == "500.0"
    assert format_value(500) == "500"
    assert format_value(np.float64(0.0)) == "0.0"
    assert format_value(np.int64(7)) == "7"  # type: ignore[arg-type]  # numpy integers are written as ints too
    assert format_value(1.76187114e-05) == "1.76187114e-05"
    assert format_value(1e16) == "1e+16"
    assert format_value(True) == "1"
    assert format_value("1.0") == '"1.0"'
    assert format_value(Matrix(np.eye(2))).endswith("data: [1.0, 0.0, 0.0, 1.0]")
    with pytest.raises(ValueError, match="non-finite"):
        format_value(float("nan"))
    with pytest.raises(TypeError):
        format_value([1.0])  # type: ignore[arg-type]


def test_settings_mono_types_and_keys(tmp_path: Path) -> None:
    camera = Camera(fx=707.0912, fy=707.0912, cx=601.8873, cy=183.1104, width=1226, height=370)
    path = write_settings(tmp_path / "mono.yaml", camera, "mono", 9.615384, OrbParameters(features=2000))
    text = path.read_text()
    assert text.startswith("%YAML:1.0\n")
    storage = read_back(path)
    assert_types(storage, text)
    assert storage.getNode("File.version").string() == "1.0"
    assert storage.getNode("Camera.type").string() == "PinHole"
    assert storage.getNode("Camera.fps").real() == 10  # rounded
    assert storage.getNode("Camera1.fx").real() == pytest.approx(707.0912)
    assert storage.getNode("Camera1.k1").real() == 0.0  # no distortion: zeros
    assert storage.getNode("ORBextractor.nFeatures").real() == 2000
    for key, value in VIEWER_KEYS:
        assert storage.getNode(key).real() == pytest.approx(value)
    for key in ("Camera2.fx", "Stereo.T_c1_c2", "Stereo.ThDepth", "Stereo.b", "RGBD.DepthMapFactor", "Camera1.k3"):
        assert storage.getNode(key).empty(), key
    # the same text through a plain YAML parser, without the %YAML line
    import yaml

    data = yaml.safe_load(text.split("\n", 1)[1])
    assert isinstance(data["Camera1.fx"], float) and isinstance(data["Camera.width"], int)
    assert all(isinstance(data[k], float) for k, _ in VIEWER_KEYS)


def test_settings_stereo_from_euroc_camera(shared_data: Path, tmp_path: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sequence = open_dataset("euroc", shared_data / "euroc" / "V1_01_easy_micro", stereo=True)
    camera = sequence.camera
    assert camera.right is not None and camera.T_lr is not None
    path = write_settings(tmp_path / "stereo.yaml", camera, "stereo", sequence.fps, OrbParameters(th_depth=60.0))
    text = path.read_text()
    storage = read_back(path)
    assert_types(storage, text)
    assert storage.getNode("Camera.fps").real() == 20
    for i, key in enumerate(REAL_KEYS):
        left = [camera.fx, camera.fy, camera.cx, camera.cy, *camera.distortion][i]
        right = [camera.right.fx, camera.right.fy, camera.right.cx, camera.right.cy, *camera.right.distortion][i]
        assert storage.getNode(f"Camera1.{key}").real() == left
        assert storage.getNode(f"Camera2.{key}").real() == right
    assert camera.right.fx != camera.fx  # unrectified: the right camera's own intrinsics
    assert storage.getNode("Stereo.ThDepth").real() == 60.0
    T = np.asarray(storage.getNode("Stereo.T_c1_c2").mat(), dtype=float)
    assert T.shape == (4, 4)
    np.testing.assert_allclose(T, camera.T_lr, atol=1e-7)  # pose of camera 2 in camera 1
    assert T[0, 3] == pytest.approx(0.110074, abs=1e-6)
    assert "!!opencv-matrix\n  rows: 4\n  cols: 4\n  dt: f\n" in text
    for key in ("Stereo.b", "RGBD.DepthMapFactor"):
        assert storage.getNode(key).empty()


def test_settings_rectified_stereo_copies_camera1() -> None:
    camera = Camera(fx=500.0, fy=500.0, cx=320.0, cy=240.0, width=640, height=480, baseline_m=0.2)
    entries = dict(settings_entries(camera, "stereo", 30.0))
    assert entries["Camera2.fx"] == 500.0 and entries["Camera2.k1"] == 0.0
    transform = entries["Stereo.T_c1_c2"]
    assert isinstance(transform, Matrix)
    np.testing.assert_array_equal(transform.values[:3, 3], [0.2, 0.0, 0.0])
    with pytest.raises(ValueError, match="T_lr"):
        settings_entries(Camera(fx=500.0, fy=500.0, cx=320.0, cy=240.0, width=640, height=480), "stereo", 30.0)


def test_settings_rgbd_keys(tmp_path: Path) -> None:
    camera = Camera(
        fx=525.0, fy=525.0, cx=319.5, cy=239.5, width=640, height=480, distortion=(0.1, -0.2, 0.001, 0.002, 0.05), depth_scale=5000.0
    )
    path = write_settings(tmp_path / "rgbd.yaml", camera, "rgbd", 30.0)
    text = path.read_text()
    storage = read_back(path)
    assert_types(storage, text)
    assert storage.getNode("RGBD.DepthMapFactor").real() == 1.0  # depth goes in as float32 metres
    assert storage.getNode("Stereo.ThDepth").real() == 40.0
    assert storage.getNode("Stereo.b").real() == pytest.approx(0.08)  # virtual baseline, required
    assert storage.getNode("Camera1.k3").real() == 0.05
    assert storage.getNode("Camera2.fx").empty() and storage.getNode("Stereo.T_c1_c2").empty()
    assert "RGBD.DepthMapFactor: 1.0\n" in settings_yaml(camera, "rgbd", 30.0)


# -- option checks (before pyorbslam3 is looked for), states, trajectories ----------------------
@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("mode", "imu"),
        ("features", 0),
        ("features", 2000.0),
        ("features", True),
        ("scale_factor", 1.0),
        ("levels", 0),
        ("fast_threshold", 300),
        ("min_fast_threshold", 25),  # above fast_threshold 20
        ("pace", -1.0),
        ("pace", "fast"),
        ("th_depth", 0.0),
        ("vocabulary", "/nonexistent/voc.txt"),
        ("settings", "/nonexistent/settings.yaml"),
        ("keep_final", "yes"),
        ("load_retries", -1),
        ("load_retries", 6),
    ],
)
def test_bad_option_names_option(option: str, value: object) -> None:
    with pytest.raises(SlamSystemError, match=option):
        create("orbslam3", **{option: value})


def test_state_mapping_and_segments() -> None:
    raw = [NIY, NI, NI, OK, OK, RL, OK, LOST, NIY, NI, OK, OK, OK, RL, None]
    states = map_states(raw)
    N, K, L = TrackState.NOT_INITIALISED, TrackState.OK, TrackState.LOST
    assert states.tolist() == [N, N, N, K, K, L, K, L, L, L, K, K, K, L, L]
    # RECENTLY_LOST -> OK stays in the map; LOST / reset starts a new one
    assert segment_ids(raw).tolist() == [-1, -1, -1, 0, 0, -1, 0, -1, -1, -1, 1, 1, 1, -1, -1]
    assert segment_ids([OK, NI, OK]).tolist() == [0, -1, 1]
    assert segment_ids([NI, NI]).tolist() == [-1, -1]
    assert map_states([]).tolist() == []


def test_read_final_trajectory_snaps_times(tmp_path: Path) -> None:
    frames = np.array([1403715273.262143, 1403715273.312143, 1403715273.362143])
    path = tmp_path / "f.txt"
    path.write_text(
        "1403715273262143232.000000 0.0 0.0 0.0 -0.0 -0.0 -0.0 1.0\n1403715273312143104.000000 0.1 0.2 0.3 0.0 0.0 0.7071068 0.7071068\n"
    )
    traj = read_final_trajectory(path, frames)
    np.testing.assert_array_equal(traj.timestamps, frames[:2])
    np.testing.assert_allclose(traj.positions[1], [0.1, 0.2, 0.3])
    np.testing.assert_allclose(traj.quaternions[1], [0.0, 0.0, 0.7071068, 0.7071068], atol=1e-6)  # x y z w
    path.write_text("")
    with pytest.raises(ValueError, match="no poses"):
        read_final_trajectory(path, frames)
