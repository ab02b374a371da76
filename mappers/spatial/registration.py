"""Start maps in 3-D from the sightings alone: frames registered to one another by their common
objects, without odometry and without a motion model.

* Rays and ranges (:func:`register_points`): each step gives its objects' 3-D points in the
  sensor's frame (range times ray), so the angle between two rays and the two ranges fix their
  distance whatever the pose (the law of cosines). Steps that share three objects not on a line
  are registered rigidly (Kabsch/Umeyama, no scale) one after another from a seed step; each
  chain of registered steps is a rigid piece, adjusted in its own frame (with ``refine``: the
  6-DoF adjustment spreads the chain's accumulated error), which three or more placed objects
  it holds (anchors first, not on a line) place in the world by a similarity, or fewer placed
  objects together with pose-free distances to placed ones, when they fix its pose uniquely.
* Rays alone (:func:`register_rays`): the anchors are the first known points; a step that sees
  three or more known objects is resected by orthogonal iteration (Lu, Hager & Mjolsness, *Fast
  and globally convergent pose estimation from video images*, IEEE TPAMI 22(6), 2000), and an
  object seen from two or more resected steps with rays that diverge is placed where its rays
  pass closest (least-squares intersection); until nothing more can be placed.

Both return the start of the 6-DoF adjustment (:mod:`mappers.spatial.adjustment`): the points
(NaN where not placed) and each step's pose (rotation sensor -> world and position; NaN where
not registered).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from mappers.core.align_3d import umeyama
from mappers.spatial.adjustment import adjust_viewpoints
from mappers.spatial.rays import RayObservations
from mappers.spatial.resection import orthogonal_iteration_batch

__all__ = ["MIN_RAY_ANGLE", "orthogonal_iteration", "register_points", "register_rays", "triangulate"]

_MIN_SPAN = 1e-3
"""Smallest second singular value [m] of three or more points for a rigid registration (not on
one line)."""

MIN_RAY_ANGLE = np.deg2rad(10.0)
"""Smallest angle between two of an object's rays for a least-squares intersection (closer
rays place it too uncertainly along them for the adjustment to recover)."""


def _groups(obs: RayObservations) -> list[np.ndarray]:
    """Each step's sightings (indices into the observations)."""
    cuts = np.flatnonzero(np.diff(obs.step)) + 1
    groups = [np.array([], dtype=np.int64)] * obs.n_steps
    for g in np.split(np.arange(len(obs.step)), cuts):
        if g.size:
            groups[obs.step[g[0]]] = g
    return groups


def _spans(points: np.ndarray) -> bool:
    if len(points) < 3:
        return False
    s = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return bool(s[1] > _MIN_SPAN)


def register_points(obs: RayObservations, anchor_ids: np.ndarray, anchor_positions: np.ndarray,
                    refine: dict | None = None):
    """``(P, R, C)``: points (M, 3), rotations sensor -> world (N, 3, 3) and positions (N, 3)
    from the steps' 3-D points (rays times ranges; sightings without a range are not used),
    each rigid piece placed by its anchors (see the module's docstring), then every step that
    sees three placed objects registered to them in the world, until none is left; NaN where not
    placed. ``refine``: keywords of :func:`mappers.spatial.adjustment.adjust_viewpoints` (the
    noise and loss) to adjust each piece of two or more steps with before it is placed; None:
    the pieces as chained."""
    m, n = obs.n_objects, obs.n_steps
    pts = obs.ray * obs.range[:, None]
    groups = [g[np.isfinite(obs.range[g])] for g in _groups(obs)]
    P = np.full((m, 3), np.nan)
    R = np.full((n, 3, 3), np.nan)
    C = np.full((n, 3), np.nan)
    ranged = np.flatnonzero(np.isfinite(obs.range))
    todo = _spans_batch(obs.step[ranged], pts[ranged], n)  # the steps with 3 points off a line
    pending = todo.copy()
    pieces = []
    while todo.any():
        seed = max(np.flatnonzero(todo), key=lambda t: groups[t].size)
        pieces.append(_grow_piece(obs, pts, groups, todo, seed))
    P[anchor_ids] = anchor_positions
    pieces = _merge_pieces(pieces)
    if refine is not None:
        pieces = [_refine_piece(obs, piece, refine) for piece in pieces]
    pairs = _pair_distances(obs, pts, groups)
    scale = None  # the pieces' scale: that of the first placed by three or more points
    while pieces:  # place the pieces the placed points fix, until none is left that they fix
        left = []
        for piece in pieces:
            used = _place_piece(piece, P, R, C, pairs, scale)
            if used is None:
                left.append(piece)
            elif scale is None and used[1]:
                scale = used[0]
        if len(left) == len(pieces):
            break
        pieces = left
    pending &= np.isnan(C[:, 0])
    while True:  # the steps left: registered to the placed points in the world
        known = np.all(np.isfinite(P), axis=1)
        grew = False
        for t in np.flatnonzero(pending):
            g = groups[t]
            s = g[known[obs.obj[g]]]
            if s.size < 3 or not _spans(pts[s]):
                continue
            R[t], _, C[t] = umeyama(pts[s], P[obs.obj[s]], False)
            pending[t], grew = False, True
            new = g[~np.all(np.isfinite(P[obs.obj[g]]), axis=1)]
            P[obs.obj[new]] = pts[new] @ R[t].T + C[t]
        if not grew:
            break
    return P, R, C


