"""The example experiment configs run ``sal perturb`` end to end, on the synthetic world as
shipped (fewer frames) and on a real dataset excerpt with only its ``dataset`` block changed.
Graded severities (``<x>_light``, ``<x>_moderate``, ``<x>_heavy``) must really grade: the written
frames move further from the clean ones from light to heavy."""

from __future__ import annotations

import json
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from example_config_table import CONFIGS, GRADES, NAMES, WORLD, _groups, _params, _real_kind, _steps

from pytest_sal.cli.main import main
from pytest_sal.experiment.config import build_sequence, load_config
from pytest_sal.experiment.schema import ExperimentConfig
from sal_adapters import DatasetWarning, Sequence, open_dataset
from sal_adapters.images import read_image
from sal_modules import module_class

FRAMES = 3  # synthetic frames per test run (the files ship with 20)
REAL_FRAMES = 3
MIN_MAD = 0.25  # grey levels: a perturbed frame differs from the clean one by more than this on average

KITTI_SEQ = Path("kitti") / "sequences" / "07"
EUROC_SEQ = Path("euroc") / "V1_01_easy_micro"


def _needs_depth(config: ExperimentConfig) -> bool:
    return any(module_class(t).needs_depth for p in config.enabled() for t in _steps(config, p.name) if t != "none")


def _drops_frames(config: ExperimentConfig, name: str) -> bool:
    return "frame_drop" in _steps(config, name)


def _rewrite(src: Path, dst: Path, base_dir: Path, dataset: dict[str, Any] | None = None) -> Path:
    """A copy of the config ``src`` at ``dst`` with ``output.base_dir`` moved and either fewer
    synthetic frames or (``dataset``) another dataset block; nothing else changes."""
    data = yaml.safe_load(src.read_text())
    if dataset is None:
        data["dataset"]["max_frames"] = FRAMES
        data["dataset"]["options"]["frames"] = FRAMES
    else:
        data["dataset"] = dataset
    data["output"]["base_dir"] = str(base_dir)
    dst.write_text(yaml.safe_dump(data, sort_keys=False))
    return dst


def _perturb(config_path: Path, cache: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    rc = main(["perturb", str(config_path), "--cache-dir", str(cache)])
    out, err = capsys.readouterr()
    return rc, out, err


def _mad(a: np.ndarray, b: np.ndarray) -> float:
    """Mean absolute difference of two uint8 images (0..255)."""
    assert a.shape == b.shape, (a.shape, b.shape)
    return float(np.abs(a.astype(np.int16) - b.astype(np.int16)).mean())


def _dropped(folder: Path) -> list[int]:
    path = folder / "dropped_frames.txt"
    if not path.is_file():
        return []
    return [int(line) for line in path.read_text().splitlines() if line and not line.startswith("#")]


def _assert_grades(config: ExperimentConfig, diffs: dict[str, float], kept: dict[str, list[Any]], n_in: int) -> None:
    """Each graded group grows from light to heavy: in pixel difference, or (frame drop) in
    frames lost, the heavier loss a subset of the lighter one."""
    for stem, grades in _groups(config).items():
        order = [grades[g] for g in GRADES if g in grades]
        if _drops_frames(config, order[0]):
            rates = [_params(config, n, "frame_drop")["drop_rate"] for n in order]
            assert rates == sorted(rates) and len(set(rates)) == len(rates), f"{stem}: drop_rate must grow light -> heavy: {rates}"
            for lighter, heavier in pairwise(order):
                assert set(kept[heavier]) <= set(kept[lighter]), f"{heavier} keeps frames that {lighter} dropped"
            counts = [len(kept[n]) for n in order]
            assert counts == sorted(counts, reverse=True) and counts[-1] < counts[0] <= n_in, f"{stem}: frames kept {counts} of {n_in}"
            continue
        values = [diffs[n] for n in order]
        assert all(a < b for a, b in pairwise(values)), f"{stem}: difference from the clean frames must grow light -> heavy: " + ", ".join(
            f"{n}={v:.3f}" for n, v in zip(order, values)
        )
        if "bandwidth" in _steps(config, order[0]):
            rates = [_params(config, n, "bandwidth")["target_mbps"] for n in order]
            assert all(a > b for a, b in pairwise(rates)), f"{stem}: target_mbps must fall light -> heavy: {rates}"


# ------------------------------------------------------------------------------ 3. synthetic run


@pytest.mark.parametrize("name", NAMES)
def test_perturb_synthetic(name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], record_property: Any) -> None:
    path = _rewrite(CONFIGS / name, tmp_path / name, tmp_path / "results")
    config = load_config(path)
    rc, out, err = _perturb(path, tmp_path / "cache", capsys)
    assert rc == 0, err
    root = tmp_path / "results" / config.experiment.name
    assert f"wrote {root}" in out
    clean = build_sequence(config)
    assert len(clean) == FRAMES and clean.sensor == WORLD[name][1]
    stereo = clean.sensor == "stereo"
    by_index = {int(r.index): k for k, r in enumerate(clean.records)}
    results = json.loads((root / "pipeline_results.json").read_text())
    assert results["status"] == "completed"

    diffs: dict[str, float] = {}
    kept: dict[str, list[int]] = {}
    for pert in config.enabled():
        folder = root / "images" / pert.name
        assert folder.is_dir(), f"{folder} was not written"
        dropped = _dropped(folder)
        indices = [i for i in sorted(by_index) if i not in dropped]
        expected = {f"{i:06d}.png" for i in indices}
        streams = ["image_left", "image_right"] if stereo else ["image_left"]
        for stream in streams:
            assert {f.name for f in (folder / stream).iterdir()} == expected, f"{pert.name}/{stream}"
        if _drops_frames(config, pert.name):
            assert len(indices) < FRAMES or pert.name.endswith("_light"), f"{pert.name} dropped nothing"
        else:
            assert not dropped and len(indices) == FRAMES
        assert results["perturbations"][pert.name]["frames_kept"] == len(indices)
        assert results["perturbations"][pert.name]["dropped_frames"] == dropped
        back = open_dataset("synthetic", folder)  # the written folder reads back as a sequence
        assert len(back) == len(indices)
        per_frame = []
        for i in indices:
            frame = clean[by_index[i]]
            per_frame.append(_mad(read_image(folder / "image_left" / f"{i:06d}.png"), frame.image))
            if stereo:
                per_frame.append(_mad(read_image(folder / "image_right" / f"{i:06d}.png"), frame.right))
        diffs[pert.name] = float(np.mean(per_frame))
        kept[pert.name] = indices
        record_property(f"mad_{pert.name}", round(diffs[pert.name], 3))  # in --junitxml
        record_property(f"kept_{pert.name}", len(indices))
        if _drops_frames(config, pert.name):
            assert diffs[pert.name] == 0.0, f"{pert.name}: frame drop must not change the kept frames"
        else:
            assert diffs[pert.name] > MIN_MAD, f"{pert.name}: the written frames barely differ from the clean ones ({diffs[pert.name]:.3f})"
    _assert_grades(config, diffs, kept, FRAMES)


