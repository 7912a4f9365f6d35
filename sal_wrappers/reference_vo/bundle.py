"""Local bundle adjustment for the monocular reference odometry (numpy + scipy.sparse).

Minimises the Huber-robust reprojection error of map points in a window of keyframes over
the free keyframe poses and the points, by damped Gauss-Newton (Levenberg-Marquardt) on the
Schur complement: the point blocks (3x3) are eliminated, the reduced camera system (6 per
free pose) is solved densely, the points are back-substituted. Fixed keyframes (the oldest of
the window) anchor position, orientation and scale. Poses are ``T_cw`` (world to camera) and
updated by left multiplication with ``exp(delta)``; deterministic (no randomness at all).
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np
import scipy.sparse as sp

__all__ = ["bundle_adjust"]


def _residuals(K: np.ndarray, R: np.ndarray, t: np.ndarray, X: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per observation: camera-frame point (Nx3) and residual projection - uv (Nx2)."""
    Xc = np.einsum("nij,nj->ni", R, X) + t
    z = np.where(Xc[:, 2] > 1e-6, Xc[:, 2], 1e-6)
    proj = np.stack([K[0, 0] * Xc[:, 0] / z + K[0, 2], K[1, 1] * Xc[:, 1] / z + K[1, 2]], axis=1)
    return Xc, proj - uv


def _robust_cost(r: np.ndarray, delta: float) -> float:
    e = np.linalg.norm(r, axis=1)
    return float(np.sum(np.where(e <= delta, 0.5 * e * e, delta * (e - 0.5 * delta))))


def bundle_adjust(
    K: np.ndarray,
    poses: np.ndarray,
    free: np.ndarray,
    X: np.ndarray,
    obs_pose: np.ndarray,
    obs_point: np.ndarray,
    uv: np.ndarray,
    delta: float = 2.5,
    iterations: int = 5,
) -> tuple[np.ndarray, np.ndarray]:
    """Refine ``poses`` (Nx4x4 ``T_cw``; those with ``free`` True) and points ``X`` (Px3) from
    observations ``uv`` (ideal px) of point ``obs_point`` in pose ``obs_pose``; returns the
    new (poses, X)."""
    poses, X = poses.copy(), X.copy()
    if not np.any(free) or not len(uv) or not (np.isfinite(poses).all() and np.isfinite(X).all() and np.isfinite(uv).all()):
        return poses, X
    problem = _Problem(K, free, len(X), obs_pose, obs_point, uv, delta)
    lam = 1e-3
    Xc, r, cost = problem.evaluate(poses, X)
    for _ in range(iterations):
        system = problem.linearise(poses, Xc, r)
        for _attempt in range(4):
            step = problem.solve(system, lam)
            if step is None:  # singular: damp more
                lam *= 10
                continue
            new_poses, new_X = problem.moved(poses, X, *step)
            new_Xc, new_r, new_cost = problem.evaluate(new_poses, new_X)
            if new_cost < cost:
                poses, X, Xc, r, cost = new_poses, new_X, new_Xc, new_r, new_cost
                lam = max(lam / 10, 1e-7)
                break
            lam *= 10
        else:
            break
    return poses, X


class _Normal(NamedTuple):
    """The Gauss-Newton normal equations: point blocks ``V`` (Px3x3) and right side ``c``,
    free-pose blocks ``U`` (Fx6x6) and ``b``, pose-point coupling ``Wm`` (6F x 3P, sparse)."""

    V: np.ndarray
    c: np.ndarray
    U: np.ndarray
    b: np.ndarray
    Wm: sp.csr_matrix