def _grow_piece(obs, pts, groups, todo, seed):
    """One rigid piece grown from ``seed`` (its frame the seed step's): its points' sums and
    counts, and its steps' poses; the steps it takes are struck from ``todo``."""
    m = obs.n_objects
    total, count = np.zeros((m, 3)), np.zeros(m)
    poses = {seed: (np.eye(3), np.zeros(3))}
    todo[seed] = False
    g = groups[seed]
    # a step sees an object once, so each of its objects is added to once: an indexed add,
    # the same numbers as np.add.at
    total[obs.obj[g]] += pts[g]
    count[obs.obj[g]] += 1
    ranged = np.concatenate(groups) if groups else np.zeros(0, np.int64)
    while True:
        known = count > 0
        # the steps left that share three placed objects not on a line, all at once
        # (_spans_batch), the most shared first (ties by step)
        k = ranged[todo[obs.step[ranged]] & known[obs.obj[ranged]]]
        shared = np.bincount(obs.step[k], minlength=obs.n_steps)
        ready = np.flatnonzero(_spans_batch(obs.step[k], pts[k], obs.n_steps))
        if not ready.size:
            break
        for t in ready[np.argsort(-shared[ready], kind="stable")]:
            g = groups[t]
            s = g[known[obs.obj[g]]]  # the objects placed when the pass began
            here = total[obs.obj[s]] / count[obs.obj[s], None]
            Rt, _, ct = umeyama(pts[s], here, False)
            poses[t] = (Rt, ct)
            todo[t] = False
            total[obs.obj[g]] += pts[g] @ Rt.T + ct
            count[obs.obj[g]] += 1
    return total, count, poses


_PIECE_PRIOR = 1.0
"""The deviation [m] of the prior that holds a piece's points near their chained places while
the piece is adjusted (:func:`_refine_piece`): loose, it only fixes the piece's gauge."""


def _refine_piece(obs, piece, params):
    """A piece of two or more steps adjusted in its own frame by the 6-DoF adjustment
    (:func:`mappers.spatial.adjustment.adjust_viewpoints` with ``params``): chaining steps one
    after another lets their errors add up along the chain (a loop of steps does not close); the
    adjustment spreads them over all the piece's sightings, so that the piece keeps the shape
    its sightings give it when the anchors and the distances place it."""
    total, count, poses = piece
    if len(poses) < 2:
        return piece
    mine = count > 0
    P0 = np.full_like(total, np.nan)
    P0[mine] = total[mine] / count[mine, None]
    R0 = np.full((obs.n_steps, 3, 3), np.nan)
    C0 = np.full((obs.n_steps, 3), np.nan)
    for k, (Rt, ct) in poses.items():
        R0[k], C0[k] = Rt, ct
    ranged = obs._replace(step=obs.step[np.isfinite(obs.range)], obj=obs.obj[np.isfinite(obs.range)],
                          ray=obs.ray[np.isfinite(obs.range)], range=obs.range[np.isfinite(obs.range)])
    res = adjust_viewpoints(ranged, P0, R0, C0, mine, anchor_noise=_PIECE_PRIOR, **params)
    steps = list(poses)
    return (np.where(mine[:, None], res.points, 0.0) * count[:, None], count,
            {k: (res.rotations[k], res.positions[k]) for k in steps})