# ------------------------------------------------------------------------------ 4. real data


@pytest.fixture
def tum_rgbd(ch7_folder: Path) -> Path:
    """The two real colour + depth pairs as a TUM freiburg2 sequence (conftest's ``ch7_folder``)."""
    return ch7_folder


def _real_dataset(kind: str, shared_data: Path, request: pytest.FixtureRequest) -> tuple[dict[str, Any], Path, list[tuple[str, str]]]:
    """The dataset block, the source folder, and (written image dir, source image dir) pairs."""
    if kind == "kitti":
        src = shared_data / KITTI_SEQ
        if not (src / "image_0").is_dir():
            pytest.skip(f"KITTI excerpt not found at {src}")
        return {"type": "kitti", "path": str(src), "max_frames": REAL_FRAMES}, src, [("sequences/07/image_0", "image_0")]
    if kind == "tum":
        src = request.getfixturevalue("tum_rgbd")
        return {"type": "tum", "path": str(src), "max_frames": REAL_FRAMES}, src, [("rgb", "rgb")]
    src = shared_data / EUROC_SEQ
    if not (src / "mav0").is_dir():
        pytest.skip(f"EuRoC excerpt not found at {src}")
    pairs = [(f"{EUROC_SEQ.name}/mav0/{cam}/data", f"mav0/{cam}/data") for cam in ("cam0", "cam1")]
    return {"type": "euroc", "path": str(src), "max_frames": REAL_FRAMES, "stereo": True}, src, pairs


@pytest.fixture(scope="module")
def mono_depth_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny monocular depth ONNX model built here, standing in for a real network (Depth
    Anything, MiDaS) that a user points SAL_DEPTH_MODEL at: depth = 8 m x the ImageNet-normalised
    grey level + 20 m, so 3 m (black) .. 41 m (white, the sky), positive everywhere."""
    from onnx_models import depth_model

    return depth_model(tmp_path_factory.mktemp("depth-model") / "mono_depth.onnx", gain=8.0, offset=20.0)


def _assert_kitti_refused_without_depth(path: Path, root: Path, cache: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The KITTI excerpt is mono (image_0 only): rain, fog and motion blur need metric depth,
    and neither native depth nor stereo matching applies. sal perturb must refuse before
    writing anything and name each missing provider and the way out (a mono ONNX model)."""
    rc, _, err = _perturb(path, cache, capsys)
    assert rc == 2
    assert "needs depth and no depth provider applies to 'kitti/07'" in err
    assert "native: sequence 'kitti/07' (mono) has no depth maps" in err
    assert "stereo: sequence 'kitti/07' is mono, not a stereo pair" in err
    assert "SAL_DEPTH_MODEL=model.onnx" in err
    assert not (root / "images").exists()


