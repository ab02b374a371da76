"""Forward-backward over a grid of candidate viewpoints: VIS-BA-WALK's continuity prior.

The steps of a walk's history are ordered: consecutive viewpoints lie close together. Read as a
hidden Markov model, the viewpoint is a cell of a square grid (spacing ``h``), the bits of a step
are its emission, and a move is an isotropic Gaussian random walk of width ``sigma`` [m] per axis,
restricted to the cells kept (the cells some step may have visited) and renormalised there. The
first step of each run of consecutive steps starts from ``init`` (the learnt occupancy).

:func:`forward_backward` runs the scaled recursion (each step's filtered distribution is
normalised and the log of its normaliser summed: the marginal log-likelihood) and returns each
step's smoothed posterior over the cells and the expected squared displacement between
consecutive steps (the EM statistic of ``sigma``). The Gaussian is applied as two 1-D
convolutions on the full rectangular grid (the kept cells scattered into it), only over the
bounding box of the cells that carry mass (above :data:`CUTOFF` of the largest), with loops
along contiguous rows that the compiler vectorises. The loops are compiled with
numba on first use (:mod:`mappers.core.jit`: the other mappers should not pay for importing
numba) and cached on disk.
"""

from __future__ import annotations

import math

import numpy as np

from mappers.core.jit import compile_in_place

__all__ = ["forward_backward", "gaussian_taps"]

CUTOFF = 1e-6
"""Mass below this share of a step's largest cell is left out of its convolution (the
posteriors move by about 0.3 % of a cell's probability at most on our histories)."""

WIDTH = 3.0
"""The transition's taps reach this many ``sigma`` (a Gaussian truncated there; the recursion
is exact for that kernel)."""

_compiled: dict = {}


def gaussian_taps(sigma: float, h: float, width: float = WIDTH) -> tuple[np.ndarray, np.ndarray]:
    """The 1-D Gaussian of width ``sigma`` [m] on a grid of spacing ``h`` [m], truncated at
    ``width * sigma`` (at least one cell each side) and normalised: ``(k, kd2)``, the taps and
    the taps times the squared offset [m^2]."""
    if not (sigma > 0 and h > 0 and math.isfinite(sigma) and math.isfinite(h)):
        raise ValueError(f"sigma and h must be positive and finite, got {sigma!r}, {h!r}")
    r = max(1, int(math.ceil(width * sigma / h)))
    off = np.arange(-r, r + 1) * h
    k = np.exp(-0.5 * (off / sigma) ** 2)
    k /= k.sum()
    return k, k * off**2


def forward_backward(E, top, init, cells, shape, sigma, h, starts, *, want_disp=True,
                     cutoff=CUTOFF, width=WIDTH):
    """Smoothed posteriors of an HMM over grid cells with a Gaussian random-walk transition.

    Args:
        E: (N, G) float32 emission likelihoods of each step at each kept cell, up to a factor
            per step, ``exp(log_lik - top)``.
        top: (N,) float64 the per-step factors' logs (added back into the marginal likelihood).
        init: (G,) float64 initial distribution of a run's first step (sums to 1).
        cells: (G,) int64 indices of the kept cells in the full grid of ``shape`` (x-major).
        shape: (nx, ny) of the full grid.
        sigma: random-walk width per axis [m]; h the grid spacing [m].
        starts: (N,) bool, True where a step starts a run (its predecessor is not linked).
        want_disp: compute ``disp`` (two more convolutions per step of the backward pass).
        cutoff: mass below this share of a step's largest cell is left out of the step's
            convolution (0: none; the posteriors then are exact).
        width: the Gaussian's taps reach ``width * sigma`` (at least one cell).

    Returns:
        ``(post, loglik, disp)``: (N, G) float32 posteriors (rows sum to 1), the marginal
        log-likelihood, and the expected squared displacement [m^2] summed over the links
        (0 when not ``want_disp``).
    """
    k, kd2 = gaussian_taps(sigma, h, width)
    nx, ny = int(shape[0]), int(shape[1])
    cells = np.ascontiguousarray(cells, dtype=np.int64)
    starts = np.asarray(starts, dtype=bool)
    n = len(starts)
    if np.shape(E) != (n, len(cells)) or np.shape(top) != (n,) or np.shape(init) != cells.shape:
        raise ValueError(f"E must be (steps, cells) = ({n}, {len(cells)}), top ({n},) and init "
                         f"({len(cells)},); got {np.shape(E)}, {np.shape(top)}, {np.shape(init)}")
    if n == 0 or not starts[0]:
        raise ValueError("starts[0] must be True (the first step starts a run)")
    if cells.size and (cells.min() < 0 or cells.max() >= nx * ny):
        raise ValueError(f"cells must index the {nx} x {ny} grid")
    if "fb" not in _compiled:
        _compile()
    return _compiled["fb"](np.ascontiguousarray(E, dtype=np.float32),
                           np.ascontiguousarray(top, dtype=np.float64),
                           np.ascontiguousarray(init, dtype=np.float64), cells, nx, ny, k, kd2,
                           np.ascontiguousarray(starts), float(cutoff),
                           bool(want_disp))


