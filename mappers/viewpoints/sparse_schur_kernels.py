"""Compiled loops of the sparse Schur step (:mod:`mappers.viewpoints.sparse_schur`) and of the
bearing adjustment's normal equations on it.

The conjugate gradients of the sparse step apply the objects' reduced system
``S = blockdiag(V) - W^T U^-1 W`` to a vector some ten to forty times a step. As three
``scipy.sparse`` block products (``W x``, ``U^-1 (W x)``, ``W^T (...)``) each pass reads the
million (3, 2) blocks of M = 1,000 objects over N = 20,000 steps with the library's generic
small-block loop, about 10 ms a product at that size; as one compiled loop over the
observations, ordered by step (``W x`` of a step, then ``U^-1`` of it, then ``W^T`` of it back
into the objects), it is a few milliseconds. Likewise the normal equations' blocks of the
bearing adjustment: as numpy expressions they are a dozen (K, 3, 3) temporaries and
eighteen scatter-adds over the K observations, about 0.5 s a round at that size, as one loop
a few tens of milliseconds. numba is the well-kept way to write such loops in Python (as
:mod:`mappers.viewpoints.view_cone_kernels`); they are compiled, and cached on disk, on first
use (:mod:`mappers.core.jit`). The loops sum in another order than the numpy expressions: equal
to rounding (tests/mappers/viewpoints/test_sparse_schur_kernels.py).
"""

from __future__ import annotations

import numpy as np

from mappers.core.jit import compiled_on_first_use

__all__ = ["bearing_blocks", "couple", "couple_transpose", "outer_sums",  # noqa: F822
           "schur_diagonal", "schur_matvec"]

__getattr__ = compiled_on_first_use(globals(), __all__, helpers=("block_products",))


def _schur_matvec(Ui, blocks, indptr, free, Vd, x, out):  # pragma: no cover - compiled
    """``out = Vd x - W^T Ui W x`` for the objects' vector ``x`` (F, d): ``Ui`` (N, p, p) the
    inverted (damped) pose blocks, ``blocks`` (K, p, d) the coupling's blocks ordered by step,
    ``indptr`` (N + 1,) where each step's blocks start, ``free`` (K,) their objects, ``Vd``
    (F, d, d) the (damped) object blocks; ``out`` (F, d) is overwritten. The planar case
    (p, d) = (3, 2) is written out (twice as fast as the loops over p and d)."""
    n, p = Ui.shape[0], Ui.shape[1]
    f, d = Vd.shape[0], Vd.shape[1]
    for j in range(f):
        for r in range(d):
            s = 0.0
            for c in range(d):
                s += Vd[j, r, c] * x[j, c]
            out[j, r] = s
    if p == 3 and d == 2:
        for t in range(n):
            lo, hi = indptr[t], indptr[t + 1]
            y0 = y1 = y2 = 0.0
            for k in range(lo, hi):
                j = free[k]
                x0, x1 = x[j, 0], x[j, 1]
                y0 += blocks[k, 0, 0] * x0 + blocks[k, 0, 1] * x1
                y1 += blocks[k, 1, 0] * x0 + blocks[k, 1, 1] * x1
                y2 += blocks[k, 2, 0] * x0 + blocks[k, 2, 1] * x1
            z0 = Ui[t, 0, 0] * y0 + Ui[t, 0, 1] * y1 + Ui[t, 0, 2] * y2
            z1 = Ui[t, 1, 0] * y0 + Ui[t, 1, 1] * y1 + Ui[t, 1, 2] * y2
            z2 = Ui[t, 2, 0] * y0 + Ui[t, 2, 1] * y1 + Ui[t, 2, 2] * y2
            for k in range(lo, hi):
                j = free[k]
                out[j, 0] -= blocks[k, 0, 0] * z0 + blocks[k, 1, 0] * z1 + blocks[k, 2, 0] * z2
                out[j, 1] -= blocks[k, 0, 1] * z0 + blocks[k, 1, 1] * z1 + blocks[k, 2, 1] * z2
        return
    y = np.zeros(p)
    z = np.zeros(p)
    for t in range(n):
        lo, hi = indptr[t], indptr[t + 1]
        if lo == hi:
            continue
        for a in range(p):
            y[a] = 0.0
        for k in range(lo, hi):
            j = free[k]
            for a in range(p):
                s = 0.0
                for c in range(d):
                    s += blocks[k, a, c] * x[j, c]
                y[a] += s
        for a in range(p):
            s = 0.0
            for b in range(p):
                s += Ui[t, a, b] * y[b]
            z[a] = s
        for k in range(lo, hi):
            j = free[k]
            for c in range(d):
                s = 0.0
                for a in range(p):
                    s += blocks[k, a, c] * z[a]
                out[j, c] -= s


