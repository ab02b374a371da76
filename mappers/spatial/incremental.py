"""A rays-only start by incremental structure from motion with merging: many pieces, each seeded
by two steps and grown in its own frame, joined by their shared objects, placed by the anchors.

1. Seeds: pairs of steps that share ``min_shared`` or more objects, with their relative rotation
   from the rays alone (:mod:`mappers.spatial.relative_rotations`: the eight-point essential
   matrix) fitting to a few times the noise and their objects seen at a parallax of at least
   ``min_parallax`` (else the depths are not fixed); best first (most objects agreeing).
2. A piece per seed neither of whose steps a piece holds yet: the two steps' and their objects' positions
   from the known rotations (:mod:`mappers.spatial.known_rotations`), then grown by resection and
   intersection in its own frame (:func:`mappers.spatial.registration.register_rays`: a step
   that sees three or more of the piece's objects is resected, an object seen from two of its
   steps at diverging angles intersected), and adjusted in that frame
   (:func:`mappers.spatial.adjustment.adjust_viewpoints`, its points under a loose prior that
   only fixes the gauge).
3. Merging: two pieces that share three or more objects are joined by the similarity (rotation,
   translation, scale: Umeyama 1991) of their shared objects, found robustly (RANSAC over
   triples of them, Fischler & Bolles 1981, inliers within ``merge_tol`` of the larger piece's
   typical depth) and kept only when the smaller piece's steps then see the larger piece's
   objects within ``max_angle`` (their median ray error): a wrong merge turns the rays away. The
   merged piece is grown and adjusted again; until no two pieces join.
4. Each piece that holds three anchors not on one line is placed in the world by the robust
   similarity of its anchors onto their positions (largest pieces first; what one piece placed
   stays).

No odometry, no motion model, no order of the steps. This is the route of incremental
structure-from-motion systems (e.g. Snavely, Seitz & Szeliski, *Photo tourism*, SIGGRAPH 2006;
Schönberger & Frahm, *Structure-from-motion revisited*, CVPR 2016) with the partial
reconstructions merged as in Moulon et al.'s and COLMAP's model merger, written on NumPy/SciPy
because no maintained Python library takes rays with unknown poses and no images (the
project's blocks do each step).
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from mappers.core.align_3d import umeyama
from mappers.spatial.adjustment import adjust_viewpoints
from mappers.spatial.known_rotations import positions_from_rotations
from mappers.spatial.rays import RayObservations
from mappers.spatial.registration import register_rays
from mappers.spatial.regrow import intersect_by_consensus, step_ray_errors
from mappers.spatial.relative_rotations import relative_rotations, view_pairs

__all__ = ["register_incremental"]

_PIECE_PRIOR = 1.0
"""Deviation (in the piece's typical depths, :func:`_depth`) of the prior that holds a piece's
points while it is adjusted in its own frame: loose, it only fixes the gauge."""

_MAX_TRIPLES = 300
"""RANSAC hypotheses (triples of shared objects) at most per merge; fewer shared objects: every
triple."""

_GROW_ROUNDS = 20
"""Rings of growing and adjusting a piece at most (:func:`_grow`)."""

_MIN_OBJECTS = 4
"""Objects a piece must hold to be kept (three fix nothing beyond a seed)."""


def _empty(m, n):
    return np.full((m, 3), np.nan), np.full((n, 3, 3), np.nan), np.full((n, 3), np.nan)


def _depth(obs, P, C) -> float:
    """The piece's typical depth: the median distance from its posed steps to the placed objects
    they see (its unit of length)."""
    use = np.all(np.isfinite(P[obs.obj]), axis=1) & np.isfinite(C[obs.step, 0])
    if not use.any():
        return np.nan
    return float(np.median(np.linalg.norm(P[obs.obj[use]] - C[obs.step[use]], axis=1)))


def _spans(points: np.ndarray, size: float) -> bool:
    """Three or more points not on one line: their second singular value above 1 % of ``size``."""
    if len(points) < 3:
        return False
    return bool(np.linalg.svd(points - points.mean(axis=0), compute_uv=False)[1] > 0.01 * size)


def _robust_similarity(src, dst, tol, rng):
    """``(R, s, t, inliers)`` taking ``src`` (k, 3) onto ``dst`` (k, 3) robustly: of the triples
    not on a line (all, or ``_MAX_TRIPLES`` random ones), the similarity that the most pairs
    fit within ``tol``, refitted on those (Umeyama 1991); None when fewer than three fit.

    By hand: scikit-learn's ``RANSACRegressor`` fits linear models, not similarities, and
    scikit-image (whose ``ransac`` takes a ``SimilarityTransform``) is not a dependency; with
    twelve or fewer shared objects every triple is tried, so the fit is deterministic."""
    k = len(src)
    size = float(np.sqrt(np.mean(np.sum((dst - dst.mean(axis=0)) ** 2, axis=1)))) or 1.0
    if k <= 12:
        triples = np.array(list(combinations(range(k), 3)))
    else:
        triples = np.array([rng.choice(k, 3, replace=False) for _ in range(_MAX_TRIPLES)])
    best = None
    for tri in triples:
        if not (_spans(src[tri], size) and _spans(dst[tri], size)):
            continue
        R, s, t = umeyama(src[tri], dst[tri], True)
        inl = np.linalg.norm(s * src @ R.T + t - dst, axis=1) < tol
        if best is None or inl.sum() > best.sum():
            best = inl
    if best is None or best.sum() < 3 or not _spans(dst[best], size):
        return None
    for _ in range(2):  # refit on the inliers, take the inliers of the refit
        R, s, t = umeyama(src[best], dst[best], True)
        inl = np.linalg.norm(s * src @ R.T + t - dst, axis=1) < tol
        if inl.sum() < 3 or not _spans(dst[inl], size):
            break
        best = inl
    R, s, t = umeyama(src[best], dst[best], True)
    return R, s, t, best


def _adjust(obs, piece, noise, loss):
    """The piece adjusted in its own frame (see the module's docstring)."""
    P, R, C = piece
    placed = np.all(np.isfinite(P), axis=1)
    if np.isfinite(C[:, 0]).sum() < 2:
        return piece
    depth = _depth(obs, P, C)
    res = adjust_viewpoints(obs, P, R, C, placed, bearing_noise=noise, loss=loss, max_iter=30,
                            tol=1e-6, anchor_noise=_PIECE_PRIOR * depth)
    return res.points, res.rotations, res.positions


def _seed(obs, a, b, rel, noise):
    """A piece from the two steps ``a``, ``b`` with relative rotation ``rel`` (``R_b^T R_a``):
    step ``a`` at the origin unturned, the shared objects and ``b`` from the known rotations."""
    m, n = obs.n_objects, obs.n_steps
    R = np.full((n, 3, 3), np.nan)
    R[a], R[b] = np.eye(3), rel.T
    steps = np.zeros(n, dtype=bool)
    steps[[a, b]] = True
    seen_a = np.zeros(m, dtype=bool)
    seen_a[obs.obj[obs.step == a]] = True
    seen_b = np.zeros(m, dtype=bool)
    seen_b[obs.obj[obs.step == b]] = True
    X, C, err = positions_from_rotations(obs, R, steps, seen_a & seen_b, noise=noise)
    if np.nanmedian(err) > 3.0 * noise:
        return None
    C_full = np.where(steps[:, None], C, np.nan)
    P = X.copy()
    # every shared object in front of both steps
    for t in (a, b):
        v = (P[seen_a & seen_b] - C_full[t]) @ R[t]
        if np.any(v[:, 2] <= 0):
            return None
    return P, np.where(steps[:, None, None], R, np.nan), C_full


def _transform(piece, Rs, s, t):
    P, R, C = piece
    return s * P @ Rs.T + t, Rs @ R, s * C @ Rs.T + t


def _join(big, small):
    """``big`` with what ``small`` (already in ``big``'s frame) adds: its objects and steps that
    ``big`` lacks."""
    P, R, C = (x.copy() for x in big)
    Ps, Rs, Cs = small
    new_p = ~np.all(np.isfinite(P), axis=1) & np.all(np.isfinite(Ps), axis=1)
    new_s = np.isnan(C[:, 0]) & np.isfinite(Cs[:, 0])
    P[new_p], R[new_s], C[new_s] = Ps[new_p], Rs[new_s], Cs[new_s]
    return P, R, C, new_s


def _object_ray_errors(obs, P, R, C) -> np.ndarray:
    """(M,) the median angle [rad] between each placed object and the rays of the posed steps
    that saw it (NaN: not placed or seen from no posed step)."""
    use = np.all(np.isfinite(P[obs.obj]), axis=1) & np.isfinite(C[obs.step, 0])
    out = np.full(len(P), np.nan)
    if not use.any():
        return out
    v = np.einsum("kji,kj->ki", R[obs.step[use]], P[obs.obj[use]] - C[obs.step[use]])
    cos = np.einsum("kj,kj->k", v, obs.ray[use]) / np.maximum(np.linalg.norm(v, axis=1), 1e-12)
    angle = np.arccos(np.clip(cos, -1.0, 1.0))
    obj = obs.obj[use]
    for i in np.unique(obj):
        out[i] = np.median(angle[obj == i])
    return out


def _grow(obs, piece, noise, loss, max_angle):
    """The piece grown in its own frame a ring at a time: one round of resection and
    intersection (:func:`~mappers.spatial.registration.register_rays`, a step resected when its
    rays fit to ``max_angle``), the piece adjusted, the steps and objects whose rays miss it by a
    median angle above ``max_angle`` dropped, the objects left out intersected by consensus
    (:mod:`mappers.spatial.regrow`); ``_GROW_ROUNDS`` rounds at most, until a round places no
    new object and poses under 1 % more steps. Adjusting after every ring keeps a wrong resection from sending the next ring's
    intersections far off (grown in one go and adjusted once, a piece of zigzag_s3 was a metre
    off in shape)."""
    none = np.zeros(0, dtype=np.int64)
    best = (_size(piece), int(np.isfinite(piece[2][:, 0]).sum()))
    for _ in range(_GROW_ROUNDS):
        piece = register_rays(obs, none, np.zeros((0, 3)), start=piece, max_rms=max_angle,
                              rounds=1)
        P, R, C = (x.copy() for x in _adjust(obs, piece, noise, loss))
        off = step_ray_errors(obs, P, R, C) > max_angle
        R[off], C[off] = np.nan, np.nan
        P[_object_ray_errors(obs, P, R, C) > max_angle] = np.nan
        P = intersect_by_consensus(obs, P, R, C, max_angle)
        piece = (P, R, C)
        now = (_size(piece), int(np.isfinite(C[:, 0]).sum()))
        # no new object and under 1 % more steps: later rings only re-pose a few steps
        if now[0] <= best[0] and now[1] <= best[1] + 0.01 * best[1]:
            break
        best = (max(best[0], now[0]), max(best[1], now[1]))
    return piece


def _try_merge(obs, big, small, merge_tol, max_angle, rng):
    """``big`` and ``small`` joined (see the module's docstring), or None."""
    shared = np.flatnonzero(np.all(np.isfinite(big[0]), axis=1)
                            & np.all(np.isfinite(small[0]), axis=1))
    if shared.size < 3:
        return None
    tol = merge_tol * _depth(obs, big[0], big[2])
    fit = _robust_similarity(small[0][shared], big[0][shared], tol, rng)
    if fit is None:
        return None
    Rs, s, t, _ = fit
    P, R, C, moved = _join(big, _transform(small, Rs, s, t))
    err = step_ray_errors(obs, P, R, C)[moved]
    if moved.any() and not np.nanmedian(err) <= max_angle:
        return None
    return P, R, C


def register_incremental(obs: RayObservations, anchor_ids: np.ndarray,
                         anchor_positions: np.ndarray, *, noise: float, min_shared: int = 8,
                         per_step: int = 1000, min_parallax: float = np.deg2rad(3.0),
                         merge_tol: float = 0.05, max_angle: float = np.deg2rad(2.0),
                         loss: str | None = "huber", seed: int = 0):
    """``(P, R, C)``: points (M, 3), rotations sensor -> world (N, 3, 3) and positions (N, 3)
    from the rays alone by incremental structure from motion with merging (see the module's
    docstring), NaN where not placed (all NaN when no piece holds three anchors not on one line).

    Args:
        obs: the sightings (:func:`mappers.spatial.rays.ray_observations`).
        anchor_ids, anchor_positions: (A,) object ids and their (A, 3) world positions.
        noise: the rays' angle noise [rad].
        min_shared: objects two steps must share to seed a piece (>= 8: the eight-point
            algorithm).
        per_step: the partners each step keeps as seed candidates (those it shares most with).
        min_parallax: the median angle [rad] between a seed's rays to one object, turned into one
            frame, at least (the depths of a seed without parallax are not fixed).
        merge_tol: a shared object fits a merge within this share of the larger piece's typical
            depth (placing a piece by its anchors: of the anchors' typical depth).
        max_angle: a merge (and a placement) is kept when the moved steps' median ray error is
            at most this angle [rad].
        loss: the robust loss of the pieces' adjustments.
        seed: the random triples of large merges (deterministic for a seed).
    """
    if min_shared < 8:
        raise ValueError(f"min_shared must be >= 8 (the eight-point algorithm), got {min_shared}")
    if not noise > 0:
        raise ValueError(f"noise must be > 0, got {noise!r}")
    if not (merge_tol > 0 and max_angle > 0 and min_parallax >= 0):
        raise ValueError(f"merge_tol and max_angle must be > 0 and min_parallax >= 0, got "
                         f"{merge_tol!r}, {max_angle!r}, {min_parallax!r}")
    rng = np.random.default_rng(seed)
    m, n = obs.n_objects, obs.n_steps
    out = _empty(m, n)
    per = np.bincount(obs.step, minlength=n)
    a, b, ka, kb, pair = view_pairs(obs, np.flatnonzero(per >= min_shared), min_shared, per_step)
    if len(a) == 0:
        return out
    pr = relative_rotations(obs, a, b, ka, kb, pair, noise=noise)
    good = ((pr.inliers >= min_shared) & (pr.residual < max(3.0 * noise, np.deg2rad(0.5)))
            & (pr.parallax >= min_parallax))
    order = np.flatnonzero(good)[np.lexsort((-pr.parallax[good], -pr.inliers[good]))]
    pieces, held = [], np.zeros(n, dtype=bool)
    for p in order:
        if held[a[p]] or held[b[p]]:
            continue
        piece = _seed(obs, a[p], b[p], pr.rotation[p], noise)
        if piece is None:
            continue
        piece = _grow(obs, piece, noise, loss, max_angle)
        if np.all(np.isfinite(piece[0]), axis=1).sum() < _MIN_OBJECTS:
            continue
        pieces.append(piece)
        held |= np.isfinite(piece[2][:, 0])
    pieces = _merge_all(obs, pieces, merge_tol, max_angle, noise, loss, rng)
    return _place(obs, pieces, np.asarray(anchor_ids), np.asarray(anchor_positions, dtype=float),
                  merge_tol, max_angle, rng)


def _size(piece) -> int:
    return int(np.all(np.isfinite(piece[0]), axis=1).sum())


def _merge_all(obs, pieces, merge_tol, max_angle, noise, loss, rng):
    """The pieces joined pairwise, largest first, each join grown and adjusted, until none
    joins."""
    pieces = sorted(pieces, key=lambda q: -_size(q))
    merged = []
    while pieces:
        big = pieces.pop(0)
        grew = True
        while grew:
            grew = False
            for k, small in enumerate(pieces):
                joined = _try_merge(obs, big, small, merge_tol, max_angle, rng)
                if joined is None:
                    continue
                big = _grow(obs, joined, noise, loss, max_angle)
                del pieces[k]
                grew = True
                break
        merged.append(big)
    return merged


def _place(obs, pieces, ids, pos, merge_tol, max_angle, rng):
    """The pieces holding three anchors (not on a line) placed on them, largest first."""
    P, R, C = _empty(obs.n_objects, obs.n_steps)
    P[ids] = pos  # a piece's steps must then see the anchors where they are
    for piece in sorted(pieces, key=lambda q: -_size(q)):
        has = np.all(np.isfinite(piece[0][ids]), axis=1)
        if has.sum() < 3:
            continue
        depth = _depth(obs, piece[0], piece[2])
        first = _robust_similarity(piece[0][ids[has]], pos[has], np.inf, rng)
        if first is None:
            continue
        tol = merge_tol * depth * first[1]  # the piece's depth in the world's metres
        fit = _robust_similarity(piece[0][ids[has]], pos[has], tol, rng)
        if fit is None:
            continue
        P2, R2, C2, moved = _join((P, R, C), _transform(piece, *fit[:3]))
        err = step_ray_errors(obs, P2, R2, C2)[moved]
        if moved.any() and np.nanmedian(err) <= max_angle:
            P, R, C = P2, R2, C2
    if not np.isfinite(C[:, 0]).any():
        P[ids] = np.nan
    return P, R, C
