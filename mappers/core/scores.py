"""Map scores (paper §4.3.2): mean position error (MPE) and mean orientation error (MOE)."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

__all__ = ["mean_orientation_error", "mean_position_error", "sampled_orientation_error"]


def check_scored_pair(estimate, truth, exclude, dim: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """The rows of ``estimate`` and ``truth`` (both (M, ``dim``)) that a score compares: all but
    the object ids in ``exclude`` (integers in [-M, M)). ValueError naming the problem for a
    wrong shape, a bad id, or a NaN/inf row left in (an unmapped object must be excluded). The
    2-D and 3-D scores (:mod:`mappers.core.scores_3d`) share it."""
    est = np.asarray(estimate, dtype=float)
    tru = np.asarray(truth, dtype=float)
    if est.ndim != 2 or est.shape[1] != dim:
        hint = (": a 3-D map is scored by mappers.mean_position_error_3d and "
                "mappers.tetrahedron_orientation_error"
                if dim == 2 and est.ndim == 2 and est.shape[1] == 3 else "")
        raise ValueError(f"estimate must have shape (M, {dim}), got {est.shape}{hint}")
    if tru.shape != est.shape:
        raise ValueError(f"truth must have the shape of estimate {est.shape}, got {tru.shape}")
    keep = np.ones(len(est), dtype=bool)
    if exclude is not None:
        ex = np.asarray(list(exclude) if not isinstance(exclude, np.ndarray) else exclude)
        if ex.size:
            if not np.issubdtype(ex.dtype, np.integer):
                raise ValueError(f"exclude must hold integer object ids, got dtype {ex.dtype}")
            if ex.min() < -len(est) or ex.max() >= len(est):
                raise ValueError(f"exclude ids out of range for M={len(est)}: {ex.tolist()}")
            keep[ex] = False
    est, tru = est[keep], tru[keep]
    for name, arr in (("estimate", est), ("truth", tru)):
        bad = np.flatnonzero(~np.all(np.isfinite(arr), axis=1))
        if bad.size:
            raise ValueError(
                f"{name} has NaN/inf rows (object ids among the kept rows: {bad.tolist()[:10]}); "
                "pass them in exclude= (e.g. exclude=map.unmapped)"
            )
    return est, tru


def mean_position_error(
    estimate: np.ndarray, truth: np.ndarray, exclude: Iterable[int] | None = None
) -> float:
    """Mean Euclidean distance [m] between estimated and true positions (MPE).

    ``exclude`` lists object ids left out (e.g. the anchors, to score non-anchor objects only).
    NaN rows (unmapped objects) must be excluded explicitly: they raise ValueError.
    """
    est, tru = check_scored_pair(estimate, truth, exclude)
    if len(est) == 0:
        raise ValueError("no objects left to score after exclude")
    return float(np.mean(np.linalg.norm(est - tru, axis=1)))


def _signs_from(P: np.ndarray, i: int) -> np.ndarray:
    """sign((p_j - p_i) x (p_k - p_i)) for all j, k > i: an antisymmetric (n-i-1)^2 block."""
    d = P[i + 1 :] - P[i]
    cross = np.multiply.outer(d[:, 0], d[:, 1])
    cross -= cross.T  # dx_j dy_k - dy_j dx_k
    return np.sign(cross)


def _moe_bruteforce(est: np.ndarray, tru: np.ndarray) -> int:
    """Number of triangles whose orientation differs: the exact O(M^3) reference.

    For each first vertex i, one (M-i-1)^2 block of signed areas over all later pairs (j, k),
    so memory stays O(M^2) (about 100 MB at M = 2000). This defines the orientations the fast
    path reproduces: apex = smallest index, d_j = fl(p_j - p_i), and the sign of
    fl(dx_j dy_k) - fl(dx_k dy_j).
    """
    wrong = 0
    for i in range(len(est) - 2):
        wrong += _wrong_at_apex(est, tru, i)
    return wrong


def _wrong_at_apex(est: np.ndarray, tru: np.ndarray, i: int) -> int:
    # The block is antisymmetric with a zero diagonal, so every triangle (i, j, k), j < k,
    # appears twice in the mismatch count.
    return int(np.count_nonzero(_signs_from(est, i) != _signs_from(tru, i))) // 2


# Folded directions closer than this (mod pi) are near ties, settled by exact cross products. It
# only has to exceed the error of arctan2 plus the fold (a few ulps of pi, ~1e-15); a larger
# value only costs more exact checks.
_TIE_TOL = 1e-10
# With every non-zero coordinate difference in this range, each product dx_j dy_k is a normal
# float, so fl(cross) differs from the exact cross product of the differences only within about
# 1e-16 rad of a tie. An apex outside it (absurd scales) goes to the brute force.
_SAFE_LO, _SAFE_HI = 1e-150, 1e150
_BATCH = 1 << 16  # (apex, point) entries, or exactly checked pairs, per numpy batch
# An apex whose exact checks exceed 1/_BRUTE_SHARE of its pairs goes to the brute-force block
# (a checked pair costs several times a brute-force one); 0 turns this off.
_BRUTE_SHARE = 8
# Below this many objects the O(M^3) block is as fast or faster (0.6 ms both at M = 50, 11 ms
# both at M = 200; 54 vs 20 ms at M = 300), so mean_orientation_error uses it there.
_FAST_FROM = 200


def _mismatch(d: tuple[np.ndarray, ...], f1: np.ndarray, f2: np.ndarray) -> np.ndarray:
    """Whether the reference's signs, sign(fl(dx_j dy_k) - fl(dx_k dy_j)), differ between the
    estimate and the truth for the entry pairs with flat indices f1, f2; d = (dxe, dye, dxt, dyt)
    raveled."""
    dxe, dye, dxt, dyt = d
    e = np.sign(dxe[f1] * dye[f2] - dxe[f2] * dye[f1])
    return e != np.sign(dxt[f1] * dyt[f2] - dxt[f2] * dyt[f1])


def _angular_model(dx: np.ndarray, dy: np.ndarray, usable: np.ndarray, m: np.ndarray):
    """Order each row's usable directions around its apex, folded mod pi, and find near ties.

    Returns, per entry, ``pos`` (rank in the folded order) and ``sgn`` (+-1 fold flag), so that
    the model orientation of entries (j, k) is sign(pos_k - pos_j) sgn_j sgn_k, and ``cl`` (the
    id of its near-tie cluster); per rank, ``rot`` (the entry with that rank) and ``clr`` (its
    cluster id, non-decreasing along the row, so clusters are runs). The m usable entries of a
    row take ranks 0..m-1; the others follow, each in a cluster of its own.
    """
    R, w = dx.shape
    a = np.arctan2(dy, dx)
    up = a >= 0
    ang = np.where(up, a, a + np.pi)  # a -> a + pi flips the orientation sign, hence sgn
    ang[~usable] = np.inf
    order = np.argsort(ang, axis=1)
    sv = np.take_along_axis(ang, order, axis=1)
    q = np.arange(w)
    inside = q < m[:, None]
    rows = np.arange(R)
    lastq = np.maximum(m - 1, 0)
    bnd = np.ones((R, w), dtype=bool)
    with np.errstate(invalid="ignore"):  # inf - inf among the unusable entries
        bnd[:, 1:] = np.diff(sv, axis=1) > _TIE_TOL
        wrap_gap = sv[rows, 0] + np.pi - sv[rows, lastq]
    bnd |= ~inside
    cid = np.cumsum(bnd, axis=1) - 1
    last = cid[rows, lastq]
    # Directions just below pi are near ties of those just above 0: move that last cluster to the
    # front (angle - pi with the flag flipped, which keeps every model orientation) as part of
    # cluster 0.
    wrap = (m >= 2) & (last > 0) & (wrap_gap <= _TIE_TOL)
    t = np.where(wrap, np.count_nonzero((cid < last[:, None]) & inside, axis=1), m)[:, None]
    tail = inside & (q >= t)
    rank = np.where(tail, q - t, np.where(inside, q + (m[:, None] - t), q))
    sg = np.where(np.take_along_axis(up, order, axis=1), 1, -1).astype(np.int8)
    sg[tail] *= -1
    cid[tail] = 0
    off = (rows * w)[:, None]
    at_entry = (order + off).ravel()
    at_rank = (rank + off).ravel()
    pos, sgn, cl, rot, clr = (np.empty_like(x) for x in (rank, sg, cid, order, cid))
    pos.ravel()[at_entry] = rank.ravel()
    sgn.ravel()[at_entry] = sg.ravel()
    cl.ravel()[at_entry] = cid.ravel()
    rot.ravel()[at_rank] = order.ravel()
    clr.ravel()[at_rank] = cid.ravel()
    return pos, sgn, cl, rot, clr


def _cluster_runs(clr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flat (row-major) indices of ranks in clusters of 2 or more, and per such rank the number
    of later members of its cluster (the near-tie pairs it starts)."""
    R, w = clr.shape
    key = (clr + np.arange(R)[:, None] * w).ravel()
    same = key[1:] == key[:-1]
    in_run = np.zeros(key.size, dtype=bool)
    in_run[1:] |= same
    in_run[:-1] |= same
    S = np.flatnonzero(in_run)
    kS = key[S]
    return S, np.searchsorted(kS, kS, side="right") - np.arange(S.size) - 1


