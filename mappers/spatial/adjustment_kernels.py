"""Compiled loops of the 6-DoF viewpoint bundle adjustment (:mod:`mappers.spatial.adjustment`):
its normal equations and its Schur-complement step with the coupling kept per sighting.

The adjustment's Gauss-Newton system has a 6 x 6 block per step, a 3 x 3 block per object and a
6 x 3 coupling block per sighting. Held as a dense (N, 6, 3F) coupling, the objects' reduced
system ``S = blockdiag(V) - sum_t W_t^T U_t^-1 W_t`` costs ``N (6 * 3F)^2`` multiplications a
step (about 0.1 s at N = 1,300 steps and F = 44 objects), though a step couples only the dozen
objects it sees; the normal blocks as numpy expressions are a dozen (K, 3, 6) temporaries and
scatter-adds. Here each step adds its own sightings' products into ``S`` (``n_t^2`` blocks for
the ``n_t`` objects it sees), and the normal blocks are one loop over the sightings: the same
Schur complement (Triggs et al., *Bundle Adjustment — A Modern Synthesis*, 2000), summed in
another order (equal to rounding; tests/mappers/spatial/test_adjustment_kernels.py). numba is the
well-kept way to write such loops in Python (as :mod:`mappers.viewpoints.sparse_schur_kernels`);
they are compiled, and cached on disk, on first use (:mod:`mappers.core.jit`).
"""

from __future__ import annotations

import numpy as np

from mappers.core.jit import compiled_on_first_use

__all__ = ["normal_equations", "pose_steps", "reduced_system"]  # noqa: F822

__getattr__ = compiled_on_first_use(globals(), __all__, helpers=("add_normal_block",))


def add_normal_block(J, e, k, wk, g, U, row):  # pragma: no cover - compiled
    """Adds ``wk J^T e[k]`` into ``g[row]`` and ``wk J^T J`` into ``U[row]`` (``J`` (3, n))."""
    n = J.shape[1]
    for a in range(n):
        x = 0.0
        for r in range(3):
            x += J[r, a] * e[k, r]
        g[row, a] += wk * x
        for b in range(n):
            x = 0.0
            for r in range(3):
                x += J[r, a] * J[r, b]
            U[row, a, b] += wk * x


def _normal_equations(R, step, t, f, v, nv, vh, e, w, B, has_r, sr, sb,
                      U, g, V, h, W):  # pragma: no cover - compiled
    """The Gauss-Newton blocks of the weighted residuals ``w * |e|^2 / 2``, as
    :func:`mappers.spatial.adjustment.normal_blocks` sums them from
    :meth:`mappers.spatial.adjustment.Problem.jacobians`: for each sighting k (its step
    ``step[k]`` with rotation ``R[step[k]]``, that step's row ``t[k]`` of the poses, its object's
    row ``f[k]`` of the free objects or -1; offset ``v`` in the sensor's frame, its length ``nv``
    and direction ``vh``; residual ``e`` (3,); tangent basis ``B`` (3, 2); range noise ``sr`` and
    whether it has a range) the pose Jacobian ``Jc`` (3, 6) and the point's ``Jp`` (3, 3); adds
    ``w Jc^T Jc`` into ``U`` (N, 6, 6), ``w Jc^T e`` into ``g`` (N, 6), and for a free object
    ``w Jp^T Jp`` into ``V`` (F, 3, 3), ``w Jp^T e`` into ``h`` (F, 3) and writes ``w Jc^T Jp``
    to ``W[k]`` (K, 6, 3) (zero for a fixed object)."""
    de = np.empty((3, 3))
    Jp = np.empty((3, 3))
    Jc = np.empty((3, 6))
    for k in range(v.shape[0]):
        s = step[k]
        a = 1.0 / (nv[k] * sb)
        for b in range(2):  # B^T (I - vh vh^T) / (nv sb)
            x = B[k, 0, b] * vh[k, 0] + B[k, 1, b] * vh[k, 1] + B[k, 2, b] * vh[k, 2]
            for c in range(3):
                de[b, c] = (B[k, c, b] - x * vh[k, c]) * a
        for c in range(3):
            de[2, c] = vh[k, c] / sr[k] if has_r[k] else 0.0
        for r in range(3):
            for c in range(3):  # Jp = de R^T
                x = 0.0
                for j in range(3):
                    x += de[r, j] * R[s, c, j]
                Jp[r, c] = x
            # de [v]x, [v]x = [[0, -v2, v1], [v2, 0, -v0], [-v1, v0, 0]]
            Jc[r, 0] = de[r, 1] * v[k, 2] - de[r, 2] * v[k, 1]
            Jc[r, 1] = -de[r, 0] * v[k, 2] + de[r, 2] * v[k, 0]
            Jc[r, 2] = de[r, 0] * v[k, 1] - de[r, 1] * v[k, 0]
            for c in range(3):
                Jc[r, 3 + c] = -Jp[r, c]
        wk, tk, j = w[k], t[k], f[k]
        add_normal_block(Jc, e, k, wk, g, U, tk)
        if j < 0:
            for a6 in range(6):
                for c in range(3):
                    W[k, a6, c] = 0.0
            continue
        add_normal_block(Jp, e, k, wk, h, V, j)
        for a6 in range(6):
            for c in range(3):
                x = 0.0
                for r in range(3):
                    x += Jc[r, a6] * Jp[r, c]
                W[k, a6, c] = wk * x


