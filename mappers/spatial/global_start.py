"""A rays-only start by global structure from motion: all steps at once, the anchors only at
the end.

1. The view graph: pairs of steps that share ``min_shared`` or more objects, each step keeping
   the partners it shares the most with; each pair's relative rotation from its rays alone
   (:mod:`mappers.spatial.relative_rotations`: the eight-point essential matrix, or the pure
   rotation where the steps barely moved).
2. The steps' rotations by rotation averaging over the graph's largest connected part
   (:mod:`mappers.spatial.rotation_averaging`); pairs that disagree with the average by more
   than ``max_pair_error`` are dropped and the average taken again.
3. With the rotations known, the steps' and objects' positions are one sparse linear
   least-squares problem (:mod:`mappers.spatial.known_rotations`), up to a similarity.
4. The similarity that takes the anchors' places onto their positions (Umeyama 1991) puts the
   whole in the world.

No odometry, no motion model, no order of the steps: every step's pose comes from what it saw,
and the anchors are used only to place the finished structure (so a sequence where no image
sees three anchors is mapped as well as one where many do). This is the route of global
structure-from-motion systems (e.g. Moulon et al., *Global fusion of relative motions for
robust, accurate and scalable structure from motion*, ICCV 2013; Wilson & Snavely, *Robust
global translations with 1DSfM*, ECCV 2014), written here on NumPy/SciPy because no maintained
Python library takes rays with unknown poses and no images.
"""

from __future__ import annotations

import numpy as np

from mappers.core.align_3d import umeyama
from mappers.spatial.known_rotations import positions_from_rotations, solvable
from mappers.spatial.rays import RayObservations
from mappers.spatial.registration import register_rays
from mappers.spatial.relative_rotations import relative_rotations, view_pairs
from mappers.spatial.rotation_averaging import average_rotations, largest_component

__all__ = ["register_global"]


def register_global(obs: RayObservations, anchor_ids: np.ndarray, anchor_positions: np.ndarray,
                    *, noise: float, min_shared: int = 8, per_step: int = 10,
                    max_pair_error: float = np.deg2rad(5.0), grow: bool = True):
    """``(P, R, C)``: points (M, 3), rotations sensor -> world (N, 3, 3) and positions (N, 3)
    from the rays alone by global structure from motion (see the module's docstring), NaN
    where not placed; all NaN when the steps that share ``min_shared`` (>= 8) objects do not
    form a graph whose structure holds three anchors not on one line. ``noise`` [rad]: the
    rays' angle noise; ``per_step``: the partners each step keeps in the view graph;
    ``max_pair_error`` [rad]: a pair's rotation further than this from the average is
    dropped."""
    if min_shared < 8:
        raise ValueError(f"min_shared must be >= 8 (the eight-point algorithm), got {min_shared}")
    if not noise > 0:
        raise ValueError(f"noise must be > 0, got {noise!r}")
    m, n = obs.n_objects, obs.n_steps
    P, R, C = np.full((m, 3), np.nan), np.full((n, 3, 3), np.nan), np.full((n, 3), np.nan)
    per = np.bincount(obs.step, minlength=n)
    a, b, ka, kb, pair = view_pairs(obs, np.flatnonzero(per >= min_shared), min_shared, per_step)
    if len(a) == 0:
        return P, R, C
    pr = relative_rotations(obs, a, b, ka, kb, pair, noise=noise)
    good = (pr.inliers >= min_shared) & (pr.residual < max(3.0 * noise, np.deg2rad(0.5)))
    a, b, rel, weight = a[good], b[good], pr.rotation[good], pr.inliers[good]
    for _ in range(2):  # average, drop the pairs the average disowns, average again
        core = largest_component(a, b, n)
        on = core[a] & core[b]
        a, b, rel, weight = a[on], b[on], rel[on], weight[on]
        if len(a) == 0:
            return P, R, C
        Rg, res = average_rotations(a, b, rel, n, weights=weight)
        ok = res < max_pair_error
        if ok.all():
            break
        a, b, rel, weight = a[ok], b[ok], rel[ok], weight[ok]
    steps, objects = solvable(obs, np.isfinite(Rg[:, 0, 0]))
    if not objects.any():
        return P, R, C
    X, Cg, _ = positions_from_rotations(obs, Rg, steps, objects, noise=noise)
    Rg = np.where(steps[:, None, None], Rg, np.nan)
    if grow:  # in the structure's own frame: steps resected, objects intersected
        none = np.zeros(0, dtype=np.int64)
        X, Rg, Cg = register_rays(obs, none, np.zeros((0, 3)), start=(X, Rg, Cg))
        steps = np.isfinite(Cg[:, 0])
    ids = np.asarray(anchor_ids)
    placed = ids[np.isfinite(X[ids, 0])]
    if placed.size < 3:
        return P, R, C
    target = anchor_positions[np.isfinite(X[ids, 0])]
    if np.linalg.svd(target - target.mean(axis=0), compute_uv=False)[1] < 1e-3:
        return P, R, C
    Rs, s, t = umeyama(X[placed], target, True)
    P = s * X @ Rs.T + t
    C = s * Cg @ Rs.T + t
    R = Rs @ Rg
    return P, R, C