def _scatter(a: np.ndarray, to: np.ndarray) -> np.ndarray:
    out = np.empty_like(a)
    out.ravel()[to] = a.ravel()
    return out


def _inversions(y: np.ndarray, rho: np.ndarray) -> tuple[int, int, int]:
    """Inversions (j before k, y_j > y_k) summed over rows: all, within rho=+1, within rho=-1.

    Each row of ``y`` must be a permutation of 0..w-1 whose rho=0 elements (padding) come last
    and are not inverted with anything. Written by hand because numpy has no inversion count and
    scipy only a float Kendall tau for one pair of sequences (a Python call per apex). This is a
    wavelet-tree pass, vectorised over rows: level by level from the top bit, the elements of a
    group of equal higher bits (the group with prefix v starts at v * 2^(b+1), as rows are
    permutations) are stably split by bit b; each 0-bit element is inverted with the 1-bit
    elements before it in its group. O(w log w) per row.
    """
    R, w = y.shape
    off = (np.arange(R, dtype=np.int64) * w)[:, None]
    col = np.arange(w)
    low = (1 << 32) - 1
    cur = y.astype(np.int64)
    plus = (rho == 1).astype(np.int64)
    minus = (rho == -1).astype(np.int64)
    inv_all = inv_p = inv_m = 0
    for b in range((w - 1).bit_length() - 1, -1, -1):
        bit = (cur >> b) & 1
        start = (cur >> (b + 1)) << (b + 1)
        # one cumsum counts the 1-bits before each element (low 32 bits) and those with rho=+1
        packed = bit | ((bit & plus) << 32)
        before = np.cumsum(packed, axis=1)
        before -= packed
        before -= before.ravel()[(start + off).ravel()].reshape(R, w)  # ... within its group
        ones = before & low
        ones_p = before >> 32
        zero = 1 - bit
        inv_all += int(np.vdot(ones, zero))
        inv_p += int(np.vdot(ones_p, zero & plus))
        # padding never precedes a rho=-1 element, so its other 1-bits have rho=-1
        inv_m += int(np.vdot(ones - ones_p, zero & minus))
        new = np.where(bit, start + np.minimum(1 << b, w - start) + ones, col - ones)
        new = (new + off).ravel()
        cur, plus, minus = (_scatter(x, new) for x in (cur, plus, minus))
    return inv_all, inv_p, inv_m