def _reduced_system(Ui, W, f, indptr, g, S, rhs):  # pragma: no cover - compiled
    """Adds each step's part of the objects' reduced system: ``S -= W_t^T Ui_t W_t`` (``S``
    (3F, 3F)) and ``rhs += W_t^T Ui_t g_t`` (``rhs`` (3F,)), over the sightings
    ``indptr[t]:indptr[t + 1]`` of step t (``W`` (K, 6, 3), their free objects ``f``, -1 for
    a fixed one); ``Ui`` (N, 6, 6) the inverted (damped) pose blocks, ``g`` (N, 6)."""
    n = Ui.shape[0]
    longest = 0
    for t in range(n):
        longest = max(longest, indptr[t + 1] - indptr[t])
    Y = np.empty((longest, 6, 3))
    uig = np.empty(6)
    for t in range(n):
        lo, hi = indptr[t], indptr[t + 1]
        for a in range(6):
            x = 0.0
            for b in range(6):
                x += Ui[t, a, b] * g[t, b]
            uig[a] = x
        for k in range(lo, hi):
            j = f[k]
            if j < 0:
                continue
            for a in range(6):  # Y = Ui W_k
                for c in range(3):
                    x = 0.0
                    for b in range(6):
                        x += Ui[t, a, b] * W[k, b, c]
                    Y[k - lo, a, c] = x
            for c in range(3):
                x = 0.0
                for a in range(6):
                    x += W[k, a, c] * uig[a]
                rhs[3 * j + c] += x
        for k1 in range(lo, hi):
            j1 = f[k1]
            if j1 < 0:
                continue
            for k2 in range(lo, hi):
                j2 = f[k2]
                if j2 < 0:
                    continue
                for r in range(3):
                    for c in range(3):
                        x = 0.0
                        for a in range(6):
                            x += W[k1, a, r] * Y[k2 - lo, a, c]
                        S[3 * j1 + r, 3 * j2 + c] -= x


def _pose_steps(Ui, W, f, indptr, g, dp, dc):  # pragma: no cover - compiled
    """The poses' steps given the objects' ``dp`` (F, 3): ``dc[t] = -Ui_t (g_t + sum_k W_k
    dp[f_k])`` over step t's sightings (``dc`` (N, 6) overwritten)."""
    y = np.empty(6)
    for t in range(Ui.shape[0]):
        for a in range(6):
            y[a] = g[t, a]
        for k in range(indptr[t], indptr[t + 1]):
            j = f[k]
            if j < 0:
                continue
            for a in range(6):
                x = 0.0
                for c in range(3):
                    x += W[k, a, c] * dp[j, c]
                y[a] += x
        for a in range(6):
            x = 0.0
            for b in range(6):
                x += Ui[t, a, b] * y[b]
            dc[t, a] = -x