def _compile() -> None:
    """Compile the loops below (the helpers first: the compiled recursion calls them as globals)
    and keep the recursion in ``_compiled``."""
    g = globals()
    compile_in_place(g, ("_conv_rows", "_conv", "_scatter", "_gather", "_unscatter",
                         "_forward_backward"), fastmath=True)
    _compiled["fb"] = g["_forward_backward"]


def _conv_rows(src, dst, taps, lo, hi, in_lo, in_hi, c0, c1):  # pragma: no cover - compiled
    """``dst[i, c0:c1+1] = sum_j taps[i - j + r] * src[j, c0:c1+1]`` for each row ``i`` in
    [lo, hi], over the rows ``j`` in [in_lo, in_hi] within the taps' radius ``r`` of ``i``: one
    1-D convolution along the first axis, written along contiguous rows (the compiler
    vectorises the innermost loop)."""
    r = (len(taps) - 1) // 2
    for i in range(lo, hi + 1):
        out = dst[i]
        for c in range(c0, c1 + 1):
            out[c] = 0.0
        for j in range(max(i - r, in_lo), min(i + r, in_hi) + 1):
            kk = taps[i - j + r]
            row = src[j]
            for c in range(c0, c1 + 1):
                out[c] += kk * row[c]


def _conv(src, tmp, tmp_t, dst_t, box, kx, ky, nx, ny):  # pragma: no cover - compiled
    """``dst_t = ((kx in x, ky in y) * src)`` transposed (indexed ``[y, x]``) over ``box`` (x0,
    x1, y0, y1, inclusive: where ``src`` may be non-zero) widened by the taps' radius and cut to
    the grid; returns that box. Both passes run along contiguous rows (the second on the
    transposed intermediate). ``tmp`` and ``tmp_t`` are zero on entry and on return."""
    r = (len(kx) - 1) // 2
    x0, x1, y0, y1 = box
    X0, X1, Y0, Y1 = max(x0 - r, 0), min(x1 + r, nx - 1), max(y0 - r, 0), min(y1 + r, ny - 1)
    _conv_rows(src, tmp, kx, X0, X1, x0, x1, y0, y1)  # along x, over the support's columns
    for ix in range(X0, X1 + 1):
        for iy in range(y0, y1 + 1):
            tmp_t[iy, ix] = tmp[ix, iy]
            tmp[ix, iy] = 0.0
    _conv_rows(tmp_t, dst_t, ky, Y0, Y1, y0, y1, X0, X1)  # along y, on the transposed rows
    for jy in range(y0, y1 + 1):
        for ix in range(X0, X1 + 1):
            tmp_t[jy, ix] = 0.0
    return X0, X1, Y0, Y1


def _scatter(vals, cx, cy, full, cutoff):  # pragma: no cover - compiled
    """Write the cells of ``vals`` above ``cutoff`` times the largest into ``full`` (at ``cx``,
    ``cy``); returns their bounding box (x0 > x1 when none)."""
    top = 0.0
    for g in range(len(vals)):
        top = max(top, vals[g])
    cut = top * cutoff
    x0, x1, y0, y1 = 1 << 30, -1, 1 << 30, -1
    for g in range(len(vals)):
        if vals[g] > cut:
            ix, iy = cx[g], cy[g]
            full[ix, iy] = vals[g]
            x0, x1, y0, y1 = min(x0, ix), max(x1, ix), min(y0, iy), max(y1, iy)
    return x0, x1, y0, y1


