"""``SlamSystem.identity()``: what goes into a trial's cache key besides the options, so that a
changed program, vocabulary or VO source is never served a stale cached trial."""

from __future__ import annotations

import importlib.metadata
import importlib.util
import shutil
from pathlib import Path

import pytest

import sal_wrappers.base as base
import sal_wrappers.reference_vo.system as reference_vo
from pytest_sal.store.cache_keys import cache_key
from pytest_sal.testing import FakeSlam
from sal_wrappers import SlamSystemError, create
from sal_wrappers.base import file_sha256

needs_orbslam3 = pytest.mark.skipif(importlib.util.find_spec("pyorbslam3") is None, reason="pyorbslam3 is not installed (extra orbslam3)")


def test_the_default_identity_is_name_version_and_options() -> None:
    system = FakeSlam(tracked="min(1, v / 80)")
    assert system.identity() == {"name": "fake", "version": 1, "options": system.options()}


def test_file_sha256_reads_a_file_once_per_version(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    reads: list[object] = []
    digest = base.hashlib.file_digest

    def counting(fh: object, name: str) -> object:
        reads.append(fh)
        return digest(fh, name)  # type: ignore[arg-type]

    monkeypatch.setattr(base.hashlib, "file_digest", counting)
    path = tmp_path / "vocabulary.txt"
    path.write_text("words\n")
    first = file_sha256(path)
    assert file_sha256(path) == first and file_sha256(str(path)) == first
    assert len(reads) == 1  # the second and third asks cost a stat
    path.write_text("other words\n")
    assert file_sha256(path) != first and len(reads) == 2


# -- reference_vo ----------------------------------------------------------------------------------
def test_reference_vo_identity_covers_its_sources(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    names = [p.name for p in reference_vo.source_files()]
    assert {"system.py", "geometry.py", "odometry.py", "bundle.py"} <= set(names)
    copies = [Path(shutil.copy(p, tmp_path / p.name)) for p in reference_vo.source_files()]
    monkeypatch.setattr(reference_vo, "source_files", lambda: copies)
    system = create("reference_vo")
    before = system.identity()
    assert before["options"] == system.options() and before["name"] == "reference_vo"
    assert set(before["sources"]) == set(names) and "opencv" in before
    copies[-1].write_text(copies[-1].read_text() + "\n# an edit\n")
    after = system.identity()
    assert after["sources"][copies[-1].name] != before["sources"][copies[-1].name]
    assert cache_key(system=after) != cache_key(system=before)


# -- orbslam3 --------------------------------------------------------------------------------------
@needs_orbslam3
def test_orbslam3_identity_covers_vocabulary_settings_and_package(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    vocabulary, settings = tmp_path / "voc.txt", tmp_path / "s.yaml"
    vocabulary.write_text("10 6 0 0\n")
    settings.write_text("%YAML:1.0\n")
    system = create("orbslam3", vocabulary=str(vocabulary), settings=str(settings))
    before = system.identity()
    assert before["pyorbslam3"] == importlib.metadata.version("pyorbslam3")
    assert before["files"] == {"vocabulary": file_sha256(vocabulary), "settings": file_sha256(settings)}
    vocabulary.write_text("10 6 0 0\n0 0 1 2\n")
    after_vocabulary = system.identity()
    assert after_vocabulary["files"]["vocabulary"] != before["files"]["vocabulary"]
    settings.write_text("%YAML:1.0\nORBextractor.nFeatures: 100\n")
    assert system.identity()["files"]["settings"] != after_vocabulary["files"]["settings"]
    monkeypatch.setattr(importlib.metadata, "version", lambda name: "9.9.9")
    assert system.identity()["pyorbslam3"] == "9.9.9"


@needs_orbslam3
def test_orbslam3_default_vocabulary_follows_the_environment_and_the_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("SAL_ORB_VOCABULARY", raising=False)
    monkeypatch.setenv("SAL_CACHE_DIR", str(tmp_path / "cache"))
    system = create("orbslam3")
    built = system.identity()["files"]["vocabulary"]
    assert built.startswith("built by sal_wrappers.orbslam3.vocabulary")  # the default build is named, not hashed or built here
    official = tmp_path / "cache" / "vocabulary" / "ORBvoc.txt"
    official.parent.mkdir(parents=True)
    official.write_text("official\n")
    assert system.identity()["files"]["vocabulary"] == file_sha256(official)
    mine = tmp_path / "mine.txt"
    mine.write_text("mine\n")
    monkeypatch.setenv("SAL_ORB_VOCABULARY", str(mine))
    assert system.identity()["files"]["vocabulary"] == file_sha256(mine)
    mine.unlink()
    with pytest.raises(SlamSystemError, match="orbslam3: cannot read the vocabulary file .*mine.txt"):
        system.identity()
