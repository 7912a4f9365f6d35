"""ORB bag-of-words vocabularies in the DBoW2 text format that ORB-SLAM3 loads.

>>> from sal_wrappers.vocabulary import ensure_vocabulary
>>> path = ensure_vocabulary()          # doctest: +SKIP   (built once, ~20 s, then cached)

The tree is trained like DBoW2 (hierarchical k-majority): at every node the descriptors are
split into ``k`` clusters by Lloyd iterations under the Hamming distance
``d(a, b) = popcount(a XOR b)``, seeded with k-means++ (``P(x) ~ D(x)^2``); a centre is the
bitwise majority of its members (bit ``j`` set when ``2 * count_j >= n``, DBoW2
``FORB::meanValue``). A node holding at most ``k`` distinct descriptors gets one leaf per
descriptor. Nodes are numbered breadth first (parent before child), leaves are the words.
Leaf weights are the IDF ``w = ln(N / N_w)`` of the ``N`` training images, ``N_w`` of which
contain word ``w`` after re-quantising their descriptors (0 when ``N_w = 0``, as DBoW2);
inner nodes weigh 0. Every leaf lies at depth ``>= levels - 4``: ORB-SLAM3 reads its
FeatureVector node four levels above the leaves and leaves it undefined above that depth.
"""

from __future__ import annotations

import os
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sal_adapters.cache_dir import user_cache_dir
from sal_adapters.compat import popcount
from sal_adapters.errors import DatasetError
from sal_adapters.file_lock import FileLock
from sal_adapters.textfiles import atomic_write_text

