"""Many steps resected at once: each step's pose from its rays to known points, by orthogonal
iteration (Lu, Hager & Mjolsness, *Fast and globally convergent pose estimation from video
images*, IEEE TPAMI 22(6), 2000), for all the steps together.

:func:`mappers.spatial.registration.orthogonal_iteration` resects one step; a map of 2,000
steps called it in a Python loop per step and per round, which cost tens of seconds. Here the
steps' sightings are segments of one array: the start and the final translations and errors are
sums over a step's sightings (one sparse matrix product) and a batched SVD; the iterations run
as one compiled loop per step (:mod:`mappers.spatial.resection_kernels`), each step stopping
once it has converged (as the one-step version does), so the poses are those of the one-step
version to rounding.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from mappers.spatial import resection_kernels as kernels

__all__ = ["orthogonal_iteration_batch"]


def _segment_sum(G, values):
    """Per segment, the sum of ``values`` (K, ...) over its rows (``G``: segments x K)."""
    shape = values.shape[1:]
    return np.asarray(G @ values.reshape(len(values), -1)).reshape((G.shape[0],) + shape)


def _kabsch(G, seg, n, src, dst):
    """Per segment, the rotation ``R`` with ``dst ~= R src + t`` (Umeyama 1991, no scale)."""
    mu_s, mu_d = _segment_sum(G, src) / n[:, None], _segment_sum(G, dst) / n[:, None]
    a, b = src - mu_s[seg], dst - mu_d[seg]
    U, _, Vt = np.linalg.svd(_segment_sum(G, b[:, :, None] * a[:, None, :]) / n[:, None, None])
    D = np.ones((len(n), 3))
    D[:, 2] = np.sign(np.linalg.det(U) * np.linalg.det(Vt))
    D[:, 2] = np.where(D[:, 2] == 0, 1.0, D[:, 2])
    return (U * D[:, None, :]) @ Vt


def orthogonal_iteration_batch(seg: np.ndarray, p: np.ndarray, u: np.ndarray, n_seg: int,
                               iters: int = 60, tol: float = 1e-10):
    """``(R, c, rms)`` per segment (``seg`` (K,) in 0..n_seg-1, each with three or more rows):
    the pose (rotation sensor -> world (S, 3, 3), position (S, 3)) of a sensor that sees the
    known points ``p`` (K, 3) along the unit rays ``u`` (K, 3), and the root mean square of its
    rays' angle errors [rad] (S,); as :func:`mappers.spatial.registration.orthogonal_iteration`
    for each segment, ``iters`` iterations at most; a segment stops once no entry of its rotation
    moves by ``tol`` or more in an iteration (1e-10: as the one-step version)."""
    k = len(seg)
    G = sparse.csc_matrix((np.ones(k), (seg, np.arange(k))), shape=(n_seg, k))
    n = np.asarray(G.sum(axis=1)).ravel()
    V = u[:, :, None] * u[:, None, :]
    F = np.linalg.inv(np.eye(3) - _segment_sum(G, V) / n[:, None, None])
    mu_p = _segment_sum(G, p) / n[:, None]
    mu_u = _segment_sum(G, u) / n[:, None]
    spread_p = _segment_sum(G, np.linalg.norm(p - mu_p[seg], axis=1)) / n
    spread_u = _segment_sum(G, np.linalg.norm(u - mu_u[seg], axis=1)) / n
    q = u * (spread_p / np.maximum(spread_u, 1e-6))[seg, None]
    Rcw = _kabsch(G, seg, n, p, q)

    def translation(Rcw):
        pc = np.einsum("kij,kj->ki", Rcw[seg], p)
        t = np.einsum("sij,sj->si", F, _segment_sum(G, np.einsum("kij,kj->ki", V, pc) - pc)
                      / n[:, None])
        return pc, t

    # the iterations: one compiled loop per segment (mappers.spatial.resection_kernels), each
    # until its rotation stops moving
    order = np.argsort(seg, kind="stable")
    indptr = np.zeros(n_seg + 1, dtype=np.int64)
    np.cumsum(np.bincount(seg, minlength=n_seg), out=indptr[1:])
    Rcw = np.ascontiguousarray(Rcw)
    kernels.orthogonal_iterations(np.ascontiguousarray(p[order], dtype=np.float64),
                                  np.ascontiguousarray(V[order]), indptr,
                                  np.ascontiguousarray(F), Rcw, int(iters), float(tol))
    pc, t = translation(Rcw)
    cam = pc + t[seg]
    cos = np.einsum("kj,kj->k", cam, u) / np.maximum(np.linalg.norm(cam, axis=1), 1e-12)
    rms = np.sqrt(_segment_sum(G, np.arccos(np.clip(cos, -1.0, 1.0)) ** 2) / n)
    R = Rcw.transpose(0, 2, 1)
    return R, -np.einsum("sij,sj->si", R, t), rms
