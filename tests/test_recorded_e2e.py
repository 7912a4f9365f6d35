"""ORB-SLAM3 on what teams record (issue 26): the KITTI 07 excerpt as a bare MCAP file tracks as
the folder does, and a requirement's search runs end to end on that bag and on an H.264 video
made from the same excerpt (``write_sequence(kitti, "kitti07.mp4")``).

Measured on the 2-core workplace machine (140 frames, 2000 features, paced at 9.6 Hz, three
runs each): the folder tracks 136/140 frames in every run with a Sim(3) ATE of 0.245, 0.282,
0.279 m over 78 m, the MCAP bag 136/140 with 0.258, 0.261, 0.290 m. The bag's frames are the
folder's to the bit, so the two differ only by ORB-SLAM3's own run-to-run noise.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest
from plugin_suites import HEADER, has_line, run

from pytest_sal.analysis.metrics import evaluate
from sal_adapters import Sequence, open_dataset, write_sequence
from sal_wrappers import RunResult, create

pytestmark = pytest.mark.skipif(importlib.util.find_spec("pyorbslam3") is None, reason="pyorbslam3 is not installed")


@pytest.fixture(scope="module")
def kitti(shared_data: Path) -> Sequence:
    return open_dataset("kitti", shared_data / "kitti", sequence="07")


@pytest.fixture(scope="module")
def recordings(kitti: Sequence, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The excerpt as a bare MCAP file and as an MP4 video (with its sidecar calibration)."""
    folder = tmp_path_factory.mktemp("recorded")
    return {"rosbag": write_sequence(kitti, folder / "kitti07.mcap"), "video": write_sequence(kitti, folder / "kitti07.mp4")}


def orbslam3(vocabulary: Path, sequence: Sequence, workdir: Path) -> RunResult:
    return create("orbslam3", vocabulary=vocabulary, features=2000, pace=True).run(sequence, workdir, timeout=300)


def test_orbslam3_tracks_the_mcap_kitti07_as_it_tracks_the_folder(
    kitti: Sequence, recordings: dict[str, Path], orb_vocabulary: Path, tmp_path: Path
) -> None:
    bag = open_dataset("rosbag", recordings["rosbag"])
    results = {name: orbslam3(orb_vocabulary, seq, tmp_path / name) for name, seq in (("folder", kitti), ("bag", bag))}
    scores = {name: evaluate(result, kitti.groundtruth) for name, result in results.items()}
    for name, result in results.items():
        assert result.ok and result.tracked >= 130, f"{name}: {result.summary()}"  # measured 136/140 on both
        assert scores[name].ate_rmse is not None and scores[name].ate_rmse <= 0.40, f"{name}: {scores[name].ate_rmse} m"  # 0.24-0.27 m
    assert abs(results["bag"].tracked - results["folder"].tracked) <= 4
    assert list(results["bag"].timestamps) == pytest.approx(list(results["folder"].timestamps), abs=1e-9)


DATASET_CONFTEST = """
import os

import pytest
from sal_adapters import open_dataset
from sal_wrappers import create


@pytest.fixture(scope="session")
def sal_dataset():
    return open_dataset(os.environ["SAL_KIND"], os.environ["SAL_RECORDING"], max_frames=60)


@pytest.fixture
def sal_system():
    return create("orbslam3", vocabulary=os.environ["SAL_ORB_VOCABULARY"])
"""


@pytest.mark.parametrize("kind", ["rosbag", "video"])
def test_a_requirement_searches_on_a_recording(
    kind: str, recordings: dict[str, Path], orb_vocabulary: Path, pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("SAL_ORB_VOCABULARY", str(orb_vocabulary))
    monkeypatch.setenv("SAL_KIND", kind)
    monkeypatch.setenv("SAL_RECORDING", str(recordings[kind]))
    pytester.makeconftest(DATASET_CONFTEST)
    pytester.makepyfile(
        test_recording=HEADER.replace("fog, rain", "night")
        + f"""

@sal.require(tracking_rate >= 0.5, night.illuminance_lux >= 400, reliability=0.5, max_runs=6)
def test_dusk(sal_outcome):
    assert sal_outcome.dataset.startswith("{kind}/kitti07") and sal_outcome.verdict == "passed"
    edge = sal_outcome.trials[0]
    assert edge.value == 400 and edge.passed and edge.runs[0]["tracking_rate"] > 0.5
    assert sal_outcome.boundary.noisy and sal_outcome.boundary.runs <= 6
"""
    )
    result = run(pytester, [], "-v")
    result.assert_outcomes(passed=1)
    has_line(result, "test_dusk", "PASSED (night.illuminance_lux boundary")
