"""Relative rotations between steps from their rays alone: the view graph of global structure
from motion.

Two steps that see the same objects fix the rotation between their frames without any point
known: the rays of one object satisfy the epipolar constraint ``d_b . E d_a = 0`` with the
essential matrix ``E = [t]x R`` (Longuet-Higgins, *A computer algorithm for reconstructing a
scene from two projections*, Nature 293, 1981). ``E`` is estimated from eight or more common
objects by the linear eight-point algorithm (Hartley, *In defense of the eight-point
algorithm*, IEEE TPAMI 19(6), 1997: unit rays of a calibrated camera need no further
normalisation), reweighted a few times by a Cauchy weight of each object's epipolar residual
(deterministic, no RANSAC), projected onto the essential manifold and decomposed into its four
``(R, t)``, of which the one that puts the most objects in front of both steps is kept
(Hartley & Zisserman, *Multiple View Geometry*, 2nd ed., section 9.6.2). Where the two steps
barely moved (the rays of one step are those of the other turned, to the noise) ``E`` is not
fixed, but the rotation is: it is the rotation that best turns one step's rays onto the
other's (Kabsch / Umeyama), kept instead.

Every pair is solved at once (batched NumPy over the pairs and their common objects) rather
than in a loop per pair: a map of 2,000 steps has tens of thousands of pairs.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import sparse

from mappers.spatial.rays import RayObservations

__all__ = ["PairRotations", "relative_rotations", "view_pairs"]

_IRLS_ROUNDS = 3
"""Reweighting rounds of the eight-point estimate."""

_W = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


class PairRotations(NamedTuple):
    """Relative rotations of pairs of steps ``a``, ``b``: ``rotation`` (P, 3, 3) turns step
    ``a``'s frame into ``b``'s (``R_b^T R_a`` with sensor -> world rotations ``R``);
    ``residual`` (P,) the median angle [rad] its rays miss the two-view geometry by;
    ``inliers`` (P,) the common objects that agree with it; ``parallax`` (P,) the median angle
    [rad] between an object's two rays once turned into one frame."""

    a: np.ndarray
    b: np.ndarray
    rotation: np.ndarray
    residual: np.ndarray
    inliers: np.ndarray
    parallax: np.ndarray


def view_pairs(obs: RayObservations, steps: np.ndarray, min_shared: int, per_step: int):
    """``(a, b, ka, kb, pair)``: pairs of ``steps`` that share at least ``min_shared`` objects,
    each step keeping the ``per_step`` partners it shares the most objects with (a pair kept by
    either step is kept), and their common sightings: ``ka``, ``kb`` index the observations of
    step ``a[pair]`` and ``b[pair]`` of the same object."""
    chosen = np.zeros(obs.n_steps, dtype=bool)
    chosen[steps] = True
    use = np.flatnonzero(chosen[obs.step])
    V = sparse.csr_matrix((np.ones(use.size), (obs.step[use], obs.obj[use])),
                          shape=(obs.n_steps, obs.n_objects))
    S = (V @ V.T).tocoo()
    keep = (S.row != S.col) & (S.data >= min_shared)
    r, c, s = S.row[keep], S.col[keep], S.data[keep]
    # per step, its partners by shared objects, most first (ties: the nearer step index)
    order = np.lexsort((np.abs(c - r), -s, r))
    r, c = r[order], c[order]
    rank = np.arange(r.size) - np.searchsorted(r, r)
    r, c = r[rank < per_step], c[rank < per_step]
    a, b = np.minimum(r, c), np.maximum(r, c)
    key = np.unique(a.astype(np.int64) * obs.n_steps + b)
    a, b = key // obs.n_steps, key % obs.n_steps
    # the common sightings: each step's sighting index per object, looked up for both
    index = sparse.csr_matrix((np.arange(1, use.size + 1, dtype=float), (obs.step[use],
                               obs.obj[use])), shape=(obs.n_steps, obs.n_objects))
    Ia, Ib = index[a], index[b]
    both = Ia.multiply(Ib > 0).tocoo()
    other = Ib.multiply(Ia > 0).tocoo()
    oa = np.lexsort((both.col, both.row))
    ob = np.lexsort((other.col, other.row))
    ka = use[both.data[oa].astype(np.int64) - 1]
    kb = use[other.data[ob].astype(np.int64) - 1]
    return a, b, ka, kb, both.row[oa]


def _smallest_eigvec(M: np.ndarray) -> np.ndarray:
    return np.linalg.eigh(M)[1][..., 0]