def _gather(full_t, box, cx, cy, out):  # pragma: no cover - compiled
    """``out`` = the transposed ``full_t`` at the kept cells inside ``box``, 0 outside it."""
    x0, x1, y0, y1 = box
    for g in range(len(cx)):
        ix, iy = cx[g], cy[g]
        out[g] = full_t[iy, ix] if (x0 <= ix <= x1 and y0 <= iy <= y1) else 0.0


def _unscatter(full, cx, cy):  # pragma: no cover - compiled
    for g in range(len(cx)):
        full[cx[g], cy[g]] = 0.0


def _forward_backward(E, top, init, cells, nx, ny, k, kd2, starts, cutoff,
                      want_disp):  # pragma: no cover - compiled
    n, g = E.shape
    cx, cy = cells // ny, cells % ny
    src, tmp = np.zeros((nx, ny)), np.zeros((nx, ny))
    tmp_t, dst, dst2 = np.zeros((ny, nx)), np.zeros((ny, nx)), np.zeros((ny, nx))
    # the normaliser of a move from each kept cell: sum over kept j of K(i, j)
    for q in range(g):
        src[cx[q], cy[q]] = 1.0
    norm = np.empty(g)
    # the whole grid's box, typed as _scatter's (a literal 0 would compile _conv once more)
    whole = (nx - nx, nx - 1, ny - ny, ny - 1)
    _gather(dst, _conv(src, tmp, tmp_t, dst, whole, k, k, nx, ny), cx, cy, norm)
    _unscatter(src, cx, cy)
    for q in range(g):
        norm[q] = 1.0 / max(norm[q], 1e-300)
    alpha = np.empty((n, g))
    scale = np.empty(n)
    pred = np.empty(g)
    vals = np.empty(g)
    loglik = 0.0
    for t in range(n):
        if starts[t]:
            for q in range(g):
                pred[q] = init[q]
        else:
            for q in range(g):
                vals[q] = alpha[t - 1, q] * norm[q]
            box = _conv(src, tmp, tmp_t, dst, _scatter(vals, cx, cy, src, cutoff), k, k, nx, ny)
            _gather(dst, box, cx, cy, pred)
            _unscatter(src, cx, cy)
        c = 0.0
        for q in range(g):
            alpha[t, q] = pred[q] * E[t, q]
            c += alpha[t, q]
        if not c > 0.0:  # the step's bits rule out every cell the walk allows: restart it
            c = 0.0
            for q in range(g):
                alpha[t, q] = init[q] * E[t, q]
                c += alpha[t, q]
            c = max(c, 1e-300)
        for q in range(g):
            alpha[t, q] /= c
        scale[t] = c
        loglik += math.log(c) + top[t]
    post = np.empty((n, g), dtype=np.float32)
    beta = np.ones(g)
    disp = 0.0
    for q in range(g):
        post[n - 1, q] = alpha[n - 1, q]
    for t in range(n - 2, -1, -1):
        if starts[t + 1]:
            for q in range(g):
                beta[q] = 1.0
        else:
            for q in range(g):
                vals[q] = E[t + 1, q] * beta[q] / scale[t + 1]
            sbox = _scatter(vals, cx, cy, src, cutoff)
            _gather(dst, _conv(src, tmp, tmp_t, dst, sbox, k, k, nx, ny), cx, cy, beta)
            if want_disp:  # sum_i alpha_i norm_i sum_j K(i, j) |g_i - g_j|^2 vals_j
                _gather(dst, _conv(src, tmp, tmp_t, dst, sbox, kd2, k, nx, ny), cx, cy, pred)
                _gather(dst2, _conv(src, tmp, tmp_t, dst2, sbox, k, kd2, nx, ny), cx, cy, vals)
                for q in range(g):
                    disp += alpha[t, q] * norm[q] * (pred[q] + vals[q])
            _unscatter(src, cx, cy)
            for q in range(g):
                beta[q] *= norm[q]
        s = 0.0
        for q in range(g):
            s += alpha[t, q] * beta[q]
        s = max(s, 1e-300)
        for q in range(g):
            post[t, q] = alpha[t, q] * beta[q] / s
    return post, loglik, disp
