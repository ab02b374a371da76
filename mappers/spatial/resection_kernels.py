"""The compiled loop of the batched resection (:mod:`mappers.spatial.resection`): Lu, Hager &
Mjolsness's orthogonal iteration (*Fast and globally convergent pose estimation from video
images*, IEEE TPAMI 22(6), 2000) run step by step until each step's rotation stops moving.

As numpy expressions over all the steps at once, each iteration is a dozen passes over the
sightings and a batched SVD, and the iteration converges linearly: at 1,300 steps it took 0.7 s,
most of it numpy's per-call overhead on arrays of a few sightings per step. One compiled loop
per step holds its few sightings and its 3 x 3 fit in registers (the SVD is LAPACK's, as
numpy's). numba is the well-kept way to write such loops in Python (as
:mod:`mappers.viewpoints.sparse_schur_kernels`); compiled, and cached on disk, on first use
(:mod:`mappers.core.jit`).
"""

from __future__ import annotations

import numpy as np

from mappers.core.jit import compiled_on_first_use

__all__ = ["orthogonal_iterations"]  # noqa: F822

__getattr__ = compiled_on_first_use(globals(), __all__, helpers=("det3",))


def det3(A):  # pragma: no cover - compiled
    """The determinant of a 3 x 3 matrix (cofactors)."""
    return (A[0, 0] * (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1])
            - A[0, 1] * (A[1, 0] * A[2, 2] - A[1, 2] * A[2, 0])
            + A[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]))


def _orthogonal_iterations(p, V, indptr, F, R, iters, tol):  # pragma: no cover - compiled
    """Iterate each segment ``s`` (its rows ``indptr[s]:indptr[s + 1]`` of the points ``p``
    (K, 3) and their rays' projections ``V`` (K, 3, 3)) from its rotation world -> sensor
    ``R[s]`` (S, 3, 3, updated in place): the translation ``t = F_s mean(V_k R p_k - R p_k)``,
    the points' projections ``q_k = V_k (R p_k + t)`` onto their rays, and the rotation of the
    best rigid fit of ``p`` onto ``q`` (Kabsch/Umeyama, no scale); ``iters`` times at most, or
    until no entry of the rotation moves by ``tol`` or more."""
    H = np.empty((3, 3))
    q = np.empty((p.shape[0], 3))
    Rc = np.empty((3, 3))
    new = np.empty((3, 3))
    pc, acc, t, mp, mq = np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    for s in range(indptr.shape[0] - 1):
        lo, hi = indptr[s], indptr[s + 1]
        n = hi - lo
        for i in range(3):
            x = 0.0
            for k in range(lo, hi):
                x += p[k, i]
            mp[i] = x / n
        for i in range(3):
            for j in range(3):
                Rc[i, j] = R[s, i, j]
        for _ in range(iters):
            acc[0] = acc[1] = acc[2] = 0.0
            for k in range(lo, hi):  # sum of V_k R p_k - R p_k
                for i in range(3):
                    pc[i] = Rc[i, 0] * p[k, 0] + Rc[i, 1] * p[k, 1] + Rc[i, 2] * p[k, 2]
                for i in range(3):
                    acc[i] += V[k, i, 0] * pc[0] + V[k, i, 1] * pc[1] + V[k, i, 2] * pc[2] - pc[i]
            for i in range(3):
                t[i] = (F[s, i, 0] * acc[0] + F[s, i, 1] * acc[1] + F[s, i, 2] * acc[2]) / n
            mq[0] = mq[1] = mq[2] = 0.0
            for k in range(lo, hi):  # q_k = V_k (R p_k + t)
                for i in range(3):
                    pc[i] = Rc[i, 0] * p[k, 0] + Rc[i, 1] * p[k, 1] + Rc[i, 2] * p[k, 2] + t[i]
                for i in range(3):
                    x = V[k, i, 0] * pc[0] + V[k, i, 1] * pc[1] + V[k, i, 2] * pc[2]
                    q[k, i] = x
                    mq[i] += x
            for i in range(3):
                mq[i] /= n
            for i in range(3):
                for j in range(3):
                    H[i, j] = 0.0
            for k in range(lo, hi):
                for i in range(3):
                    for j in range(3):
                        H[i, j] += (q[k, i] - mq[i]) * (p[k, j] - mp[j])
            for i in range(3):
                for j in range(3):
                    H[i, j] /= n
            U, _, Vt = np.linalg.svd(H)
            d = np.sign(det3(U) * det3(Vt))
            if d == 0.0:
                d = 1.0
            moved = 0.0
            for i in range(3):
                for j in range(3):
                    x = U[i, 0] * Vt[0, j] + U[i, 1] * Vt[1, j] + d * U[i, 2] * Vt[2, j]
                    moved = max(moved, abs(x - Rc[i, j]))
                    new[i, j] = x
            for i in range(3):
                for j in range(3):
                    Rc[i, j] = new[i, j]
            if moved < tol:
                break
        for i in range(3):
            for j in range(3):
                R[s, i, j] = Rc[i, j]
