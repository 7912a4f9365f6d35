"""``cracked_lens``: an impact cracks the lens glass; stress propagation over random points.

Mathematical formulation (after the StressPropagator of "Fractured Glass, Failing Cameras",
arXiv 2405.15033)
----------------------------------------------------------------------------------------
The glass is sampled by ``points`` random support points. An impact of force F (N) hits the
point nearest to (impact_x W, impact_y H) along the direction g0 (``impact_angle_deg``).

* Initiation: every point n within ``neighbour_radius_px`` R of the impact cracks towards it
  (a radial star, drawn for any F > 0) and starts a crack front with the stress
  s_n = |F cos angle(g_n, g0)|, g_n the unit vector from the impact to n.
* Propagation: a front at point p with stress s, moving along g, loads every point j within R
  with s_j = s cos theta_j (theta_j the angle between g and p -> j); it advances to the most
  loaded one while s_j > ``break_threshold_n`` T, and continues from there along p -> j. The
  stress decays multiplicatively by cos theta per step. A front that reaches a cracked point
  joins that crack and stops (crack arrest).
* Secondary cracks: the minimum spanning tree of the cracked points (on a sparse k-nearest-
  neighbour graph) joins neighbouring cracks; a tree edge breaks when both its points did.

Every crack edge e carries a stress factor k_e = s_e / F, so it breaks when F k_e > T. Fronts
advance in order of decreasing stress (the strongest front first, not depth first), which makes
every arrest decision depend only on edges of larger k: the network at force F is exactly the
network at a larger force with the edges of k_e <= T / F removed. Hence the path choice does not
depend on F, only its length, and the cracks at a lower force are a subset of those at a higher
force. The network is grown once per lens down to k = T / F_max.

Rendering: crack lines ``crack_width_px`` wide (anti-aliased) in a grey that depends on the
light direction: a fracture face along the crack glints with |sin angle(crack, light)|,
grey = 60 + 160 |sin|. The scene seen through the shattered zone is blurred with a Gaussian of
sigma ``blur_px`` within about 3 sigma of the cracks. Both maps are built once per lens in
``setup``; a frame costs one blur and two blends.
"""

from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import minimum_spanning_tree
from scipy.spatial import cKDTree

from sal_modules.optics.lens import LensEffect, Overlay
from sal_modules.params import Param

__all__ = ["CrackNetwork", "CrackedLens", "grow_cracks"]

#: Largest impact force (N): the network is grown down to the stress factor T / MAX_FORCE_N.
MAX_FORCE_N = 5000.0

#: Neighbours per point of the sparse graph the secondary-crack spanning tree is built on.
TREE_NEIGHBOURS = 8

#: Crack grey levels: a crack along the light direction, and one across it (brightest glint).
CRACK_GREY = (60.0, 220.0)

#: Sub-pixel bits of the crack line end points given to OpenCV.
SHIFT = 4


@dataclass(frozen=True)
class CrackNetwork:
    """Every crack a lens can get, with the stress factor at which each edge breaks.

    Attributes:
        points: (N, 2) float support points (x, y) in px.
        edges: (E, 2) int point indices of crack edges (primary, then secondary).
        factor: (E,) stress factor k_e; the edge breaks when F k_e > T (inf: the impact star).
        primary: (E,) bool, True for propagation edges, False for spanning-tree edges.
    """

    points: np.ndarray
    edges: np.ndarray
    factor: np.ndarray
    primary: np.ndarray

    def active(self, force_n: float, threshold_n: float) -> np.ndarray:
        """Mask of the edges broken by an impact of ``force_n`` for glass of ``threshold_n``."""
        if force_n <= 0:
            return np.zeros(len(self.edges), bool)
        return self.factor > threshold_n / force_n