class _Problem:
    """The fixed structure of one adjustment: who observes what, and the sparse sums over it."""

    def __init__(
        self, K: np.ndarray, free: np.ndarray, points: int, obs_pose: np.ndarray, obs_point: np.ndarray, uv: np.ndarray, delta: float
    ):
        self.K, self.free, self.P, self.delta = K, free, points, delta
        self.obs_pose, self.obs_point, self.uv = obs_pose, obs_point, uv
        self.nfree = int(np.count_nonzero(free))
        slot = np.cumsum(free) - 1  # index of a free pose among the free ones
        n, P = len(uv), points
        self.sum_by_point = sp.csr_matrix((np.ones(n), (obs_point, np.arange(n))), shape=(P, n))
        f = free[obs_pose]
        self.k, self.i = np.flatnonzero(f), slot[obs_pose[f]]  # observations in free poses, their pose slots
        p = obs_point[f]
        self.sum_by_pose = sp.csr_matrix((np.ones(len(self.k)), (self.i, np.arange(len(self.k)))), shape=(self.nfree, len(self.k)))
        self.block_rows = (3 * np.arange(P)[:, None, None] + np.arange(3)[None, :, None]).repeat(3, axis=2).ravel()
        self.block_cols = (3 * np.arange(P)[:, None, None] + np.arange(3)[None, None, :]).repeat(3, axis=1).ravel()
        self.coupling_rows = (6 * self.i[:, None, None] + np.arange(6)[None, :, None]).repeat(3, axis=2).ravel()
        self.coupling_cols = (3 * p[:, None, None] + np.arange(3)[None, None, :]).repeat(6, axis=1).ravel()

    def evaluate(self, poses: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """Camera-frame points, residuals (px) and robust cost of every observation."""
        R, t = poses[self.obs_pose, :3, :3], poses[self.obs_pose, :3, 3]
        Xc, r = _residuals(self.K, R, t, X[self.obs_point], self.uv)
        return Xc, r, _robust_cost(r, self.delta)

    def linearise(self, poses: np.ndarray, Xc: np.ndarray, r: np.ndarray) -> _Normal:
        """The Huber-weighted (IRLS) normal equations at ``poses`` (``Xc``, ``r`` from ``evaluate``)."""
        K, n, P, k = self.K, len(self.uv), self.P, self.k
        e = np.linalg.norm(r, axis=1)
        w = np.where(e <= self.delta, 1.0, self.delta / np.maximum(e, 1e-12))  # Huber weights (IRLS)
        z = np.where(Xc[:, 2] > 1e-6, Xc[:, 2], 1e-6)
        x, y = Xc[:, 0], Xc[:, 1]
        dproj = np.zeros((n, 2, 3))
        dproj[:, 0, 0], dproj[:, 0, 2] = K[0, 0] / z, -K[0, 0] * x / (z * z)
        dproj[:, 1, 1], dproj[:, 1, 2] = K[1, 1] / z, -K[1, 1] * y / (z * z)
        skew = np.zeros((n, 3, 6))  # d Xc / d (omega, v) = [-[Xc]x, I]
        skew[:, 0, 1], skew[:, 0, 2] = Xc[:, 2], -Xc[:, 1]
        skew[:, 1, 0], skew[:, 1, 2] = -Xc[:, 2], Xc[:, 0]
        skew[:, 2, 0], skew[:, 2, 1] = Xc[:, 1], -Xc[:, 0]
        skew[:, 0, 3] = skew[:, 1, 4] = skew[:, 2, 5] = 1.0
        Jc = dproj @ skew  # 2x6 per observation
        Jx = dproj @ poses[self.obs_pose, :3, :3]  # 2x3
        JxT = Jx.transpose(0, 2, 1) * w[:, None, None]
        V = (self.sum_by_point @ (JxT @ Jx).reshape(n, 9)).reshape(P, 3, 3)
        c = -(self.sum_by_point @ (JxT @ r[:, :, None]).reshape(n, 3))
        JcT = Jc[k].transpose(0, 2, 1) * w[k, None, None]
        U = (self.sum_by_pose @ (JcT @ Jc[k]).reshape(len(k), 36)).reshape(self.nfree, 6, 6)
        b = -(self.sum_by_pose @ (JcT @ r[k, :, None]).reshape(len(k), 6))
        Wm = sp.csr_matrix(((JcT @ Jx[k]).ravel(), (self.coupling_rows, self.coupling_cols)), shape=(6 * self.nfree, 3 * P))
        return _Normal(V, c, U, b, Wm)

    def solve(self, system: _Normal, lam: float) -> tuple[np.ndarray, np.ndarray] | None:
        """(pose step 6F, point step Px3) of the system damped by ``lam`` (Schur complement on
        the points), or ``None`` when it is singular."""
        V, c, U, b, Wm = system
        P, eye3, eye6 = self.P, np.eye(3), np.eye(6)
        Vd = V + lam * eye3 * np.maximum(np.einsum("nii->ni", V), 1e-9)[:, :, None] + 1e-9 * eye3
        try:
            Vinv = np.linalg.inv(Vd)
        except np.linalg.LinAlgError:
            return None
        Ud = U + lam * eye6 * np.maximum(np.einsum("nii->ni", U), 1e-9)[:, :, None]
        Vm = sp.csr_matrix((Vinv.ravel(), (self.block_rows, self.block_cols)), shape=(3 * P, 3 * P))
        Y = Wm @ Vm
        S = -(Y @ Wm.T).toarray()  # sparse products: no multi-threaded BLAS for small sizes
        for s in range(self.nfree):
            S[6 * s : 6 * s + 6, 6 * s : 6 * s + 6] += Ud[s]
        rhs = b.ravel() - Y @ c.ravel()
        try:
            dpose = np.linalg.solve(S, rhs)
        except np.linalg.LinAlgError:
            return None
        dpoint = (Vinv @ (c - (Wm.T @ dpose).reshape(P, 3))[:, :, None])[:, :, 0]
        return dpose, dpoint

    def moved(self, poses: np.ndarray, X: np.ndarray, dpose: np.ndarray, dpoint: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The free poses left-multiplied by ``exp(dpose)`` and the points moved by ``dpoint``."""
        new_poses = poses.copy()
        for s, idx in enumerate(np.flatnonzero(self.free)):
            d = dpose[6 * s : 6 * s + 6]
            step = np.eye(4)
            step[:3, :3] = cv2.Rodrigues(d[:3])[0]
            step[:3, 3] = d[3:]
            new_poses[idx] = step @ poses[idx]
        return new_poses, X + dpoint