def _clean_sequence(kind: str, config: ExperimentConfig) -> Sequence:
    """The config's unperturbed real sequence (the EuRoC excerpt warns of its 4 missing images)."""
    if kind == "euroc":
        with pytest.warns(DatasetWarning, match=r"cam1/data\.csv: 4 of 99 rows skipped"):
            return build_sequence(config)
    return build_sequence(config)


def _written_frames(
    pert: str, folder: Path, src: Path, pairs: list[tuple[str, str]], n_kept: int, n_in: int
) -> tuple[list[str], list[float]]:
    """The file names written into each ``(written, source)`` folder pair of ``folder`` (those of
    the last pair) and each written frame's mean absolute difference to its source (grey levels)."""
    names: list[str] = []
    per_frame = []
    for written_dir, source_dir in pairs:
        names = sorted(f.name for f in (folder / written_dir).iterdir())
        source_names = sorted(f.name for f in (src / source_dir).iterdir())
        # the dataset's own layout and file names: the first frames of the source, less the dropped ones
        assert set(names) <= set(source_names[:n_in]), f"{pert}: {written_dir} holds files other than the first {n_in} of the source"
        assert len(names) == n_kept
        for file_name in names:
            per_frame.append(_mad(read_image(folder / written_dir / file_name), read_image(src / source_dir / file_name)))
    return names, per_frame


def _assert_written_layout(pert: str, folder: Path, kind: str, n_in: int, n_kept: int) -> None:
    """``folder`` holds the dataset kind's own layout (RGB-D depth maps too) and reads back with
    the adapter of its kind, ``n_kept`` of the ``n_in`` frames."""
    layout = {
        "kitti": ["sequences/07/times.txt", "sequences/07/calib.txt"],
        "tum": ["rgb.txt", "depth.txt"],
        "euroc": [f"{EUROC_SEQ.name}/mav0/cam0/data.csv", f"{EUROC_SEQ.name}/mav0/cam1/data.csv"],
    }[kind]
    for listed in layout:
        assert (folder / listed).is_file(), f"{pert}: {listed} missing from the written {kind} layout"
    if kind == "tum":  # RGB-D: the depth maps travel with the perturbed colour frames
        assert len(list((folder / "depth").glob("*.png"))) == n_in
    if kind == "kitti":  # each reads back with the adapter of its kind
        back = open_dataset("kitti", folder / "sequences" / "07")
    elif kind == "euroc":
        back = open_dataset("euroc", folder / EUROC_SEQ.name, stereo=True)
    else:
        back = open_dataset("tum", folder)
    assert len(back) == n_kept


@pytest.mark.parametrize("name", NAMES)
def test_perturb_real_data(
    name: str,
    shared_data: Path,
    tmp_path: Path,
    request: pytest.FixtureRequest,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    record_property: Any,
) -> None:
    kind = _real_kind(name)
    dataset, src, pairs = _real_dataset(kind, shared_data, request)
    path = _rewrite(CONFIGS / name, tmp_path / name, tmp_path / "results", dataset)
    config = load_config(path)
    root = tmp_path / "results" / config.experiment.name
    monkeypatch.delenv("SAL_DEPTH_MODEL", raising=False)

    if kind == "kitti" and _needs_depth(config):
        _assert_kitti_refused_without_depth(path, root, tmp_path / "cache", capsys)
        # The product's monocular ONNX provider then makes the same config run on the same data.
        monkeypatch.setenv("SAL_DEPTH_MODEL", str(request.getfixturevalue("mono_depth_model")))

    rc, _, err = _perturb(path, tmp_path / "cache", capsys)
    assert rc == 0, err
    if kind == "euroc":
        # the real excerpt's cam1/data.csv lists 4 images that do not exist (see tests/test_euroc_errors.py)
        assert "sal: warning:" in err and "cam1/data.csv" in err
    else:
        assert "sal: warning:" not in err, err
    n_in = len(_clean_sequence(kind, config))
    assert n_in == min(REAL_FRAMES, 2 if kind == "tum" else REAL_FRAMES)
    written_any = 0
    kept: dict[str, list[str]] = {}
    diffs: dict[str, float] = {}
    for pert in config.enabled():
        folder = root / "images" / pert.name
        assert folder.is_dir(), f"{folder} was not written"
        dropped = set(_dropped(folder))
        kept[pert.name], per_frame = _written_frames(pert.name, folder, src, pairs, n_in - len(dropped), n_in)
        written_any += len(per_frame)
        diffs[pert.name] = float(np.mean(per_frame))
        record_property(f"mad_{pert.name}", round(diffs[pert.name], 3))
        if _drops_frames(config, pert.name):
            assert diffs[pert.name] == 0.0  # a frame drop loses frames, it does not change them
        else:
            assert not dropped
            assert diffs[pert.name] > MIN_MAD, f"{pert.name}: written frames barely differ from the originals ({diffs[pert.name]:.3f})"
        _assert_written_layout(pert.name, folder, kind, n_in, n_in - len(dropped))
    assert written_any
    _assert_grades(config, diffs, kept, n_in)  # the levels grade on real frames too