def grow_cracks(points: np.ndarray, impact: int, direction: np.ndarray, radius: float, min_factor: float) -> CrackNetwork:
    """Stress propagation from point ``impact`` along unit vector ``direction``.

    Args:
        points: (N, 2) support points (x, y) in px.
        impact: index of the impact point.
        direction: unit impact direction (x, y).
        radius: neighbour radius R (px).
        min_factor: grow edges while their stress factor exceeds this (T / F_max).
    """
    tree = cKDTree(points)
    claimed = np.full(len(points), -1.0)  # stress factor at which a point cracked; -1 = intact
    edges: list[tuple[int, int]] = []
    factors: list[float] = []
    fronts: list[tuple[float, int, int, int, float, float]] = []  # (-k, order, from, to, gx, gy)
    order = itertools.count()

    def advance(p: int, k: float, g: np.ndarray) -> None:
        """Queue the step of the front at ``p`` (factor ``k``, heading ``g``) to its most loaded neighbour."""
        near = np.asarray(tree.query_ball_point(points[p], radius), dtype=np.intp)
        near = near[near != p]
        if near.size == 0:
            return
        step = points[near] - points[p]
        length = np.maximum(np.hypot(step[:, 0], step[:, 1]), 1e-12)
        cos = (step @ g) / length
        best = int(np.argmax(cos))
        if k * cos[best] > min_factor:
            heading = step[best] / length[best]
            heapq.heappush(fronts, (-k * cos[best], next(order), p, int(near[best]), heading[0], heading[1]))

    # initiation: the radial star around the impact, every front with |F cos angle to g0|
    claimed[impact] = np.inf
    star = np.asarray(tree.query_ball_point(points[impact], radius), dtype=np.intp)
    star = star[star != impact]
    for n in star:
        edges.append((impact, int(n)))
        factors.append(np.inf)
        claimed[n] = np.inf
    for n in star:
        g = points[n] - points[impact]
        g = g / max(float(np.hypot(*g)), 1e-12)
        advance(int(n), abs(float(g @ direction)), g)
    # propagation: the most stressed front first
    while fronts:
        negative_k, _, p, j, gx, gy = heapq.heappop(fronts)
        k = -negative_k
        edges.append((p, j))
        factors.append(k)
        if claimed[j] >= 0:
            continue  # reached a crack: arrest
        claimed[j] = k
        advance(j, k, np.array([gx, gy]))
    primary = np.asarray(edges, dtype=np.intp).reshape(-1, 2)
    secondary, secondary_factor = _spanning_tree(points, claimed)
    return CrackNetwork(
        points=points,
        edges=np.concatenate([primary, secondary]),
        factor=np.concatenate([np.asarray(factors, float), secondary_factor]),
        primary=np.concatenate([np.ones(len(primary), bool), np.zeros(len(secondary), bool)]),
    )