def _merge_pieces(pieces):
    """The pieces joined where one shares three or more objects (not on a line) with another:
    the smaller registered rigidly onto the larger, repeatedly, largest first."""
    pieces = sorted(pieces, key=lambda p: -int((p[1] > 0).sum()))
    merged = []
    while pieces:
        total, count, poses = pieces.pop(0)
        grew = True
        while grew:
            grew = False
            for k, (t2, c2, p2) in enumerate(pieces):
                common = np.flatnonzero((count > 0) & (c2 > 0))
                if common.size < 3:
                    continue
                here = total[common] / count[common, None]
                there = t2[common] / c2[common, None]
                if not (_spans(here) and _spans(there)):
                    continue
                Rm, _, cm = umeyama(there, here, False)
                total = total + t2 @ Rm.T + c2[:, None] * cm
                count = count + c2
                poses.update({t: (Rm @ Rt, Rm @ ct + cm) for t, (Rt, ct) in p2.items()})
                del pieces[k]
                grew = True
                break
        merged.append((total, count, poses))
    return merged


def _pair_distances(obs, pts, groups) -> dict[tuple[int, int], float]:
    """Pose-free distances: per pair of objects seen in one step with ranges, the median over
    those steps of the distance between their points (the law of cosines). Keyed ``(a, b)`` in
    the order the step lists them, in the order the pairs are first met (the pose fit of
    :func:`_fit_piece` reads them in that order)."""
    # every pair (a, b), a before b, of each step's sightings, step by step in the order
    # np.triu_indices lists a step's pairs: the j-th of a step's n sightings pairs with the
    # n - 1 - j after it
    many = [g for g in groups if g.size >= 2]
    if not many:
        return {}
    sightings = np.concatenate(many)
    sizes = np.array([g.size for g in many])
    place = np.arange(sightings.size) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    after = np.repeat(sizes, sizes) - 1 - place
    a = np.repeat(np.arange(sightings.size), after)
    b = a + 1 + np.arange(a.size) - np.repeat(np.cumsum(after) - after, after)
    first, second = obs.obj[sightings[a]], obs.obj[sightings[b]]
    dist = np.linalg.norm(pts[sightings[a]] - pts[sightings[b]], axis=1)
    code = first.astype(np.int64) * obs.n_objects + second
    order = np.lexsort((dist, code))  # by pair, each pair's distances sorted
    code_s, dist_s = code[order], dist[order]
    starts = np.flatnonzero(np.r_[True, code_s[1:] != code_s[:-1]])
    counts = np.diff(np.r_[starts, code_s.size])
    low = dist_s[starts + (counts - 1) // 2]
    high = dist_s[starts + counts // 2]
    median = np.where(counts % 2 == 1, low, (low + high) / 2)  # as np.median computes it
    _, met = np.unique(code, return_index=True)  # sorted by code, as ``starts``
    keys = code_s[starts]
    return {(int(k // obs.n_objects), int(k % obs.n_objects)): float(median[i])
            for i in np.argsort(met, kind="stable") for k in [keys[i]]}


def _place_piece(piece, P, R, C, pairs, scale):
    """Place a piece in the world when the points placed already fix it: three or more of its
    points placed, not on a line (a similarity), or else its points placed and the pose-free
    distances from its other points to placed ones, where those fix its pose unambiguously
    (:func:`_fit_piece`, at the scale ``scale`` of the pieces placed already, 1 if None). Points
    placed already stay; returns None if it was not placed, else the scale used and whether it
    came from a similarity."""
    total, count, poses = piece
    mine = count > 0
    local = np.full_like(total, np.nan)
    local[mine] = total[mine] / count[mine, None]
    known = np.all(np.isfinite(P), axis=1)
    common = np.flatnonzero(mine & known)
    if common.size >= 3 and _spans(P[common]) and _spans(local[common]):
        Rs, s, t = umeyama(local[common], P[common], True)
        similar = True
    else:
        found = _fit_piece(local, P, common, mine & ~known, known & ~mine, pairs,
                           1.0 if scale is None else scale)
        if found is None:
            return None
        (Rs, s, t), similar = found, False
    new = mine & ~known
    P[new] = s * local[new] @ Rs.T + t
    for k, (Rt, ct) in poses.items():
        R[k] = Rs @ Rt
        C[k] = s * Rs @ ct + t
    return s, similar


_PIECE_NOISE = 0.05
"""The deviation [m] a piece's placed points and its pose-free distances are weighed with when a
piece is placed by them (:func:`_fit_piece`): a few centimetres, a stereo point's error."""

_PIECE_MAX_RMS = 0.10
"""Largest root-mean-square misfit [m] of a piece placed by distances (:func:`_fit_piece`)."""

_PIECE_STARTS = Rotation.create_group("O")
"""The rotations a piece's placement starts from: the 24 turns of the cube (Rotation.create_group),
so that every local minimum of the fit is within 45 degrees of a start."""


def _rodrigues(w: np.ndarray) -> np.ndarray:
    """The rotation matrix of the rotation vector ``w`` (Rodrigues' formula; by hand because
    SciPy's Rotation objects cost more than the small fit that calls this thousands of times)."""
    a = float(np.linalg.norm(w))
    if a < 1e-12:
        return np.eye(3)
    k = w / a
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(a) * K + (1.0 - np.cos(a)) * K @ K


def _fit_piece(local, P, common, movers, others, pairs, scale):
    """``(R, s, t)`` placing a piece by its placed points (fewer than three, or on a line) and the
    pose-free distances from its other points (``movers``) to placed ones (``others``): the rigid
    pose (at ``scale``) that fits both in least squares (a soft-L1 loss; SciPy's least_squares),
    from the 24 turns of the cube. None unless the fit is unique: at least eight constraints (two
    more than the pose's six unknowns, so that a wrong pose shows as a misfit: two common points
    and one distance leave the turn about their line at two mirror places, or at one place that
    a small error moves far), a misfit of at most 10 cm, and no other local minimum that moves
    the piece's points by more than 10 cm fitting within three times the misfit (or 1 cm more):
    such a piece is left unplaced, not guessed.

    Written by hand: a piece's pose from a mix of point matches and distances is no library's
    registration (Umeyama's needs three matched points)."""
    use = [(i, j, d) for (i, j), d in pairs.items()
           for i, j in ((i, j), (j, i)) if movers[i] and others[j]]
    if 3 * common.size + len(use) < 8:
        return None
    ui, uj, ud = (np.array(v, dtype=float if k == 2 else np.int64)
                  for k, v in enumerate(zip(*use, strict=True))) if use else (
        np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
    here = np.flatnonzero(np.all(np.isfinite(local), axis=1))
    centre = local[here].mean(axis=0)
    target = P[common].mean(axis=0) if common.size else P[uj].mean(axis=0)

    def moved(x, idx):
        return scale * (local[idx] - centre) @ _rodrigues(x[:3]).T + x[3:]

    def residuals(x):
        e_common = (moved(x, common) - P[common]).ravel()
        e_dist = np.linalg.norm(moved(x, ui) - P[uj], axis=1) - scale * ud
        return np.concatenate([e_common, e_dist]) / _PIECE_NOISE

    fits = []
    for r0 in _PIECE_STARTS:
        x0 = np.concatenate([r0.as_rotvec(), target])
        if common.size:  # the start's turn, then the shift that puts the common points on theirs
            x0[3:] += (P[common] - moved(x0, common)).mean(axis=0)
        sol = least_squares(residuals, x0, loss="soft_l1", f_scale=2.0, max_nfev=60)
        rms = _PIECE_NOISE * float(np.sqrt(np.mean(sol.fun**2)))
        fits.append((rms, sol.x))
    fits.sort(key=lambda f: f[0])
    best_rms, best = fits[0]
    if best_rms > _PIECE_MAX_RMS:
        return None
    spot = moved(best, here)
    for rms, x in fits[1:]:
        apart = np.sqrt(np.mean(np.sum((moved(x, here) - spot) ** 2, axis=1)))
        if apart > 0.1 and rms <= max(3.0 * best_rms, best_rms + 0.01):
            return None
    Rs = _rodrigues(best[:3])
    return Rs, scale, best[3:] - scale * Rs @ centre


def orthogonal_iteration(p: np.ndarray, u: np.ndarray, iters: int = 60):
    """``(R, c, rms)``: the pose (rotation sensor -> world, position) of a sensor that sees the
    known points ``p`` (k, 3), k >= 3, along the unit rays ``u`` (k, 3), by Lu, Hager &
    Mjolsness's orthogonal iteration (2000), started from a depth of the points' spread over
    their rays' spread; ``rms`` is the root mean square of the rays' angle errors [rad]."""
    k = len(p)
    V = u[:, :, None] * u[:, None, :]  # line-of-sight projections
    F = np.linalg.inv(np.eye(3) - V.mean(axis=0))
    spread_p = np.linalg.norm(p - p.mean(axis=0), axis=1).mean()
    spread_u = np.linalg.norm(u - u.mean(axis=0), axis=1).mean()
    q = u * (spread_p / max(spread_u, 1e-6))  # points along their rays at one depth
    Rcw, _, tcw = umeyama(p, q, False)
    for _ in range(iters):
        t = F @ np.mean(np.einsum("kij,kj->ki", V, p @ Rcw.T) - p @ Rcw.T, axis=0)
        q = np.einsum("kij,kj->ki", V, p @ Rcw.T + t)
        previous, (Rcw, _, _) = Rcw, umeyama(p, q, False)
        if np.abs(Rcw - previous).max() < 1e-10:
            break
    t = F @ np.mean(np.einsum("kij,kj->ki", V, p @ Rcw.T) - p @ Rcw.T, axis=0)
    cam = p @ Rcw.T + t
    cos = np.einsum("kj,kj->k", cam, u) / np.maximum(np.linalg.norm(cam, axis=1), 1e-12)
    rms = float(np.sqrt(np.mean(np.arccos(np.clip(cos, -1.0, 1.0)) ** 2))) if k else np.inf
    return Rcw.T, -Rcw.T @ t, rms


def triangulate(C: np.ndarray, d: np.ndarray):
    """``(p, ok)``: the point where the lines ``C + s d`` (k lines, unit ``d`` in the world) pass
    closest in least squares, and whether two of the rays diverge by at least 10 degrees."""
    A = np.eye(3)[None] - d[:, :, None] * d[:, None, :]
    p = np.linalg.solve(A.sum(axis=0) + 1e-12 * np.eye(3), np.einsum("kij,kj->i", A, C))
    cosines = d @ d.T
    return p, bool(np.min(cosines) < np.cos(MIN_RAY_ANGLE))


def _spans_batch(step, points, n):
    """(n,) bool: per step 0..n-1, whether its ``points`` (one row per entry of ``step``)
    are three or more not on one line (:func:`_spans` for each step at once)."""
    cnt = np.bincount(step, minlength=n)
    mean = np.stack([np.bincount(step, points[:, j], minlength=n) for j in range(3)], 1)
    mean = mean / np.maximum(cnt, 1)[:, None]
    a = points - mean[step]
    S = np.zeros((n, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            S[:, i, j] = S[:, j, i] = np.bincount(step, a[:, i] * a[:, j], minlength=n)
    second = np.sqrt(np.maximum(np.linalg.eigvalsh(S)[:, 1], 0.0))
    return (cnt >= 3) & (second > _MIN_SPAN)


def register_rays(obs: RayObservations, anchor_ids: np.ndarray, anchor_positions: np.ndarray,
                  *, start=None, max_rms: float = np.deg2rad(5.0), rounds: int = 50):
    """``(P, R, C)`` from rays alone, started from the anchors (see the module's docstring): a
    step is resected when it sees three or more placed objects and its rays fit them to
    ``max_rms`` [rad]; an object seen from two or more resected steps at diverging angles is
    intersected; ``rounds`` times at most. ``start``: ``(P, R, C)`` placed already (e.g. by
    :func:`register_points`), continued from."""
    m, n = obs.n_objects, obs.n_steps
    if start is None:
        P, R, C = np.full((m, 3), np.nan), np.full((n, 3, 3), np.nan), np.full((n, 3), np.nan)
    else:
        P, R, C = (a.copy() for a in start)
    P[anchor_ids] = anchor_positions
    tried = np.zeros(n, dtype=np.int64)  # the placed objects a step saw when last tried
    for _ in range(rounds):
        known = np.all(np.isfinite(P), axis=1)
        grew = False
        # every unposed step at once (orthogonal_iteration_batch): the same poses as one
        # orthogonal_iteration per step, without a Python loop over thousands of steps
        k = np.flatnonzero(np.isnan(C[obs.step, 0]) & known[obs.obj])
        count = np.bincount(obs.step[k], minlength=n)
        ready = (count >= 3) & (count != tried)
        ready[ready] = _spans_batch(obs.step[k], P[obs.obj[k]], n)[ready]
        k = k[ready[obs.step[k]]]
        if k.size:
            tried[ready] = count[ready]
            steps, seg = np.unique(obs.step[k], return_inverse=True)
            Rt, ct, rms = orthogonal_iteration_batch(seg, P[obs.obj[k]], obs.ray[k], steps.size)
            ok = rms <= max_rms
            R[steps[ok]], C[steps[ok]] = Rt[ok], ct[ok]
            grew = bool(ok.any())
        seen_from = np.isfinite(C[obs.step, 0]) & ~known[obs.obj]
        for i in np.unique(obs.obj[seen_from]):
            k = np.flatnonzero(seen_from & (obs.obj == i))
            if k.size < 2:
                continue
            d = np.einsum("kij,kj->ki", R[obs.step[k]], obs.ray[k])
            p, ok = triangulate(C[obs.step[k]], d)
            ahead = np.einsum("kj,kj->k", p - C[obs.step[k]], d) > 0
            if ok and ahead.all():
                P[i], grew = p, True
        if not grew:
            break
    return P, R, C