def _wrong_in_rows(est: np.ndarray, tru: np.ndarray, i0: int, i1: int) -> int:
    """Wrong triangles whose smallest index (the apex) is in [i0, i1); see _moe_fast."""
    n = len(est)
    R, w = i1 - i0, n - i0 - 1
    r_of = np.arange(R)[:, None]
    valid = np.arange(w) >= r_of  # entry (r, c): apex i0 + r, point i0 + 1 + c
    dxe, dye = (est[None, i0 + 1 :, k] - est[i0:i1, None, k] for k in (0, 1))
    dxt, dyt = (tru[None, i0 + 1 :, k] - tru[i0:i1, None, k] for k in (0, 1))
    brute = np.zeros(R, dtype=bool)  # rows left to _wrong_at_apex
    for d in (dxe, dye, dxt, dyt):
        ad = np.abs(d)
        brute |= np.any(valid & (ad != 0) & ((ad < _SAFE_LO) | (ad > _SAFE_HI)), axis=1)
    zero = valid & ~brute[:, None] & (((dxe == 0) & (dye == 0)) | ((dxt == 0) & (dyt == 0)))
    usable = valid & ~brute[:, None] & ~zero
    m = np.count_nonzero(usable, axis=1)
    pe, se, cle, rote, clre = _angular_model(dxe, dye, usable, m)
    pt, st, clt, rott, clrt = _angular_model(dxt, dyt, usable, m)
    runs = [_cluster_runs(clre), _cluster_runs(clrt)]
    d = tuple(x.ravel() for x in (dxe, dye, dxt, dyt))

    # Rows where the exact checks would cost more than the brute force's block (nearly all
    # points collinear with, or equal to, the apex) go to the brute force.
    checks = np.count_nonzero(zero, axis=1) * (w - r_of[:, 0])
    for S, cnt in runs:
        checks += np.bincount(S // w, weights=cnt, minlength=R).astype(np.int64)
    brute |= _BRUTE_SHARE * checks > (w - r_of[:, 0]) ** 2
    zero &= ~brute[:, None]
    for k, (S, cnt) in enumerate(runs):
        keep = ~brute[S // w]
        runs[k] = (S[keep], cnt[keep])
    wrong = sum(_wrong_at_apex(est, tru, i0 + int(r)) for r in np.flatnonzero(brute))

    # Model count. In estimate order, take the truth ranks y and rho = sgn_e sgn_t: a pair is
    # wrong iff it is inverted in y within a rho group, or not inverted across the two groups:
    # inv(+) + inv(-) + (n+ n- - (inv(all) - inv(+) - inv(-))).
    y = np.empty_like(pe)
    rho = np.empty_like(se)
    at = (pe + r_of * w).ravel()
    y.ravel()[at] = pt.ravel()
    rho.ravel()[at] = (se * st).ravel()
    pad = (np.arange(w) >= m[:, None]) | brute[:, None]
    y[pad] = np.broadcast_to(np.arange(w), (R, w))[pad]
    rho[pad] = 0
    inv_all, inv_p, inv_m = _inversions(y, rho)
    n_p = np.count_nonzero(rho == 1, axis=1)
    n_m = np.count_nonzero(rho == -1, axis=1)
    wrong += 2 * (inv_p + inv_m) - inv_all + int(np.dot(n_p, n_m))

    wrong += _near_tie_corrections(runs, (rote, rott), cle, d, (pe, se, pt, st), w)
    return wrong + _wrong_with_equal_points(zero, d, w)


def _near_tie_corrections(runs, rots, cle, d, model, w: int) -> int:
    """Near ties: each pair in a cluster of either configuration (once) swaps its model verdict
    for the exact one; returns the change in the count of wrong triangles (see _wrong_in_rows)."""
    pe_, se_, pt_, st_ = (x.ravel() for x in model)
    change = 0
    for (S, cnt), rot, other_cl in zip(runs, rots, (None, cle), strict=True):
        ends = np.cumsum(cnt)
        lo = 0
        while lo < S.size:
            hi = min(S.size, max(lo + 1, int(np.searchsorted(ends, ends[lo] - cnt[lo] + _BATCH))))
            c = cnt[lo:hi]
            first = np.repeat(np.arange(lo, hi), c)
            second = first + 1 + np.arange(first.size) - np.repeat(np.cumsum(c) - c, c)
            f1, f2 = S[first], S[second]  # flat ranks -> flat entries
            row_off = f1 - f1 % w
            f1, f2 = row_off + rot.ravel()[f1], row_off + rot.ravel()[f2]
            if other_cl is not None:  # pairs also tied in the estimate were done there
                keep = other_cl.ravel()[f1] != other_cl.ravel()[f2]
                f1, f2 = f1[keep], f2[keep]
            me = np.sign(pe_[f2] - pe_[f1]) * se_[f1] * se_[f2]
            mt = np.sign(pt_[f2] - pt_[f1]) * st_[f1] * st_[f2]
            change += int(np.count_nonzero(_mismatch(d, f1, f2))) - int(np.count_nonzero(me != mt))
            lo = hi
    return change


def _wrong_with_equal_points(zero, d, w: int) -> int:
    """Points equal to the apex in either configuration are outside the model: all their pairs
    are checked exactly (a pair of two such points once); returns their wrong triangles."""
    wrong = 0
    zr, zc = np.nonzero(zero)
    cols = np.arange(w)
    step = max(1, _BATCH // w)
    for s in range(0, zr.size, step):
        r, c = zr[s : s + step, None], zc[s : s + step, None]
        ok = (cols >= r) & (cols != c) & ~(zero[r, cols] & (cols < c))
        f1, f2 = (np.broadcast_to(r * w + x, ok.shape)[ok] for x in (c, cols))
        wrong += int(np.count_nonzero(_mismatch(d, f1, f2)))
    return wrong


def _moe_fast(est: np.ndarray, tru: np.ndarray) -> int:
    """Number of triangles whose orientation differs, equal to _moe_bruteforce; see
    mean_orientation_error for the algorithm."""
    n = len(est)
    wrong = 0
    i0 = 0
    while i0 < n - 2:
        w = n - i0 - 1
        # entries (r, c < r) of a batch are padding: rows <= w / 8 keep that waste small
        i1 = min(n - 2, i0 + max(1, min(_BATCH // w, max(256, w // 8))))
        wrong += _wrong_in_rows(est, tru, i0, i1)
        i0 = i1
    return wrong


def mean_orientation_error(
    estimate: np.ndarray, truth: np.ndarray, exclude: Iterable[int] | None = None
) -> float:
    """Percentage of all C(M, 3) triangles whose orientation differs from the truth (MOE).

    Orientation is the sign of the triangle's signed area (anticlockwise +, clockwise -,
    degenerate 0); a triangle counts as wrong when the signs differ (so degenerate in one map
    and not in the other is wrong, degenerate in both is right). Exact: the count equals the
    O(M^3) reference ``_moe_bruteforce`` (used below M = 200, where it is as fast) on every
    finite input, where triangle (i, j, k), i < j < k, has the sign of fl(dx_j dy_k) -
    fl(dx_k dy_j) with d = fl(p - p_i). Time
    O(M^2 log M) plus the near-degenerate triangles (below); memory O(M), in batches of about
    ``_BATCH`` (apex, point) entries (~16 MB), except for apexes sent to the brute force.

    Algorithm, per apex i over the points j > i (vectorised over batches of apexes): fold each
    direction d_j, at angle a, to a' = a mod pi with a flag s_j = +1 if a in [0, pi) else -1;
    then sign(d_j x d_k) = sign(a'_k - a'_j) s_j s_k. Rank the folded angles of the estimate
    and of the truth, and let rho_j = s_j(estimate) s_j(truth). A pair (j, k) is wrong iff its
    two rank orders disagree while rho_j = rho_k, or agree while rho_j != rho_k: discordant pairs
    inside each rho group plus concordant pairs across them, which are counted from inversion
    counts (``_inversions``) in O(M log M) per apex.

    Exactness. Rounding a product is monotone, so fl(cross) has the sign of the exact cross
    product of the (rounded) differences, except that it may be 0 where |sin| of the angle
    between d_j and d_k is below 2^-53. That needs the products to be normal floats: every
    non-zero coordinate difference in [1e-150, 1e150], else the apex goes to the brute force.
    arctan2 and the fold err by a few ulps (~1e-15 rad), so the ranks give that exact sign for
    every pair whose folded angles are more than ``_TIE_TOL`` (1e-10) apart mod pi. The sorted
    folded angles are chained into near-tie clusters wherever consecutive ones are at most
    ``_TIE_TOL`` apart (the cluster just below pi joins the one just above 0), so points in
    different clusters are farther apart than that, and every pair inside a cluster of either
    configuration (collinear points, grid layouts, points on a line plus jitter, atan2 ties) is
    re-decided with the reference's own fl(cross) in place of the ranks' verdict. Points equal
    to the apex (zero direction, sign 0 with everything) are kept out of the ranks and all their
    pairs are checked exactly. An apex whose exact checks would exceed 1/8 of its pairs (nearly
    all points collinear with it) uses the brute-force block instead, so degenerate layouts
    cost at most about as much as the brute force.
    """
    est, tru = check_scored_pair(estimate, truth, exclude)
    n = len(est)
    if n < 3:
        raise ValueError(f"need at least 3 objects for orientation error, got {n}")
    total = n * (n - 1) * (n - 2) // 6
    count = _moe_fast if n >= _FAST_FROM else _moe_bruteforce  # the same count either way
    return 100.0 * count(est, tru) / total


def _triangle_signs(P: np.ndarray, i: np.ndarray, j: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Orientation of triangles (i < j < k) as :func:`_signs_from` defines it."""
    dj, dk = P[j] - P[i], P[k] - P[i]
    return np.sign(dj[:, 0] * dk[:, 1] - dk[:, 0] * dj[:, 1])


def sampled_orientation_error(
    estimate: np.ndarray,
    truth: np.ndarray,
    exclude: Iterable[int] | None = None,
    *,
    n_triangles: int = 2_000_000,
    confidence: float = 0.95,
    random_state: int | None = 0,
) -> tuple[float, tuple[float, float]]:
    """MOE [%] estimated from ``n_triangles`` triangles drawn uniformly, with its interval.

    For maps too large for :func:`mean_orientation_error` in the time at hand (it is exact, in
    O(M^2 log M)). Triangles are drawn with replacement among the C(M, 3) (three distinct ids,
    each triangle equally likely) and scored exactly as the exact MOE scores them; returns the
    percentage wrong and the Wilson score interval (Wilson 1927) at ``confidence``, a binomial
    interval that stays valid for proportions near 0 (unfolded maps have MOE below 1 %).
    """
    from scipy.stats import norm

    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    if isinstance(n_triangles, bool) or not isinstance(n_triangles, int | np.integer) or n_triangles < 1:
        raise ValueError(f"n_triangles must be a positive integer, got {n_triangles!r}")
    est, tru = check_scored_pair(estimate, truth, exclude)
    n = len(est)
    if n < 3:
        raise ValueError(f"need at least 3 objects for orientation error, got {n}")
    rng = np.random.default_rng(random_state)
    wrong = drawn = 0
    while drawn < n_triangles:
        size = min(_BATCH * 8, n_triangles - drawn)
        ids = np.sort(rng.integers(0, n, size=(2 * size, 3)), axis=1)
        ids = ids[(ids[:, 0] < ids[:, 1]) & (ids[:, 1] < ids[:, 2])][:size]  # distinct: uniform
        i, j, k = ids.T
        wrong += int(np.count_nonzero(_triangle_signs(est, i, j, k) != _triangle_signs(tru, i, j, k)))
        drawn += ids.shape[0]
    p = wrong / drawn
    z = float(norm.ppf(0.5 + 0.5 * confidence))
    centre = (p + z * z / (2 * drawn)) / (1 + z * z / drawn)
    half = z * np.sqrt(p * (1 - p) / drawn + z * z / (4 * drawn * drawn)) / (1 + z * z / drawn)
    return 100.0 * p, (100.0 * max(centre - half, 0.0), 100.0 * min(centre + half, 1.0))