def relative_rotations(obs: RayObservations, a, b, ka, kb, pair, *,
                       noise: float) -> PairRotations:
    """The relative rotation of each pair ``a[p]``, ``b[p]`` from its common sightings ``ka``,
    ``kb`` (``pair`` the pair of each; :func:`view_pairs`), see the module's docstring;
    ``noise`` [rad] the rays' angle noise, which scales the reweighting and tells a pair that
    barely moved (its rays turned onto each other within three times it)."""
    n_pairs = len(a)
    da, db = obs.ray[ka], obs.ray[kb]
    count = np.bincount(pair, minlength=n_pairs).astype(float)
    # the pure rotation: Kabsch on the two steps' rays (db ~ Rot da)
    H = np.zeros((n_pairs, 3, 3))
    np.add.at(H, pair, db[:, :, None] * da[:, None, :])
    Rk = _project_rotation(H)
    turned = np.einsum("kij,kj->ki", Rk[pair], da)
    spin = np.arccos(np.clip(np.einsum("kj,kj->k", turned, db), -1.0, 1.0))
    still = _segment_median(spin, pair, n_pairs) < 3.0 * noise
    # the eight-point algorithm, reweighted: rows kron(db, da) of E flattened row-major
    rows = (db[:, :, None] * da[:, None, :]).reshape(-1, 9)
    w = np.ones(len(pair))
    for _ in range(_IRLS_ROUNDS):
        M = np.zeros((n_pairs, 9, 9))
        np.add.at(M, pair, w[:, None, None] * rows[:, :, None] * rows[:, None, :])
        E = _smallest_eigvec(M).reshape(n_pairs, 3, 3)
        U, _, Vt = np.linalg.svd(E)
        E = U @ np.diag([1.0, 1.0, 0.0]) @ Vt
        r = _epipolar_angle(E[pair], da, db)
        scale = np.maximum(_segment_median(np.abs(r), pair, n_pairs), noise)
        w = 1.0 / (1.0 + (r / (2.0 * scale[pair])) ** 2)
    U, _, Vt = np.linalg.svd(E)
    U = U * np.sign(np.linalg.det(U))[:, None, None]
    Vt = Vt * np.sign(np.linalg.det(Vt))[:, None, None]
    cands = [U @ _W @ Vt, U @ _W.T @ Vt]
    t = U[:, :, 2]
    best_front = np.full(n_pairs, -1.0)
    Re = np.zeros((n_pairs, 3, 3))
    for Rc in cands:
        for sign in (1.0, -1.0):
            front = _in_front(Rc[pair], sign * t[pair], da, db)
            n_front = np.bincount(pair, weights=front, minlength=n_pairs)
            better = n_front > best_front
            best_front = np.where(better, n_front, best_front)
            Re[better] = Rc[better]
    R = np.where(still[:, None, None], Rk, Re)
    r_final = np.where(still[pair], spin, np.abs(_epipolar_angle(E[pair], da, db)))
    residual = _segment_median(r_final, pair, n_pairs)
    inliers = np.bincount(pair, weights=r_final < 3.0 * np.maximum(residual[pair], noise),
                          minlength=n_pairs)
    turned = np.einsum("kij,kj->ki", R[pair], da)
    parallax = _segment_median(np.arccos(np.clip(np.einsum("kj,kj->k", turned, db), -1, 1)),
                               pair, n_pairs)
    inliers = np.where(best_front < 0.8 * count, 0.0, inliers)  # cheirality not clear: refuse
    return PairRotations(a, b, R, residual, inliers, parallax)


def _project_rotation(H: np.ndarray) -> np.ndarray:
    """The rotations nearest (Frobenius) to the (P, 3, 3) matrices ``H``."""
    U, _, Vt = np.linalg.svd(H)
    D = np.ones((len(H), 3))
    D[:, 2] = np.where(np.linalg.det(U @ Vt) < 0, -1.0, 1.0)
    return (U * D[:, None, :]) @ Vt


def _epipolar_angle(E, da, db):
    """The epipolar residual of each ray pair as an angle [rad]: ``db . E da`` over the norm of
    ``E da`` (the sine of the angle between ``db`` and the epipolar plane of ``da``)."""
    Eda = np.einsum("kij,kj->ki", E, da)
    return np.einsum("kj,kj->k", db, Eda) / np.maximum(np.linalg.norm(Eda, axis=1), 1e-12)


def _in_front(R, t, da, db):
    """Whether each object lies in front of both steps for ``db ~ R da + t``: the depths of the
    two rays' closest points are positive."""
    Rda = np.einsum("kij,kj->ki", R, da)
    # solve  za Rda - zb db = -t  in least squares (2 unknowns)
    A11 = np.einsum("kj,kj->k", Rda, Rda)
    A12 = -np.einsum("kj,kj->k", Rda, db)
    A22 = np.einsum("kj,kj->k", db, db)
    b1, b2 = -np.einsum("kj,kj->k", Rda, t), np.einsum("kj,kj->k", db, t)
    det = A11 * A22 - A12**2
    det = np.where(np.abs(det) < 1e-12, 1e-12, det)
    za = (A22 * b1 - A12 * b2) / det
    zb = (A11 * b2 - A12 * b1) / det
    return ((za > 0) & (zb > 0)).astype(float)


def _segment_median(values, seg, n):
    """The median of ``values`` per segment id ``seg`` (0..n-1); NaN for empty segments."""
    order = np.lexsort((values, seg))
    v, s = values[order], seg[order]
    start = np.searchsorted(s, np.arange(n))
    stop = np.searchsorted(s, np.arange(n), side="right")
    out = np.full(n, np.nan)
    has = stop > start
    lo = v[(start + (stop - start - 1) // 2)[has]]
    hi = v[(start + (stop - start) // 2)[has]]
    out[has] = 0.5 * (lo + hi)
    return out
