"""The DBoW2 vocabulary tree ORB-SLAM3 loads: ``Vocabulary``, its text format, and word lookup.

The text format: a header ``k L scoring weighting``, then one line per node but the root,
``parent is_leaf d0 .. d31 weight``, nodes in breadth-first order (parents first); the
leaves are the words, numbered in node order.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sal_adapters.common.compat import popcount
from sal_adapters.common.errors import DatasetError
from sal_adapters.common.textfiles import atomic_write_text

__all__ = ["DESCRIPTOR_BYTES", "Vocabulary", "VocabularyError", "checked_descriptors", "descriptor_words"]

#: Bytes of one ORB descriptor (256 bits).
DESCRIPTOR_BYTES = 32


class VocabularyError(DatasetError):
    """A vocabulary file or build option is wrong (the message names the file and line)."""


def descriptor_words(descriptors: np.ndarray) -> np.ndarray:
    """``N x 32`` uint8 -> ``N x 4`` uint64 (for XOR + popcount)."""
    return np.ascontiguousarray(descriptors, dtype=np.uint8).view(np.uint64)


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
        nodes = descriptor_words(self.descriptors)
        query = descriptor_words(checked_descriptors(descriptors))
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


def checked_descriptors(descriptors: np.ndarray) -> np.ndarray:
    """``descriptors`` as a contiguous ``N x 32`` uint8 array, else ``VocabularyError``."""
    descriptors = np.ascontiguousarray(descriptors)
    if descriptors.ndim != 2 or descriptors.shape[1] != DESCRIPTOR_BYTES or descriptors.dtype != np.uint8:
        raise VocabularyError(f"expected N x 32 uint8 ORB descriptors, got {descriptors.dtype} {descriptors.shape}")
    return descriptors