__all__ = [
    "BUILDER_VERSION",
    "ENV_VARIABLE",
    "Vocabulary",
    "VocabularyError",
    "build_vocabulary",
    "check_tree_shape",
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
#: ORB-SLAM3 takes its FeatureVector node this many levels above the leaves.
FEATURE_LEVELS_UP = 4
DESCRIPTOR_BYTES = 32

Progress = Callable[[str], None]


class VocabularyError(DatasetError):
    """A vocabulary file or build option is wrong (the message names the file and line)."""


def orb_image_descriptors(images: Iterable[np.ndarray], features: int = 1000) -> list[np.ndarray]:
    """ORB descriptors (``Mi x 32`` uint8) of every image, OpenCV defaults but ``nfeatures``.

    Colour images are taken as RGB and converted to grey.
    """
    import cv2

    orb = cv2.ORB_create(nfeatures=features)
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


def _words(descriptors: np.ndarray) -> np.ndarray:
    """``N x 32`` uint8 -> ``N x 4`` uint64 (for XOR + popcount)."""
    return np.ascontiguousarray(descriptors, dtype=np.uint8).view(np.uint64)


def _hamming(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pairwise Hamming distances of ``n x 4`` and ``m x 4`` uint64 rows: ``n x m`` int."""
    return popcount(a[:, None, :] ^ b[None, :, :]).sum(axis=2, dtype=np.int32)


@dataclass(eq=False)
class Vocabulary:
    """A DBoW2 vocabulary tree; node 0 is the root (parent -1), leaves are the words.

    ``parents``, ``leaf``, ``descriptors`` (``n x 32`` uint8) and ``weights`` have one row
    per node, in breadth-first order. Word ids count the leaves in node order, as ORB-SLAM3.
    """

    k: int
    levels: int
    parents: np.ndarray
    leaf: np.ndarray
    descriptors: np.ndarray
    weights: np.ndarray
    scoring: int = 0  # L1 norm
    weighting: int = 0  # TF-IDF

    @property
    def n_nodes(self) -> int:
        """Nodes written to the file (all but the root)."""
        return len(self.parents) - 1

    @property
    def n_words(self) -> int:
        """Leaves (words)."""
        return int(np.count_nonzero(self.leaf))

    def word_nodes(self) -> np.ndarray:
        """Node id of every word id."""
        return np.flatnonzero(self.leaf)

    def depths(self) -> np.ndarray:
        """Depth of every node (root 0); valid because parents come first."""
        depth = np.zeros(len(self.parents), np.int64)
        while True:  # one round per tree level
            updated = np.concatenate([[0], depth[self.parents[1:]] + 1])
            if np.array_equal(updated, depth):
                return depth
            depth = updated

    def children_table(self) -> np.ndarray:
        """``nodes x k`` child ids in file order, -1 padded (at most ``k`` children each)."""
        parents = self.parents[1:]
        width = max(self.k, int(np.bincount(parents).max()) if len(parents) else 0)
        table = np.full((len(self.parents), width), -1, np.int64)
        order = np.argsort(parents, kind="stable")  # children keep their file order
        grouped = parents[order]
        rank = np.arange(len(grouped)) - np.searchsorted(grouped, grouped, side="left")
        table[grouped, rank] = order + 1
        return table

    def transform(self, descriptors: np.ndarray, chunk: int = 32768) -> np.ndarray:
        """Word id of every descriptor: descend from the root to the nearest child at each
        level (the first one on ties), like DBoW2 ``transform``."""
        return np.searchsorted(self.word_nodes(), self.leaf_nodes(descriptors, chunk))

    def leaf_nodes(self, descriptors: np.ndarray, chunk: int = 32768) -> np.ndarray:
        """Leaf node id of every descriptor (see ``transform``)."""
        table = self.children_table()
        nodes = _words(self.descriptors)
        query = _words(_checked(descriptors))
        result = np.zeros(len(query), np.int64)
        for start in range(0, len(query), chunk):
            part = query[start : start + chunk]
            current = np.zeros(len(part), np.int64)
            active = np.flatnonzero(~self.leaf[current])
            while active.size:
                children = table[current[active]]
                dist = popcount(part[active, None, :] ^ nodes[children]).sum(axis=2, dtype=np.int32)
                dist[children < 0] = np.iinfo(np.int32).max
                current[active] = children[np.arange(active.size), dist.argmin(axis=1)]
                active = active[~self.leaf[current[active]]]
            result[start : start + chunk] = current
        return result

    def to_text(self) -> str:
        """The ORB-SLAM text format: ``k L scoring weighting`` then per non-root node
        ``parent is_leaf d0 .. d31 weight``; no trailing newline."""
        lines = [f"{self.k} {self.levels} {self.scoring} {self.weighting}"]
        bytes_text = [" ".join(map(str, row)) for row in self.descriptors[1:].tolist()]
        for parent, is_leaf, desc, weight in zip(self.parents[1:].tolist(), self.leaf[1:].tolist(), bytes_text, self.weights[1:].tolist()):
            lines.append(f"{parent} {int(is_leaf)} {desc} {weight:.6g}")
        return "\n".join(lines)

    def write_text(self, path: str | os.PathLike[str]) -> Path:
        """Write ``to_text()`` atomically (temporary file + ``os.replace``), mode 0644;
        returns the path."""
        path = Path(path)
        atomic_write_text(path, self.to_text())
        path.chmod(0o644)  # the temporary file was private (0600)
        return path

    @classmethod
    def read_text(cls, path: str | os.PathLike[str]) -> Vocabulary:
        """Parse an ORB-SLAM text vocabulary (``VocabularyError`` naming file:line when bad)."""
        path = Path(path)
        try:
            text = path.read_text(encoding="ascii")
        except FileNotFoundError:
            raise VocabularyError("vocabulary file not found", path) from None
        except (OSError, UnicodeDecodeError) as exc:
            raise VocabularyError(f"cannot read vocabulary ({exc})", path) from None
        head, _, body = text.partition("\n")
        try:
            k, levels, scoring, weighting = (int(f) for f in head.split())
        except ValueError:
            raise VocabularyError(f"expected 'k L scoring weighting', got {head[:60]!r}", path, 1) from None
        if not (2 <= k <= 20 and 1 <= levels <= 10 and 0 <= scoring <= 5 and 0 <= weighting <= 3):
            raise VocabularyError(f"header out of range (k 2..20, L 1..10, scoring 0..5, weighting 0..3): {head!r}", path, 1)
        rows = body.rstrip("\n").split("\n") if body.strip() else []
        width = 3 + DESCRIPTOR_BYTES
        try:
            values = np.array(" ".join(rows).split(), dtype=np.float64)
        except ValueError:
            bad = next(i for i, row in enumerate(rows) if not _numbers(row))
            raise VocabularyError(f"expected numbers, got {rows[bad][:60]!r}", path, bad + 2) from None
        if values.size != width * len(rows):
            bad = next(i for i, row in enumerate(rows) if len(row.split()) != width)
            raise VocabularyError(f"expected {width} fields per node, got {len(rows[bad].split())}", path, bad + 2)
        table = values.reshape(len(rows), width)
        parents = np.concatenate([[-1], table[:, 0]]).astype(np.int64)
        leaf = np.concatenate([[False], table[:, 1] > 0])
        descriptors = np.vstack([np.zeros((1, DESCRIPTOR_BYTES)), table[:, 2:-1]])
        weights = np.concatenate([[0.0], table[:, -1]])
        ids = np.arange(len(parents))
        wrong = np.flatnonzero((parents[1:] < 0) | (parents[1:] >= ids[1:]) | leaf[np.clip(parents[1:], 0, None)])
        if wrong.size:
            raise VocabularyError(
                f"parent {parents[wrong[0] + 1]} is not an inner node listed before node {wrong[0] + 1}", path, wrong[0] + 2
            )
        if np.any((descriptors < 0) | (descriptors > 255)):
            raise VocabularyError("descriptor bytes must be 0..255", path)
        childless = np.setdiff1d(np.flatnonzero(~leaf[1:]) + 1, parents[1:])
        if childless.size:
            raise VocabularyError(f"inner node {childless[0]} has no children", path, int(childless[0]) + 1)
        return cls(k, levels, parents, leaf, descriptors.astype(np.uint8), weights, scoring, weighting)


def _numbers(row: str) -> bool:
    try:
        np.array(row.split(), dtype=np.float64)
    except ValueError:
        return False
    return True


def _checked(descriptors: np.ndarray) -> np.ndarray:
    """``descriptors`` as a contiguous ``N x 32`` uint8 array, else ``VocabularyError``."""
    descriptors = np.ascontiguousarray(descriptors)
    if descriptors.ndim != 2 or descriptors.shape[1] != DESCRIPTOR_BYTES or descriptors.dtype != np.uint8:
        raise VocabularyError(f"expected N x 32 uint8 ORB descriptors, got {descriptors.dtype} {descriptors.shape}")
    return descriptors


def check_tree_shape(k: int, levels: int) -> None:
    """``VocabularyError`` unless ``2 <= k <= 20`` and ``1 <= levels <= 10`` (ORB-SLAM3's limits)."""
    if not (2 <= k <= 20 and 1 <= levels <= 10):
        raise VocabularyError(f"k must be 2..20 and levels 1..10 (ORB-SLAM3 limits), got k={k} levels={levels}")


def build_vocabulary(
    descriptors: np.ndarray,
    k: int = 10,
    levels: int = 6,
    seed: int = 0,
    images: list[np.ndarray] | None = None,
    *,
    max_iterations: int = 100,
) -> Vocabulary:
    """Train a vocabulary tree (see the module docstring) on ``N x 32`` uint8 descriptors.

    Args:
        descriptors: the training descriptors.
        k: branching factor (2..20); levels: depth ``L`` of the tree (1..10, ORB-SLAM3 wants 6).
        seed: seeds k-means++; the same inputs and seed give the same tree.
        images: the per-image descriptor arrays whose documents give the IDF weights;
            default: consecutive blocks of 1000 rows of ``descriptors`` (``orb_descriptors``).
        max_iterations: Lloyd iterations at most per node (DBoW2 iterates to convergence).
    """
    descriptors = _checked(descriptors)
    if len(descriptors) == 0:
        raise VocabularyError("expected N x 32 uint8 ORB descriptors with N >= 1, got none")
    check_tree_shape(k, levels)
    rng = np.random.default_rng(seed)
    words = _words(descriptors)
    bits = np.unpackbits(descriptors, axis=1)
    min_depth = max(1, levels - FEATURE_LEVELS_UP)
    parents, leaf, centres = [-1], [False], [np.zeros(DESCRIPTOR_BYTES, np.uint8)]
    queue: deque[tuple[int, np.ndarray, int]] = deque([(0, np.arange(len(descriptors)), 0)])
    while queue:
        node, members, depth = queue.popleft()
        groups, group_centres = _split(words, bits, members, k, rng, max_iterations)
        if len(groups) == 1 and depth >= min_depth:  # all members alike: a leaf
            leaf[node] = True
            continue
        for group, centre in zip(groups, group_centres):
            child = len(parents)
            parents.append(node)
            centres.append(centre)
            alike = len(group) == 1 or not np.any(words[group] != words[group[0]])
            is_leaf = depth + 1 == levels or (alike and depth + 1 >= min_depth)
            leaf.append(is_leaf)
            if not is_leaf:
                queue.append((child, group, depth + 1))
    vocabulary = Vocabulary(k, levels, np.array(parents, np.int64), np.array(leaf), np.array(centres, np.uint8), np.zeros(len(parents)))
    if images is None:
        images = [descriptors[i : i + 1000] for i in range(0, len(descriptors), 1000)]
    vocabulary.weights = _idf_weights(vocabulary, images)
    return vocabulary


def _split(
    words: np.ndarray, bits: np.ndarray, members: np.ndarray, k: int, rng: np.random.Generator, max_iterations: int
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Member groups and their centres (32 uint8) of one node: one per distinct descriptor
    when there are at most ``k``, else k-majority clusters (empty ones dropped)."""
    points = words[members]
    if len(members) <= k:
        _, first, inverse = np.unique(points.view(np.dtype((np.void, DESCRIPTOR_BYTES))).ravel(), return_index=True, return_inverse=True)
        order = np.argsort(first)  # distinct descriptors in order of appearance
        groups = [members[inverse == j] for j in order]
        return groups, [points[first[j]].view(np.uint8) for j in order]
    # k-means++ seeding: next centre drawn with P(x) ~ D(x)^2
    chosen = [int(rng.integers(len(points)))]
    nearest = _hamming(points, points[chosen[0]][None]).ravel().astype(np.float64)
    while len(chosen) < k:
        weight = np.cumsum(nearest**2)
        if weight[-1] == 0:  # fewer than k distinct descriptors
            break
        pick = min(int(np.searchsorted(weight, rng.random() * weight[-1], side="right")), len(points) - 1)
        chosen.append(pick)
        nearest = np.minimum(nearest, _hamming(points, points[pick][None]).ravel())
    centres = points[chosen]
    assign = _hamming(points, centres).argmin(axis=1)
    node_bits = bits[members]
    for _ in range(max_iterations):
        centres = _majority(node_bits, assign, centres)
        updated = _hamming(points, centres).argmin(axis=1)
        if np.array_equal(updated, assign):
            break
        assign = updated
    groups, group_centres = [], []
    for c in range(len(centres)):
        group = members[assign == c]
        if group.size:
            groups.append(group)
            group_centres.append(centres[c].view(np.uint8))
    return groups, group_centres


def _majority(bits: np.ndarray, assign: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Bitwise majority of every cluster (bit set when ``2 * ones >= members``, DBoW2
    ``FORB::meanValue``); an empty cluster keeps its centre."""
    result = centres.copy()
    for c in range(len(centres)):
        members = bits[assign == c]
        if len(members):
            result[c] = _words(np.packbits(2 * members.sum(axis=0, dtype=np.int32) >= len(members))[None])[0]
    return result


def _idf_weights(vocabulary: Vocabulary, images: list[np.ndarray]) -> np.ndarray:
    """``ln(N / N_w)`` per leaf from the ``N`` images' re-quantised descriptors, else 0."""
    weights = np.zeros(len(vocabulary.parents))
    images = [d for d in images if len(d)]
    if not images:
        return weights
    leaves = vocabulary.leaf_nodes(np.concatenate(images))
    image_of = np.repeat(np.arange(len(images)), [len(d) for d in images])
    pairs = np.unique(image_of * len(vocabulary.parents) + leaves)
    containing = np.bincount(pairs % len(vocabulary.parents), minlength=len(vocabulary.parents))
    seen = containing > 0
    weights[seen] = np.log(len(images) / containing[seen])
    return weights


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
