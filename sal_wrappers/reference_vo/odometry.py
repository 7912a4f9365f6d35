"""The per-frame state machine of ``reference_vo``: local map, tracking, keyframes, restarts.

The local map holds 3-D world points with an ORB descriptor (the last one observed) and the
frame they were last an inlier in. ``orb`` tracking projects the map points with the pose the
constant-velocity model predicts, matches them to the frame's keypoints nearby (all keypoints
when that finds too few), solves PnP with RANSAC and refines on a second, narrower projection
search. ``klt`` tracking follows the map points from frame to frame by optical flow instead.
A keyframe is made when the inliers drop below ``KEYFRAME_FRACTION`` of those of the first
frame after the previous keyframe: it adds the keypoints no map point explains, with depth
(RGB-D), stereo depth (stereo) or, for mono, triangulated against the two previous keyframes
(keypoints that cannot be triangulated yet wait as candidates) and followed by a local bundle
adjustment (``bundle``) of the last ``WINDOW`` keyframes, the oldest ``FIXED`` of them held
fixed, which keeps the monocular scale from drifting. Map points not an inlier for
``MAX_UNSEEN`` frames are dropped.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from sal_wrappers.base import TrackState
from sal_wrappers.reference_vo import geometry as geo
from sal_wrappers.reference_vo.bundle import bundle_adjust
from sal_wrappers.reference_vo.features import Features, brute_match, detect, guided_match
from sal_wrappers.reference_vo.lens import Lens

__all__ = ["Odometry"]

KEYFRAME_FRACTION = 0.7  #: a keyframe when the inliers fall below this share of the first after the last one
THRESHOLD_PX = 2.5  #: reprojection threshold of PnP and triangulation (px)
MAX_UNSEEN = 30  #: frames a map point survives without being an inlier
INIT_FLOW = 0.03  #: mono start: median flow needed (fraction of the image width)
INIT_ANGLE_DEG = 1.0  #: mono start: smallest parallax of a triangulated point
INIT_SHARE = 0.3  #: mono start: share of the matches that must triangulate
TRIANGULATE_ANGLE_DEG = 0.5  #: mono keyframes: smallest parallax of a new point
INIT_WINDOW = 30  #: mono start: frames a reference frame is kept before a newer one replaces it
CANDIDATE_KEYFRAMES = 2  #: mono: keyframes whose untriangulated keypoints are matched again
WINDOW = 6  #: mono: keyframes in the local bundle adjustment
FIXED = 2  #: mono: the oldest keyframes of the window, which stay fixed (fewer while the map is young)

Update = tuple[int, TrackState, int, "np.ndarray | None"]  # position, state, inliers, T_wc


class Odometry:
    """Visual odometry over one sequence; ``step`` takes the frames in order."""

    def __init__(self, lens: Lens, mode: str, size: tuple[int, int], *, features: int, min_inliers: int, tracker: str, max_lost: int):
        self.lens, self.mode, self.tracker = lens, mode, tracker
        self.features, self.min_inliers, self.max_lost = features, min_inliers, max_lost
        self.width, self.height = size
        self.orb = cv2.ORB.create(features, 1.2, 8, 19, 0, 2, cv2.ORB_HARRIS_SCORE, 31, 20)
        self.radius = max(10.0, 0.03 * self.width)
        self.segments = self.keyframes = self.frame = 0
        self._reset()

    def _reset(self) -> None:
        self.X = np.zeros((0, 3))
        self.desc = np.zeros((0, 32), np.uint8)
        self.last = np.zeros(0, np.int64)
        self.track = np.zeros((0, 2), np.float32)  # KLT: map points in the last tracked frame
        self.pid = np.zeros(0, np.int64)  # stable ids of the map points (ascending)
        self.next_pid = 0
        self.candidates: list[dict[str, Any]] = []  # mono: untriangulated keypoints per keyframe
        self.kf_poses: dict[int, np.ndarray] = {}  # mono: keyframe number -> T_cw
        self.obs = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2)))  # mono: keyframe, point id, ideal px
        self.started = False
        self.lost, self.reference = 0, 0
        self.T_cw, self.t_last, self.velocity = np.eye(4), 0.0, np.zeros(6)
        self.prev_grey: np.ndarray | None = None
        self.init: dict[str, Any] | None = None

    # -- per frame --------------------------------------------------------------------------
    def step(self, pos: int, t: float, image: np.ndarray, right: np.ndarray | None, depth: np.ndarray | None) -> list[Update]:
        self.frame += 1
        grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
        right_grey = None if right is None else cv2.cvtColor(right, cv2.COLOR_RGB2GRAY)
        if self.lens.maps is not None:
            grey = cv2.remap(grey, *self.lens.maps[0], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
            if right_grey is not None:
                right_grey = cv2.remap(right_grey, *self.lens.maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        if not self.started:
            if self.mode == "mono":
                return self._start_mono(pos, t, grey)
            return self._start(pos, t, grey, right_grey, depth)
        tracked = self._track(t, grey)
        if tracked is None:
            self.lost += 1
            if self.lost >= self.max_lost:
                self._reset()
            return [(pos, TrackState.LOST, 0, None)]
        T_cw, inliers, current, ids, cols = tracked
        self._moved(T_cw, t, grey)
        if not self.reference:
            self.reference = inliers
        if inliers < KEYFRAME_FRACTION * self.reference:
            T_cw = self._keyframe(T_cw, current, ids, cols, grey, right_grey, depth)
            self.reference = 0
        self._cull()
        return [(pos, TrackState.OK, inliers, geo.invert(T_cw))]

    def _moved(self, T_cw: np.ndarray, t: float, grey: np.ndarray) -> None:
        dt = t - self.t_last
        if dt > 0 and self.lost == 0:
            rel = T_cw @ geo.invert(self.T_cw)
            self.velocity = np.concatenate([cv2.Rodrigues(rel[:3, :3])[0].ravel(), rel[:3, 3]]) / dt
        elif dt > 0:
            self.velocity = np.zeros(6)
        self.T_cw, self.t_last, self.lost, self.prev_grey = T_cw, t, 0, grey

    def _predicted(self, t: float) -> np.ndarray:
        step = self.velocity * max(t - self.t_last, 0.0)
        return geo.matrix(step[:3], step[3:]) @ self.T_cw

    # -- tracking ---------------------------------------------------------------------------
    def _track(self, t: float, grey: np.ndarray) -> tuple | None:
        """(T_cw, inliers, current features, map rows, current rows) or None when lost."""
        K = self.lens.K
        if self.tracker == "klt":
            ids, xy = self._flow(grey, np.flatnonzero(self.last >= 0), t)
            current = Features(xy, self.lens.undistort(xy), np.zeros(len(xy), np.int32), None)
            cols = np.arange(len(ids))
        else:
            current = detect(self.orb, grey, self.lens)
            ids, cols = self._match(current, self._predicted(t), self.radius)
            if len(ids) < 3 * self.min_inliers:
                recent = np.flatnonzero(self.last >= self.frame - 3 - self.lost)
                match = brute_match(self.desc[recent], current)
                ids, cols = recent[match >= 0], match[match >= 0]
        solved = geo.solve_pnp(K, self.X[ids], current.pts[cols], THRESHOLD_PX, 100)
        if solved is None:
            return None
        T_cw, inlier = solved
        ids, cols = ids[inlier], cols[inlier]
        if self.tracker == "orb":  # second, narrow search with the estimated pose
            ids2, cols2 = self._match(current, T_cw, 4.0, k=8)
            refined = geo.refine_pnp(K, self.X[ids2], current.pts[cols2], T_cw, THRESHOLD_PX)
            if refined is not None and np.count_nonzero(refined[1]) >= len(ids):
                T_cw, ids, cols = refined[0], ids2[refined[1]], cols2[refined[1]]
        if len(ids) < self.min_inliers:
            return None
        self.last[ids] = self.frame
        if self.tracker == "klt":
            self.last[np.setdiff1d(np.flatnonzero(self.last >= 0), ids)] = -1  # lost by the flow or an outlier
            self.track[ids] = current.xy[cols]
        else:
            self.desc[ids] = current.descriptors[cols]
        return T_cw, len(ids), current, ids, cols

    def _match(self, current: Features, T_cw: np.ndarray, radius: float, k: int = 8) -> tuple[np.ndarray, np.ndarray]:
        """Map points (ids) matched to current keypoints (rows) near their projections."""
        uv = geo.project(self.lens.K, T_cw, self.X)
        seen = (
            np.isfinite(uv[:, 0])
            & (uv[:, 0] > -radius)
            & (uv[:, 0] < self.width + radius)
            & (uv[:, 1] > -radius)
            & (uv[:, 1] < self.height + radius)
        )
        seen = np.flatnonzero(seen)
        match = guided_match(self.desc[seen], uv[seen], current, radius, k)
        return seen[match >= 0], match[match >= 0]

    def _flow(self, grey: np.ndarray, ids: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        """KLT: map points ``ids`` followed from the last tracked frame into ``grey``, starting
        from where the motion model predicts them (outliers are left to PnP)."""
        if not len(ids) or self.prev_grey is None:
            return ids[:0], np.zeros((0, 2), np.float32)
        p0 = self.track[ids].reshape(-1, 1, 2)
        guess = self.lens.distort(geo.project(self.lens.K, self._predicted(t), self.X[ids]))
        guess = np.where(np.isfinite(guess), guess, p0.reshape(-1, 2)).astype(np.float32).reshape(-1, 1, 2)
        p1, st, _ = cv2.calcOpticalFlowPyrLK(
            self.prev_grey,
            grey,
            p0,
            guess,
            winSize=(15, 15),
            maxLevel=3,
            criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 0.03),
            flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
        )
        p1 = p1.reshape(-1, 2)
        good = (st.ravel() == 1) & (p1[:, 0] >= 0) & (p1[:, 0] < grey.shape[1]) & (p1[:, 1] >= 0) & (p1[:, 1] < grey.shape[0])
        return ids[good], p1[good].astype(np.float32)

    # -- map --------------------------------------------------------------------------------
    def _add(self, X: np.ndarray, desc: np.ndarray | None, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Add the finite rows of ``X``; returns (those rows, their point ids)."""
        ok = np.isfinite(X[:, 0])
        pids = self.next_pid + np.arange(int(ok.sum()))
        self.next_pid += len(pids)
        self.pid = np.concatenate([self.pid, pids])
        self.X = np.concatenate([self.X, X[ok]])
        self.desc = np.concatenate([self.desc, desc[ok] if desc is not None else np.zeros((int(ok.sum()), 32), np.uint8)])
        self.last = np.concatenate([self.last, np.full(int(ok.sum()), self.frame)])
        self.track = np.concatenate([self.track, xy[ok].astype(np.float32)])
        return np.flatnonzero(ok), pids

    def _cull(self) -> None:
        keep = self.last >= max(self.frame - MAX_UNSEEN, 0) if self.tracker == "orb" else self.last >= 0
        if len(keep) > 5 * self.features:  # the map's size stays bounded: the least recent go
            keep &= self.last >= np.sort(self.last)[-5 * self.features]
        if not keep.all():
            self.X, self.desc, self.last, self.track, self.pid = (
                self.X[keep],
                self.desc[keep],
                self.last[keep],
                self.track[keep],
                self.pid[keep],
            )

    def _measure(self, features: Features, grey: np.ndarray, right_grey: np.ndarray | None, depth: np.ndarray | None) -> np.ndarray:
        """Camera-frame points of ``features`` from depth or stereo (NaN: unknown)."""
        if self.mode == "rgbd":
            if depth is None:
                raise ValueError("RGB-D odometry needs every frame's depth map")
            return geo.depth_points(self.lens, depth, features)
        if right_grey is None:
            raise ValueError("stereo odometry needs every frame's right image")
        right = detect(self.orb, right_grey, self.lens, stream=1)
        return geo.stereo_points(self.lens, features, right, grey, right_grey, max_disparity=grey.shape[1] / 3)

    def _new_features(self, grey: np.ndarray, keep_xy: np.ndarray) -> Features:
        """KLT keyframes: ORB (FAST) keypoints at least 8 px from the points still followed."""
        mask = np.full(grey.shape, 255, np.uint8) if self.lens.masks[0] is None else self.lens.masks[0].copy()
        for x, y in np.rint(keep_xy).astype(int):
            cv2.circle(mask, (int(x), int(y)), 8, 0, -1)
        return detect(self.orb, grey, self.lens, mask=mask)

    def _keyframe(
        self,
        T_cw: np.ndarray,
        current: Features,
        ids: np.ndarray,
        cols: np.ndarray,
        grey: np.ndarray,
        right_grey: np.ndarray | None,
        depth: np.ndarray | None,
    ) -> np.ndarray:
        """Add the keypoints of this frame that no map point explains; returns the frame's
        pose (mono: after the local bundle adjustment)."""
        self.keyframes += 1
        if self.tracker == "klt":
            fresh = self._new_features(grey, current.xy[cols])
        else:
            fresh = current.take(np.setdiff1d(np.arange(len(current)), cols))
        if self.mode != "mono":
            self._add(_to_world(T_cw, self._measure(fresh, grey, right_grey, depth)), fresh.desc, fresh.xy)
            return T_cw
        number = max(self.kf_poses) + 1
        self.kf_poses[number] = T_cw
        self._observe(number, self.pid[ids], current.pts[cols])
        left = np.ones(len(fresh), bool)
        pool = self.candidates[-CANDIDATE_KEYFRAMES:]
        if pool and len(fresh):
            match = brute_match(np.concatenate([c["desc"] for c in pool]), fresh)
            start = np.cumsum([0] + [len(c["desc"]) for c in pool])
            for c, lo, hi in zip(pool, start[:-1], start[1:]):
                rows = np.flatnonzero(match[lo:hi] >= 0)
                at = match[lo:hi][rows]
                X = geo.triangulate(
                    self.lens.K, self.kf_poses[c["kf"]], T_cw, c["pts"][rows], fresh.pts[at], THRESHOLD_PX, TRIANGULATE_ANGLE_DEG
                )
                made, pids = self._add(X, fresh.descriptors[at], fresh.xy[at])
                self._observe(c["kf"], pids, c["pts"][rows[made]])
                self._observe(number, pids, fresh.pts[at[made]])
                left[at[made]] = False
                keep = np.setdiff1d(np.arange(len(c["desc"])), rows[made])
                c["desc"], c["pts"] = c["desc"][keep], c["pts"][keep]
        self.candidates = (self.candidates + [{"kf": number, "pts": fresh.pts[left], "desc": fresh.descriptors[left]}])[
            -CANDIDATE_KEYFRAMES:
        ]
        return self._adjust()

    def _observe(self, kf: int, pids: np.ndarray, pts: np.ndarray) -> None:
        k, p, uv = self.obs
        self.obs = (np.concatenate([k, np.full(len(pids), kf)]), np.concatenate([p, pids]), np.concatenate([uv, pts]))

    def _adjust(self) -> np.ndarray:
        """Mono: local bundle adjustment of the last ``WINDOW`` keyframes (the oldest two
        fixed) and the points they see; drops outlier observations; returns the new pose of
        the newest keyframe (this frame)."""
        numbers = sorted(self.kf_poses)[-WINDOW:]
        newest = numbers[-1]
        for old in [n for n in self.kf_poses if n < numbers[0]]:
            del self.kf_poses[old]
        k, p, uv = self.obs
        row = np.searchsorted(self.pid, p)
        keep = (k >= numbers[0]) & (row < len(self.pid))
        keep[keep] &= self.pid[row[keep]] == p[keep]
        k, p, uv, row = k[keep], p[keep], uv[keep], row[keep]
        self.obs = (k, p, uv)
        fixed = 1 if numbers[0] == 0 else FIXED
        if len(numbers) <= fixed:
            return self.kf_poses[newest]
        slot = np.searchsorted(numbers, k)
        free = np.arange(len(numbers)) >= fixed
        counts = np.bincount(row, minlength=len(self.pid))
        seen_free = np.bincount(row, weights=free[slot], minlength=len(self.pid))
        use = (counts[row] >= 2) & (seen_free[row] > 0)
        points, index = np.unique(row[use], return_inverse=True)
        poses = np.stack([self.kf_poses[n] for n in numbers])
        poses, X = bundle_adjust(self.lens.K, poses, free, self.X[points], slot[use], index, uv[use], THRESHOLD_PX, 5)
        self.X[points] = X
        for n, T in zip(numbers, poses):
            self.kf_poses[n] = T
        err = np.linalg.norm(geo.project_each(self.lens.K, poses[slot], self.X[row]) - uv, axis=1)
        good = np.isfinite(err) & (err < 2 * THRESHOLD_PX)
        self.obs = (k[good], p[good], uv[good])
        self.T_cw = self.kf_poses[newest]
        return self.T_cw

    # -- starting a map ---------------------------------------------------------------------
    def _start(self, pos: int, t: float, grey: np.ndarray, right_grey: np.ndarray | None, depth: np.ndarray | None) -> list[Update]:
        if self.tracker == "klt":
            features = self._new_features(grey, np.zeros((0, 2), np.float32))
        else:
            features = detect(self.orb, grey, self.lens)
        X = self._measure(features, grey, right_grey, depth) if len(features) else np.zeros((0, 3))
        count = int(np.count_nonzero(np.isfinite(X[:, 0])))
        if count < 2 * self.min_inliers:
            return [(pos, TrackState.NOT_INITIALISED, count, None)]
        self._reset()
        self.started, self.segments, self.keyframes = True, self.segments + 1, self.keyframes + 1
        self.t_last, self.prev_grey = t, grey
        self._add(X, features.desc, features.xy)
        return [(pos, TrackState.OK, count, np.eye(4))]

    def _start_mono(self, pos: int, t: float, grey: np.ndarray) -> list[Update]:
        """Mono: wait for parallax against a reference frame, then triangulate the first map."""
        not_yet: list[Update] = [(pos, TrackState.NOT_INITIALISED, 0, None)]
        features = detect(self.orb, grey, self.lens)
        init = self.init
        if len(features) < 4 * self.min_inliers:
            return not_yet
        if init is None or pos - init["pos"] > INIT_WINDOW:
            self.init = {"pos": pos, "t": t, "features": features, "grey": grey, "pending": []}
            return not_yet
        ref = init["features"]
        match = brute_match(ref.descriptors, features)
        rows, cols = np.flatnonzero(match >= 0), match[match >= 0]
        if len(rows) < 4 * self.min_inliers:
            self.init = {"pos": pos, "t": t, "features": features, "grey": grey, "pending": []}
            return not_yet
        flow = np.median(np.linalg.norm(ref.pts[rows] - features.pts[cols], axis=1))
        T21 = geo.initial_pose(self.lens.K, ref.pts[rows], features.pts[cols], 1.0) if flow >= INIT_FLOW * self.width else None
        X = (
            None
            if T21 is None
            else geo.triangulate(self.lens.K, np.eye(4), T21, ref.pts[rows], features.pts[cols], THRESHOLD_PX, INIT_ANGLE_DEG)
        )
        good = np.zeros(len(rows), bool) if X is None else np.isfinite(X[:, 0])
        if T21 is None or X is None or np.count_nonzero(good) < max(3 * self.min_inliers, INIT_SHARE * len(rows)):
            init["pending"].append((pos, t, grey, features))
            return not_yet
        scale = 1.0 / np.median(X[good, 2])
        X, T21[:3, 3] = X * scale, T21[:3, 3] * scale
        pending = init["pending"]
        self._reset()
        self.started, self.segments, self.keyframes = True, self.segments + 1, self.keyframes + 2
        _, pids = self._add(X, features.descriptors[cols], features.xy[cols])
        self.kf_poses = {0: np.eye(4), 1: T21}
        self._observe(0, pids, ref.pts[rows[good]])
        self._observe(1, pids, features.pts[cols[good]])
        used = np.zeros(len(ref), bool)
        used[rows[good]] = True
        free = np.ones(len(features), bool)
        free[cols[good]] = False
        self.candidates = [
            {"kf": 0, "pts": ref.pts[~used], "desc": ref.descriptors[~used]},
            {"kf": 1, "pts": features.pts[free], "desc": features.descriptors[free]},
        ]
        self.reference = int(np.count_nonzero(good))
        self.t_last, self.prev_grey = init["t"], init["grey"]
        updates: list[Update] = [(init["pos"], TrackState.OK, self.reference, np.eye(4))]
        for p, _tp, _g, f in pending:  # the frames in between: matched to the new map
            match = brute_match(self.desc, f)
            solved = geo.solve_pnp(self.lens.K, self.X[match >= 0], f.pts[match[match >= 0]], THRESHOLD_PX, 100)
            if solved is not None and np.count_nonzero(solved[1]) >= self.min_inliers:
                updates.append((p, TrackState.OK, int(np.count_nonzero(solved[1])), geo.invert(solved[0])))
            else:
                updates.append((p, TrackState.LOST, 0, None))
        self.T_cw, self.t_last, self.prev_grey = T21, t, grey
        self.velocity = np.zeros(6)
        if t > init["t"]:
            self.velocity = np.concatenate([cv2.Rodrigues(T21[:3, :3])[0].ravel(), T21[:3, 3]]) / (t - init["t"])
        self.last[:] = self.frame
        updates.append((pos, TrackState.OK, self.reference, geo.invert(T21)))
        return updates


def _to_world(T_cw: np.ndarray, Xc: np.ndarray) -> np.ndarray:
    T_wc = geo.invert(T_cw)
    return Xc @ T_wc[:3, :3].T + T_wc[:3, 3]
