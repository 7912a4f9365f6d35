"""Local bundle adjustment for the monocular reference odometry (numpy + scipy.sparse).

Minimises the Huber-robust reprojection error of map points in a window of keyframes over
the free keyframe poses and the points, by damped Gauss-Newton (Levenberg-Marquardt) on the
Schur complement: the point blocks (3x3) are eliminated, the reduced camera system (6 per
free pose) is solved densely, the points are back-substituted. Fixed keyframes (the oldest of
the window) anchor position, orientation and scale. Poses are ``T_cw`` (world to camera) and
updated by left multiplication with ``exp(delta)``; deterministic (no randomness at all).
"""

from __future__ import annotations

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
    nfree = int(np.count_nonzero(free))
    if nfree == 0 or not len(uv) or not (np.isfinite(poses).all() and np.isfinite(X).all() and np.isfinite(uv).all()):
        return poses, X
    slot = np.cumsum(free) - 1  # index of a free pose among the free ones
    P = len(X)
    lam = 1e-3

    def evaluate(poses: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        R, t = poses[obs_pose, :3, :3], poses[obs_pose, :3, 3]
        Xc, r = _residuals(K, R, t, X[obs_point], uv)
        return Xc, r, _robust_cost(r, delta)

    Xc, r, cost = evaluate(poses, X)
    n = len(uv)
    sum_by_point = sp.csr_matrix((np.ones(n), (obs_point, np.arange(n))), shape=(P, n))
    f = free[obs_pose]
    k, i = np.flatnonzero(f), slot[obs_pose[f]]
    p = obs_point[f]
    sum_by_pose = sp.csr_matrix((np.ones(len(k)), (i, np.arange(len(k)))), shape=(nfree, len(k)))
    eye3, eye6 = np.eye(3), np.eye(6)
    block_rows = (3 * np.arange(P)[:, None, None] + np.arange(3)[None, :, None]).repeat(3, axis=2).ravel()
    block_cols = (3 * np.arange(P)[:, None, None] + np.arange(3)[None, None, :]).repeat(3, axis=1).ravel()
    for _ in range(iterations):
        e = np.linalg.norm(r, axis=1)
        w = np.where(e <= delta, 1.0, delta / np.maximum(e, 1e-12))  # Huber weights (IRLS)
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
        Jx = dproj @ poses[obs_pose, :3, :3]  # 2x3
        JxT = Jx.transpose(0, 2, 1) * w[:, None, None]
        V = (sum_by_point @ (JxT @ Jx).reshape(n, 9)).reshape(P, 3, 3)
        c = -(sum_by_point @ (JxT @ r[:, :, None]).reshape(n, 3))
        JcT = Jc[k].transpose(0, 2, 1) * w[k, None, None]
        U = (sum_by_pose @ (JcT @ Jc[k]).reshape(len(k), 36)).reshape(nfree, 6, 6)
        b = -(sum_by_pose @ (JcT @ r[k, :, None]).reshape(len(k), 6))
        rows = (6 * i[:, None, None] + np.arange(6)[None, :, None]).repeat(3, axis=2).ravel()
        cols = (3 * p[:, None, None] + np.arange(3)[None, None, :]).repeat(6, axis=1).ravel()
        Wm = sp.csr_matrix(((JcT @ Jx[k]).ravel(), (rows, cols)), shape=(6 * nfree, 3 * P))  # pose-point blocks
        for _attempt in range(4):
            Vd = V + lam * eye3 * np.maximum(np.einsum("nii->ni", V), 1e-9)[:, :, None] + 1e-9 * eye3
            try:
                Vinv = np.linalg.inv(Vd)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            Ud = U + lam * eye6 * np.maximum(np.einsum("nii->ni", U), 1e-9)[:, :, None]
            Vm = sp.csr_matrix((Vinv.ravel(), (block_rows, block_cols)), shape=(3 * P, 3 * P))
            Y = Wm @ Vm
            S = -(Y @ Wm.T).toarray()  # sparse products: no multi-threaded BLAS for small sizes
            for s in range(nfree):
                S[6 * s : 6 * s + 6, 6 * s : 6 * s + 6] += Ud[s]
            rhs = b.ravel() - Y @ c.ravel()
            try:
                dpose = np.linalg.solve(S, rhs)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            dpoint = (Vinv @ (c - (Wm.T @ dpose).reshape(P, 3))[:, :, None])[:, :, 0]
            new_poses = poses.copy()
            for s, idx in enumerate(np.flatnonzero(free)):
                d = dpose[6 * s : 6 * s + 6]
                step = np.eye(4)
                step[:3, :3] = cv2.Rodrigues(d[:3])[0]
                step[:3, 3] = d[3:]
                new_poses[idx] = step @ poses[idx]
            new_X = X + dpoint
            new_Xc, new_r, new_cost = evaluate(new_poses, new_X)
            if new_cost < cost:
                poses, X, Xc, r, cost = new_poses, new_X, new_Xc, new_r, new_cost
                lam = max(lam / 10, 1e-7)
                break
            lam *= 10
        else:
            break
    return poses, X
