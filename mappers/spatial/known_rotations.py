"""Positions of the steps and the objects from rays once the steps' rotations are known.

With a step's rotation ``R_t`` (sensor -> world) known, its ray to object ``i`` is a direction
``w = R_t d`` in the world, and ``w x (X_i - C_t) = 0`` is linear in the unknown positions of
the object ``X_i`` and of the step ``C_t``: all rays together are one sparse linear least-squares
problem, fixed up to a translation and a scale (the known-rotation problem: Kahl & Hartley,
*Multiple-view geometry under the L-infinity norm*, IEEE TPAMI 30(9), 2008; in linear form e.g.
Jiang, Cui & Tan, *A global linear method for camera pose registration*, ICCV 2013). The gauge
is fixed by one step at the origin and one of its objects at depth 1. The cross product's
length is the angle error times the depth, so the system is re-solved with each ray divided by
its current depth (angle errors), and with a Cauchy weight of that angle (a wrong sighting
loses its pull). SciPy's sparse direct solver solves the normal equations.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import spsolve

from mappers.spatial.rays import RayObservations

__all__ = ["positions_from_rotations", "solvable"]


def _skew(w):
    z = np.zeros(len(w))
    return np.stack([np.stack([z, -w[:, 2], w[:, 1]], 1), np.stack([w[:, 2], z, -w[:, 0]], 1),
                     np.stack([-w[:, 1], w[:, 0], z], 1)], 1)


def solvable(obs: RayObservations, posed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(steps, objects)`` bool: the posed steps that see two or more objects seen from two or
    more such steps, and those objects (a step with one ray, or an object with one, is not
    fixed by the rays: its position slides along the ray), found by pruning until both hold."""
    use = posed[obs.step]
    steps, objects = posed.copy(), np.ones(obs.n_objects, dtype=bool)
    while True:
        k = use & steps[obs.step] & objects[obs.obj]
        n_obj = np.bincount(obs.obj[k], minlength=obs.n_objects)
        objects_new = objects & (n_obj >= 2)
        k &= objects_new[obs.obj]
        n_step = np.bincount(obs.step[k], minlength=obs.n_steps)
        steps_new = steps & (n_step >= 2)
        if np.array_equal(steps_new, steps) and np.array_equal(objects_new, objects):
            return steps, objects
        steps, objects = steps_new, objects_new


def positions_from_rotations(obs: RayObservations, R: np.ndarray, steps: np.ndarray,
                             objects: np.ndarray, *, noise: float, rounds: int = 3):
    """``(X, C, angle)``: object positions (M, 3) and step positions (N, 3) (NaN outside
    ``objects`` / ``steps``) from the rays of the ``steps`` to the ``objects`` with the steps'
    rotations ``R`` (N, 3, 3), up to a similarity (see the module's docstring), and each
    sighting's angle error [rad] (NaN where unused); ``noise`` [rad] scales the robust weight,
    ``rounds`` re-solves with the depths and weights of the last."""
    k = np.flatnonzero(steps[obs.step] & objects[obs.obj])
    t, i = obs.step[k], obs.obj[k]
    w = np.einsum("kij,kj->ki", R[t], obs.ray[k])
    s_idx = np.full(obs.n_steps, -1)
    s_idx[steps] = np.arange(steps.sum())
    o_idx = np.full(obs.n_objects, -1)
    o_idx[objects] = np.arange(objects.sum())
    n_s, n_o = int(steps.sum()), int(objects.sum())
    # the gauge: the step with the most sightings at the origin, its first object at depth 1
    counts = np.bincount(s_idx[t], minlength=n_s)
    s0 = int(np.argmax(counts))
    first = int(np.flatnonzero(s_idx[t] == s0)[0])
    o0 = o_idx[i[first]]
    x0 = w[first]
    free_o = np.ones(n_o, dtype=bool)
    free_o[o0] = False
    free_s = np.ones(n_s, dtype=bool)
    free_s[s0] = False
    col_o = np.full(n_o, -1)
    col_o[free_o] = np.arange(n_o - 1)
    col_s = np.full(n_s, -1)
    col_s[free_s] = n_o - 1 + np.arange(n_s - 1)
    n_cols = 3 * (n_o + n_s - 2)
    S = _skew(w)  # (K, 3, 3): rows S (X - C)
    scale = np.ones(len(k))
    X = C = None
    for _ in range(rounds):
        rows_o = o_idx[i]
        rows_s = s_idx[t]
        data, rr, cc = [], [], []
        rhs = np.zeros((len(k), 3))
        Ss = S * scale[:, None, None]
        for sign, idx, col in ((1.0, rows_o, col_o), (-1.0, rows_s, col_s)):
            on = col[idx] >= 0
            kk = np.flatnonzero(on)
            r = (3 * kk[:, None, None] + np.arange(3)[None, :, None]) * np.ones((1, 1, 3), int)
            c = (3 * col[idx[kk]][:, None, None] + np.arange(3)[None, None, :]) * np.ones(
                (1, 3, 1), int)
            data.append(sign * Ss[kk].ravel())
            rr.append(r.ravel())
            cc.append(c.ravel())
        fixed_o = rows_o == o0  # the gauge object's known part moves to the right-hand side
        rhs[fixed_o] -= np.einsum("kij,j->ki", Ss[fixed_o], x0)
        A = sparse.csr_matrix((np.concatenate(data), (np.concatenate(rr), np.concatenate(cc))),
                              shape=(3 * len(k), n_cols))
        N = (A.T @ A).tocsc() + sparse.identity(n_cols, format="csc") * 1e-12
        x = spsolve(N, A.T @ rhs.ravel())
        Xo = np.zeros((n_o, 3))
        Xo[free_o] = x[: 3 * (n_o - 1)].reshape(-1, 3)
        Xo[o0] = x0
        Cs = np.zeros((n_s, 3))
        Cs[free_s] = x[3 * (n_o - 1):].reshape(-1, 3)
        v = Xo[rows_o] - Cs[rows_s]
        depth = np.linalg.norm(v, axis=1)
        cos = np.einsum("kj,kj->k", v, w) / np.maximum(depth, 1e-12)
        angle = np.arccos(np.clip(cos, -1.0, 1.0))
        typical = np.median(depth[depth > 0]) if np.any(depth > 0) else 1.0
        robust = 1.0 / np.sqrt(1.0 + (angle / (3.0 * noise)) ** 2)
        scale = robust / np.maximum(depth, 0.05 * typical)
        X, C = Xo, Cs
    out_X = np.full((obs.n_objects, 3), np.nan)
    out_X[objects] = X
    out_C = np.full((obs.n_steps, 3), np.nan)
    out_C[steps] = C
    err = np.full(len(obs.step), np.nan)
    err[k] = angle
    return out_X, out_C, err
