"""Training an ORB vocabulary tree like DBoW2: ``build_vocabulary``.

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

from collections import deque

import numpy as np

from sal_adapters.common.compat import popcount
from sal_wrappers.orbslam3.vocabulary_tree import DESCRIPTOR_BYTES, Vocabulary, VocabularyError, checked_descriptors, descriptor_words

__all__ = ["FEATURE_LEVELS_UP", "build_vocabulary", "check_tree_shape"]

#: ORB-SLAM3 takes its FeatureVector node this many levels above the leaves.
FEATURE_LEVELS_UP = 4


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
    descriptors = checked_descriptors(descriptors)
    if len(descriptors) == 0:
        raise VocabularyError("expected N x 32 uint8 ORB descriptors with N >= 1, got none")
    check_tree_shape(k, levels)
    rng = np.random.default_rng(seed)
    words = descriptor_words(descriptors)
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
            result[c] = descriptor_words(np.packbits(2 * members.sum(axis=0, dtype=np.int32) >= len(members))[None])[0]
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


def _hamming(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pairwise Hamming distances of ``n x 4`` and ``m x 4`` uint64 rows: ``n x m`` int."""
    return popcount(a[:, None, :] ^ b[None, :, :]).sum(axis=2, dtype=np.int32)