def _schur_diagonal(Ui, blocks, step, free, Vd, out):  # pragma: no cover - compiled
    """The preconditioner's blocks: ``out[j] = Vd[j] - sum over the blocks k of object j of
    W_k^T Ui_t W_k`` (F, d, d), overwritten."""
    p, d = blocks.shape[1], blocks.shape[2]
    for j in range(out.shape[0]):
        for r in range(d):
            for c in range(d):
                out[j, r, c] = Vd[j, r, c]
    for k in range(blocks.shape[0]):
        t, j = step[k], free[k]
        for r in range(d):
            for c in range(d):
                s = 0.0
                for a in range(p):
                    u = 0.0
                    for b in range(p):
                        u += Ui[t, a, b] * blocks[k, b, c]
                    s += blocks[k, a, r] * u
                out[j, r, c] -= s


def block_products(blocks, into, by, x, out, transposed):  # pragma: no cover - compiled
    """``out[into[k]] += B_k @ x[by[k]]`` for each block k, ``B_k`` = ``blocks[k]`` (p, d) or,
    ``transposed``, its transpose (``x`` (., d) or (., p), ``out`` (., p) or (., d)): the one
    loop of :func:`couple` and :func:`couple_transpose`. The transpose is read in place:
    numba's ``ndarray.transpose`` compiles its argument checks' messages, seconds on first use."""
    rows, cols = blocks.shape[1], blocks.shape[2]
    if transposed:
        rows, cols = cols, rows
    for k in range(blocks.shape[0]):
        i, j = into[k], by[k]
        for a in range(rows):
            s = 0.0
            for c in range(cols):
                s += (blocks[k, c, a] if transposed else blocks[k, a, c]) * x[j, c]
            out[i, a] += s


def _couple(blocks, step, free, x, out):  # pragma: no cover - compiled
    """``out += W x``: each step's (p,) sum of its blocks times their objects' ``x`` (F, d)."""
    block_products(blocks, step, free, x, out, False)


def _couple_transpose(blocks, step, free, v, out):  # pragma: no cover - compiled
    """``out += W^T v``: each object's (d,) sum of its blocks' transposes times their steps'
    ``v`` (N, p)."""
    block_products(blocks, free, step, v, out, True)


def _bearing_blocks(d, res, w, t, f, U, g, V, h, blocks, bstep, bfree):  # pragma: no cover
    """The bearing adjustment's normal equations (as
    :func:`mappers.viewpoints.engine.normal_blocks`): for each observation k (offset ``d[k]``
    object - viewpoint, angle residual ``res[k]``, weight ``w[k]``, step ``t[k]``, free object
    ``f[k]`` or -1) the pose Jacobian ``a = (dy, -dx, -r^2) / r^2``, the object's ``b = -a[:2]``;
    adds ``w a a^T`` into ``U`` (N, 3, 3), ``w res a`` into ``g`` (N, 3), and for a free object
    ``w b b^T`` into ``V`` (F, 2, 2), ``w res b`` into ``h`` (F, 2) and writes ``w a b^T`` as the
    next of ``blocks`` (K_free, 3, 2) with its step and object in ``bstep``, ``bfree``. With
    every ``f[k] = -1`` (and empty object arrays) it sums the poses' part alone: the resection's
    Gauss-Newton system (:func:`mappers.viewpoints.engine.resect`)."""
    kk = 0
    a = np.array([0.0, 0.0, -1.0])
    for k in range(d.shape[0]):
        dx, dy = d[k, 0], d[k, 1]
        r2 = max(dx * dx + dy * dy, 1e-12)
        a[0], a[1] = dy / r2, -dx / r2
        wk, tk = w[k], t[k]
        wr = wk * res[k]
        for r in range(3):
            g[tk, r] += wr * a[r]
            for c in range(3):
                U[tk, r, c] += wk * a[r] * a[c]
        j = f[k]
        if j < 0:
            continue
        for r in range(2):
            h[j, r] -= wr * a[r]
            for c in range(2):
                V[j, r, c] += wk * a[r] * a[c]
        for r in range(3):
            for c in range(2):
                blocks[kk, r, c] = -wk * a[r] * a[c]
        bstep[kk], bfree[kk] = tk, j
        kk += 1


def _outer_sums(rows, t, out):  # pragma: no cover - compiled
    """Adds each row's outer product ``rows[k] rows[k]^T`` into ``out[t[k]]`` (N, q, q): the
    normal matrices of the closed-form resection
    (:func:`mappers.viewpoints.engine.initial_poses`)."""
    q = rows.shape[1]
    for k in range(rows.shape[0]):
        tk = t[k]
        for r in range(q):
            for c in range(q):
                out[tk, r, c] += rows[k, r] * rows[k, c]