def _spanning_tree(points: np.ndarray, claimed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Minimum spanning tree edges of the cracked points (k-NN graph) and their stress factors."""
    nodes = np.flatnonzero(claimed >= 0)
    if nodes.size < 2:
        return np.empty((0, 2), np.intp), np.empty(0)
    k = min(TREE_NEIGHBOURS, nodes.size - 1)
    dist, nearest = cKDTree(points[nodes]).query(points[nodes], k=k + 1)
    rows = np.repeat(np.arange(nodes.size), k)
    graph = csr_matrix((dist[:, 1:].ravel() + 1e-9, (rows, nearest[:, 1:].ravel())), shape=(nodes.size, nodes.size))
    tree = minimum_spanning_tree(graph).tocoo()
    pairs = np.stack([nodes[tree.row], nodes[tree.col]], axis=1).astype(np.intp)
    return pairs, np.minimum(claimed[pairs[:, 0]], claimed[pairs[:, 1]])


class CrackedLens(LensEffect):
    """A cracked lens: stress-propagation cracks, nested across impact forces, one per lens."""

    name = "cracked_lens"
    version = 1
    summary = "Cracked lens glass from an impact: stress propagation, spanning-tree secondary cracks, blur"

    impact_force_n = Param(
        500.0,
        unit="N",
        min=0.0,
        max=MAX_FORCE_N,
        searchable=True,
        worse="higher",
        doc="impact force; crack edges break where the propagated stress exceeds break_threshold_n",
    )
    break_threshold_n = Param(300.0, unit="N", min=1.0, max=MAX_FORCE_N, doc="stress at which the glass breaks")
    impact_x = Param(0.5, min=0.0, max=1.0, doc="impact point, fraction of the image width")
    impact_y = Param(0.5, min=0.0, max=1.0, doc="impact point, fraction of the image height")
    impact_angle_deg = Param(35.0, unit="deg", min=-180.0, max=180.0, doc="impact direction in the image (x right, y down)")
    points = Param(10_000, domain="integer", unit="points", min=100, max=100_000, doc="random support points sampling the glass")
    neighbour_radius_px = Param(65.0, unit="px", min=2.0, max=500.0, doc="radius within which stress passes between points")
    crack_width_px = Param(1, domain="integer", unit="px", min=1, max=10, doc="width of the crack lines")
    blur_px = Param(2.5, unit="px", min=0.0, max=20.0, doc="Gaussian sigma of the blur seen through the glass near cracks (0 = none)")
    light_angle_deg = Param(90.0, unit="deg", min=-180.0, max=180.0, doc="light direction that makes the crack faces glint")

    def network(self, stream: str, height: int, width: int) -> CrackNetwork:
        """The full crack network of lens ``stream`` (all forces up to ``MAX_FORCE_N``)."""
        uniform = self.rng("pattern", stream).random((self.points, 2))
        points = uniform * (width, height)
        target = np.array([self.impact_x * width, self.impact_y * height])
        impact = int(np.argmin(np.sum((points - target) ** 2, axis=1)))
        angle = np.radians(self.impact_angle_deg)
        direction = np.array([np.cos(angle), np.sin(angle)])
        return grow_cracks(points, impact, direction, self.neighbour_radius_px, self.break_threshold_n / MAX_FORCE_N)

    def build(self, stream: str, height: int, width: int) -> tuple[Overlay, Overlay | None] | None:
        """Crack overlay and blur zone (an overlay of the blurred frame) of lens ``stream``;
        ``None`` when the glass is intact."""
        net = self.network(stream, height, width)
        edges = net.edges[net.active(self.impact_force_n, self.break_threshold_n)]
        if edges.size == 0:
            return None
        ends = np.round(net.points[edges] * (1 << SHIFT)).astype(np.int32)  # (E, 2, 2)
        coverage = np.zeros((height, width), np.uint8)
        cv2.polylines(coverage, list(ends), False, 255, self.crack_width_px, cv2.LINE_AA, SHIFT)
        colour = np.zeros((height, width), np.uint8)
        light = np.radians(self.light_angle_deg)
        step = ends[:, 1] - ends[:, 0]
        sin = np.abs(step[:, 0] * np.sin(light) - step[:, 1] * np.cos(light)) / np.maximum(np.hypot(step[:, 0], step[:, 1]), 1)
        grey = np.round(CRACK_GREY[0] + (CRACK_GREY[1] - CRACK_GREY[0]) * sin).astype(int)
        for level in np.unique(grey):  # brighter glints drawn last, on top
            cv2.polylines(colour, list(ends[grey == level]), False, int(level), self.crack_width_px + 2, cv2.LINE_8, SHIFT)
        overlay = Overlay(coverage.astype(np.float32) / 255.0, cv2.cvtColor(colour, cv2.COLOR_GRAY2RGB))
        if self.blur_px == 0:
            return overlay, None
        reach = int(np.ceil(3 * self.blur_px))
        zone = cv2.dilate((coverage > 0).astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach + 1,) * 2))
        weight = cv2.GaussianBlur(zone.astype(np.float32), (0, 0), self.blur_px)
        return overlay, Overlay(np.maximum(weight, coverage > 0).astype(np.float32))

    def apply(self, image: np.ndarray, depth: np.ndarray | None, index: int, stream: str) -> np.ndarray:
        pattern = self.pattern(stream, image)
        if pattern is None:
            return image.copy()
        cracks, blur_zone = pattern
        if blur_zone is not None:
            image = blur_zone.over(image, cv2.GaussianBlur(image, (0, 0), self.blur_px))
        return cracks.over(image)
