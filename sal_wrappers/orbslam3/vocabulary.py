"""The ORB vocabulary ORB-SLAM3 runs with: ``ensure_vocabulary`` finds or builds it, once.

>>> from sal_wrappers.orbslam3.vocabulary import ensure_vocabulary
>>> path = ensure_vocabulary()          # doctest: +SKIP   (built once, ~20 s, then cached)

The tree and its file format are in ``sal_wrappers.orbslam3.vocabulary_tree``, the training in
``sal_wrappers.orbslam3.vocabulary_training``; the training images are ORB descriptors of synthetic
views (or of a sequence's images, for ``sal vocab build``).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from sal_adapters.common.cache_dir import user_cache_dir
from sal_adapters.common.file_lock import FileLock
from sal_wrappers.orbslam3.vocabulary_training import build_vocabulary
from sal_wrappers.orbslam3.vocabulary_tree import DESCRIPTOR_BYTES, VocabularyError

__all__ = [
    "BUILDER_VERSION",
    "ENV_VARIABLE",
    "ensure_vocabulary",
    "orb_descriptors",
    "orb_image_descriptors",
    "sequence_images",
    "synthetic_training_images",
]

#: Bumped whenever a change gives different trees; part of the cached file name.
BUILDER_VERSION = 1
#: Environment variable naming a vocabulary file to use instead of building one.
ENV_VARIABLE = "SAL_ORB_VOCABULARY"

Progress = Callable[[str], None]


def orb_image_descriptors(images: Iterable[np.ndarray], features: int = 1000) -> list[np.ndarray]:
    """ORB descriptors (``Mi x 32`` uint8) of every image, OpenCV defaults but ``nfeatures``.

    Colour images are taken as RGB and converted to grey.
    """
    import cv2

    orb = cv2.ORB.create(nfeatures=features)
    result = []
    for image in images:
        grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
        _, found = orb.detectAndCompute(np.ascontiguousarray(grey), None)
        result.append(np.zeros((0, DESCRIPTOR_BYTES), np.uint8) if found is None else found)
    return result


def orb_descriptors(images: Iterable[np.ndarray], features: int = 1000) -> np.ndarray:
    """All ORB descriptors of ``images`` stacked into one ``N x 32`` uint8 array."""
    parts = orb_image_descriptors(images, features)
    return np.concatenate(parts) if parts else np.zeros((0, DESCRIPTOR_BYTES), np.uint8)


def sequence_images(sequence: object, count: int) -> list[np.ndarray]:
    """``count`` left images spread evenly over a ``sal_adapters.Sequence`` (all if shorter)."""
    total = len(sequence)  # type: ignore[arg-type]
    positions = np.unique(np.linspace(0, total - 1, num=min(count, total)).round().astype(int))
    return [sequence[int(i)].image for i in positions]  # type: ignore[index]


def synthetic_training_images(seed: int = 0, frames: int = 40, progress: Progress | None = None) -> list[np.ndarray]:
    """``frames`` views of each synthetic scene (urban over 20 s, indoor over 13 s) of world
    ``seed + 100``: a world the tests (seed 0) do not drive through."""
    from sal_adapters import open_dataset

    images: list[np.ndarray] = []
    for scene, length in (("urban", 200), ("indoor", 400)):
        if progress:
            progress(f"rendering {frames} {scene} views (world seed {seed + 100})")
        sequence = open_dataset("synthetic", scene=scene, frames=max(length, frames), seed=seed + 100)
        images += sequence_images(sequence, frames)
    return images


def ensure_vocabulary(
    seed: int = 0,
    cache_dir: str | os.PathLike[str] | None = None,
    progress: Progress | None = None,
    *,
    k: int = 10,
    levels: int = 6,
    frames: int = 40,
) -> Path:
    """A vocabulary file for ORB-SLAM3, built at most once.

    Order: ``$SAL_ORB_VOCABULARY`` (must exist); ``ORBvoc.txt`` in the cache folder (the
    official one, when the user put it there); the cached build
    ``sal-orbvoc-b<BUILDER_VERSION>-k<k>-L<levels>-s<seed>-f<frames>.txt``; else build it from
    ``frames`` synthetic views per scene. Concurrent callers (xdist workers) serialise on an
    exclusive lock file beside it, so one builds and the others reuse its file.
    """
    configured = os.environ.get(ENV_VARIABLE)
    if configured:
        path = Path(configured).expanduser()
        if not path.is_file():
            raise VocabularyError(f"{ENV_VARIABLE} names a file that does not exist", path)
        return path
    folder = Path(cache_dir) if cache_dir is not None else user_cache_dir("vocabulary")
    if (folder / "ORBvoc.txt").is_file():
        return folder / "ORBvoc.txt"
    target = folder / f"sal-orbvoc-b{BUILDER_VERSION}-k{k}-L{levels}-s{seed}-f{frames}.txt"
    if target.is_file():
        return target
    folder.mkdir(parents=True, exist_ok=True)
    with FileLock(folder / f".{target.name}.lock"):
        if not target.is_file():  # another process may have built it while we waited
            started = time.perf_counter()
            images = orb_image_descriptors(synthetic_training_images(seed, frames, progress))
            if progress:
                progress(f"training k={k} L={levels} on {sum(map(len, images))} ORB descriptors")
            vocabulary = build_vocabulary(np.concatenate(images), k, levels, seed, images)
            vocabulary.write_text(target)
            if progress:
                progress(f"vocabulary {target} ({vocabulary.n_words} words, {time.perf_counter() - started:.1f} s)")
    return target
