"""Marginal covariances of the objects of a bundle adjustment, the viewpoints eliminated.

At the adjustment's solution the Gauss-Newton normal equations of the poses (one (3, 3) block
``U_t`` per step) and the free objects (``V``, and the coupling ``W``) are built once more,
undamped, with the loss's IRLS weights at the final residuals; eliminating the poses (Schur
complement) leaves the objects' information ``S = V - W^T U^-1 W``, and the (2, 2) diagonal blocks
of ``S^-1``, times the residuals' variance, are the objects' marginal covariances
(:func:`schur_information`, :func:`model_covariances` and :func:`sandwich_covariances` are
generic over the pose's size and the map's dimension: the 6-DoF adjustment in 3-D uses them too,
:mod:`mappers.spatial.marginals`) (Triggs et al.,
*Bundle Adjustment — A Modern Synthesis*, 2000, §9; Hartley & Zisserman, *Multiple View
Geometry*, 2nd ed., §5.2.3). The variance is the weighted residuals' ``sum(w r²) / (K - p)``
(``K`` residuals, ``p`` unknowns: 3 per used step, 2 per free object); with the robust weights it
is the IRLS estimate of the inliers' noise, so a wrong reading does not inflate every ellipse.

*Correlated readings*: the model above takes every reading's error as independent, and a
robot's consecutive readings are not (a landmark seen from nearly the same place, the same
misdetection, a sensor bias that drifts): on logged runs its ellipses are far too small. So a
second, robust covariance is computed from the same linearisation: the cluster-robust
("sandwich") covariance ``S^-1 (sum_b z_b z_b^T) S^-1 * B / (B - 1)``, with ``z_b`` the
reduced gradient (objects' part, the poses' part eliminated) of the readings of block ``b`` of
consecutive steps (``ceil(sqrt(N))`` steps of one robot; B blocks) — the estimate of
Huber (1967) and White (1980) with clusters (Liang & Zeger 1986), which holds when the readings
within a block are correlated and the loss is not the true likelihood. Each object gets the
larger (by trace) of the two covariances: the model's where the readings are independent, the
sandwich's where they are not.

*Gauge*: the anchors are held fixed at their known positions (zero covariance), as in the
adjustment itself; the uncertainty of the anchors' positions is not propagated (they are taken
as exact, as ``build_map`` takes them). Objects the adjustment left at their start map (seen
from too few steps, or along nearly parallel rays) are included as free objects of the same
linearisation: their ellipses are then long (or unbounded, ``inf``), which is what the readings
say about them. Steps the adjustment left out (no pose) contribute nothing.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from mappers.core.uncertainty import block_marginals
from mappers.viewpoints import range_bearing as rb
from mappers.viewpoints.bearing import BearingAdjustment
from mappers.viewpoints.engine import (
    DENSE_COUPLING_MAX_BYTES,
    bearing_angles,
    bearing_residuals,
    normal_blocks,
    pose_jacobian,
    robust_weights,
    use_sparse_coupling,
)
from mappers.viewpoints.range_bearing import RangeBearingAdjustment

__all__ = [
    "adjustment_covariances", "block_gradients", "has_model_covariances", "held_out_anchors", "model_covariances",
    "released_anchor", "released_steps", "restricted_parts", "sandwich_covariances",
    "schur_information",
    "step_blocks",
]


def schur_information(U: np.ndarray, V: np.ndarray, Wf: np.ndarray) -> np.ndarray:
    """The free objects' (dF, dF) information with the poses eliminated:
    ``blockdiag(V) - W^T U^-1 W`` for pose blocks ``U`` (N, p, p), object blocks ``V`` (F, d, d)
    and couplings ``Wf`` (N, p, dF) (p = 3 for a planar pose, 6 in space)."""
    f, d = V.shape[0], V.shape[1]
    S = np.zeros((d * f, d * f))
    idx = np.arange(f)[:, None] * d + np.arange(d)[None, :]
    S[idx[:, :, None], idx[:, None, :]] = V
    if len(U):
        Ui = np.linalg.inv(U + 1e-12 * np.eye(U.shape[1]))
        flat = Wf.reshape(-1, d * f)
        S -= flat.T @ (Ui @ Wf).reshape(-1, d * f)
    return S


def _frame(est, anchor_ids):
    """``(P, C, phi, used_steps, free, free_index)`` of a fitted adjustment."""
    P = np.asarray(est.embedding_, dtype=float)
    placed = np.all(np.isfinite(P), axis=1)
    free = placed.copy()
    free[np.asarray(anchor_ids, dtype=int)] = False
    used = np.all(np.isfinite(est.poses_), axis=1)
    C = np.where(used[:, None], est.poses_[:, :2], 0.0)
    phi = np.where(used, est.poses_[:, 2], 0.0)
    free_index = np.full(len(P), -1)
    free_index[free] = np.arange(free.sum())
    return np.where(placed[:, None], P, 0.0), C, phi, used, placed, free, free_index


def step_blocks(n_steps: int, timeline=None) -> np.ndarray:
    """The block of each step (N,) for the sandwich: runs of ``ceil(sqrt(N))`` consecutive
    steps, each robot's steps apart when a ``timeline`` ((N, 2) robot, tick) is given."""
    length = max(1, int(np.ceil(np.sqrt(n_steps))))
    if timeline is None:
        return np.arange(n_steps) // length
    tl = np.asarray(timeline)
    order = np.lexsort((tl[:, 1], tl[:, 0]))
    robot = tl[order, 0]
    start = np.r_[0, np.flatnonzero(np.diff(robot)) + 1]
    rank = np.arange(n_steps) - np.repeat(start, np.diff(np.r_[start, n_steps]))
    key = np.unique(np.column_stack([robot, rank // length]), axis=0, return_inverse=True)[1]
    out = np.empty(n_steps, dtype=int)
    out[order] = key.ravel()
    return out


def block_gradients(U, Wf, t, f, g_pose, g_obj, blocks, n_cols) -> np.ndarray:
    """(B, n_cols) the reduced gradient of the readings of each block (the objects' part, the
    poses' part eliminated): the ``z_b`` of :func:`sandwich_covariances`, whose arguments these
    are (``n_cols``: d times the number of unknown objects)."""
    n, p, d = len(U), U.shape[1], g_obj.shape[1]
    n_blocks = int(blocks.max()) + 1 if len(blocks) else 0
    Z = np.zeros((n_blocks, n_cols))
    k = f >= 0
    for c in range(d):
        np.add.at(Z, (blocks[t[k]], d * f[k] + c), g_obj[k, c])
    gp = np.zeros((n, p))
    np.add.at(gp, t, g_pose)
    y = np.linalg.solve(U + 1e-12 * np.eye(p), gp[..., None])[..., 0]
    np.add.at(Z, blocks, -np.einsum("nij,ni->nj", Wf, y))
    return Z


def sandwich_covariances(Sinv, U, Wf, t, f, g_pose, g_obj, blocks) -> np.ndarray:
    """The (F, d, d) cluster-robust covariances (module docstring), generic over the pose size
    ``p`` and the map's dimension ``d``: ``Sinv`` (dF, dF) the inverse of the objects' reduced
    information, ``U`` (N, p, p) and ``Wf`` (N, p, dF) the poses' blocks, ``g_pose`` (K, p) and
    ``g_obj`` (K, d) each reading's gradient, ``t`` its step (row of ``U``), ``f`` its free
    object (-1: none) and ``blocks`` (N,) each step's block."""
    d = g_obj.shape[1]
    Z = block_gradients(U, Wf, t, f, g_pose, g_obj, blocks, Sinv.shape[0])
    n_blocks = len(Z)
    A = (Z @ Sinv).reshape(n_blocks, -1, d)
    return np.einsum("bfi,bfj->fij", A, A) * n_blocks / max(n_blocks - 1, 1)


def model_covariances(S, U, Wf, sandwich_args, dof_resid, n_residuals, n_unknowns, P, free):
    """(M, d, d): the scaled marginals of ``S`` for the ``free`` objects, each replaced by its
    sandwich covariance (:func:`sandwich_covariances` of ``sandwich_args``) where that is wider
    by trace; zero for the other placed objects, NaN for unplaced ones (NaN rows of ``P``).
    The noise scale is ``dof_resid / (n_residuals - n_unknowns)``."""
    d = P.shape[1]
    cov = np.full((len(P), d, d), np.nan)
    placed = np.isfinite(P[:, 0])
    cov[placed] = 0.0  # the anchors (and the free objects, overwritten below)
    sigma2 = dof_resid / max(n_residuals - n_unknowns, 1)
    model = sigma2 * block_marginals(S, d)
    if S.shape[0] and np.all(np.isfinite(model)):
        Sinv = np.linalg.inv(0.5 * (S + S.T))
        robust = sandwich_covariances(Sinv, U, Wf, *sandwich_args)
        wider = np.trace(robust, axis1=1, axis2=2) > np.trace(model, axis1=1, axis2=2)
        model[wider] = robust[wider]
    cov[free] = model
    return cov


def _bearing_parts(est: BearingAdjustment, X, mask, anchor_ids, blocks, unknown):
    """The linearisation of a fitted bearing adjustment at its solution, ``unknown`` ((M,) bool)
    the objects taken as unknowns (its free objects; with the anchors too for
    :func:`held_out_anchors`): ``(U, V, Wf, g, h, sandwich_args, dof_resid, n_residuals,
    n_unknowns, index)`` (``index``: each object's row among the unknowns, -1 for none;
    ``n_unknowns`` counts the adjustment's own: its poses and free objects)."""
    P, C, phi, used, placed, free, _ = _frame(est, anchor_ids)
    unknown = unknown & placed
    index = np.full(len(P), -1)
    index[unknown] = np.arange(unknown.sum())
    limit = getattr(est, "dense_coupling_bytes", DENSE_COUPLING_MAX_BYTES)
    if use_sparse_coupling(len(C), 3, 2, int(unknown.sum()), limit):
        raise ValueError(
            f"model covariances of BEARING-BA hold the dense (N, 3, 2F) coupling, "
            f"{8 * 6 * len(C) * int(unknown.sum()) / 2**30:.1f} GiB for N = {len(C)} steps and "
            f"F = {int(unknown.sum())} free objects (above its dense_coupling_bytes, "
            f"{limit:.3g}); use uncertainty='bootstrap' or fewer steps")
    if sp.issparse(X):  # a compact history of a size the dense coupling fits
        X, mask = X.toarray(), (mask.toarray() if sp.issparse(mask) else mask)
    theta, seen = bearing_angles(X, mask)
    seen = seen & used[:, None] & placed[None, :]
    t, i = np.nonzero(seen)
    obs = (t, i, theta[t, i])
    res, _ = bearing_residuals(P, C, phi, obs)
    w = robust_weights(res, est.scale_, est.loss)
    U, V, Wf, g, h = normal_blocks(P, C, phi, obs, w, index, int(unknown.sum()))
    a = pose_jacobian(bearing_residuals(P, C, phi, obs)[1])
    gk = (w * res)[:, None] * a
    return (U, V, Wf, g, h, (t, index[i], gk, -gk[:, :2], blocks), float(np.sum(w * res * res)),
            len(t), 3 * int(used.sum()) + 2 * int(free.sum()), index)


def _range_bearing_parts(est: RangeBearingAdjustment, X, masks, anchor_ids, blocks, unknown):
    """:func:`_bearing_parts` of a fitted range-bearing adjustment."""
    masks = dict(masks or {})
    theta, seen = bearing_angles(X["bearing"], masks.get("bearing"))
    R = np.asarray(X["range"], dtype=float).T
    if masks.get("range") is not None:
        seen &= np.asarray(masks["range"], dtype=bool).T
    seen &= np.isfinite(R) & (R > 0)
    P, C, phi, used, placed, free, _ = _frame(est, anchor_ids)
    unknown = unknown & placed
    index = np.full(len(P), -1)
    index[unknown] = np.arange(unknown.sum())
    seen &= used[:, None] & placed[None, :]
    t, i = np.nonzero(seen)
    obs = (t, i, theta[t, i], R[t, i])
    wb = np.ones(len(t))
    # the adjustment's own blocks: scaled angle and range residuals, robust weights inside
    U, V, Wf, g, h = est._blocks(P, C, phi, obs, wb, est.scales_, index, int(unknown.sum()))
    ra, rr, d = rb.bearing_residuals(P, C, phi, obs)
    ua, ur = ra / est.scales_[0], rr / est.scales_[1]
    wa = robust_weights(ua, est.robust_scale, est.loss)
    wr = robust_weights(ur, est.robust_scale, est.loss)
    # each reading's gradient, as the adjustment's blocks build it: J^T W u over both residuals
    dist = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
    ga = (wa * ua / est.scales_[0])[:, None] * pose_jacobian(d)
    gr = (wr * ur / est.scales_[1])[:, None] * np.column_stack(
        [-d[:, 0] / dist, -d[:, 1] / dist, np.zeros_like(dist)])
    gk = ga + gr
    return (U, V, Wf, g, h, (t, index[i], gk, -gk[:, :2], blocks),
            float(np.sum(wa * ua * ua + wr * ur * ur)), 2 * len(t),
            3 * int(used.sum()) + 2 * int(free.sum()), index)


def _covariances(parts, P, free, S=None) -> np.ndarray:
    """:func:`model_covariances` of a linearisation ``parts``; ``S`` its reduced information
    when already at hand (:func:`schur_information` of its blocks)."""
    U, V, Wf, _, _, sandwich, dof, n_rows, n_unknowns, _ = parts
    S = schur_information(U, V, Wf) if S is None else S
    return model_covariances(S, U, Wf, sandwich, dof, n_rows, n_unknowns, P, free)


def released_steps(parts, free_rows, held_rows, prior: float | None = None, S=None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """For each of ``held_rows`` (rows of the unknowns of ``parts``, a linearisation as
    :func:`_bearing_parts` gives it, whose objects the adjustment held): the undamped
    Gauss-Newton steps from the solution when it alone is released, the objects of
    ``free_rows`` free, and its covariance then, the other held rows fixed
    (:func:`model_covariances`, the same noise scale). ``(steps (H, H, d), covariances
    (H, d, d))``: ``steps[j, k]`` the step of held row ``k`` when row ``j`` is released (zero
    for the others when they are held exactly, ``prior`` None; with ``prior``, the information
    ``prior * I`` of a held row's prior, as the adjustment with ``anchor_noise`` holds its
    anchors, the others move too and row ``j`` loses its prior). Generic over the pose's size
    and the map's dimension.

    At the solution the free objects' and the poses' gradients vanish (and a held row's
    readings balance its prior), so the step is what the released object's own readings pull
    it by, through the rest of the adjustment: the linearised leave-one-out prediction of a
    held object (the outlier test of a constraint, Baarda 1968; Koch, *Parameter Estimation
    and Hypothesis Testing in Linear Models*, 1999, §4.4), at the cost of a small solve instead
    of an adjustment again. ``S``: the unknowns' reduced information
    (:func:`schur_information` of ``parts``' blocks) when already at hand."""
    U, V, Wf, g, h, (t, f_all, gp, go, blocks), dof, n_rows, n_unknowns, _ = parts
    d = V.shape[1]
    free_rows = np.asarray(free_rows, dtype=int)
    held_rows = np.asarray(held_rows, dtype=int)
    # the poses eliminated once for all unknowns: a subset's reduced information and gradient
    # are the rows (and columns) of these
    S = schur_information(U, V, Wf) if S is None else S
    Ui = np.linalg.inv(U + 1e-12 * np.eye(U.shape[1]))
    z = h.reshape(-1) - Wf.reshape(-1, S.shape[0]).T @ np.einsum("nij,nj->ni", Ui, g).ravel()
    Z = block_gradients(U, Wf, t, f_all, gp, go, blocks, S.shape[0])
    n_blocks = len(Z)
    sigma2 = dof / max(n_rows - n_unknowns, 1)
    cols_of = lambda rows: (np.asarray(rows)[:, None] * d + np.arange(d)[None, :]).ravel()  # noqa: E731
    F, A = cols_of(free_rows), cols_of(held_rows)
    steps = np.zeros((len(held_rows), len(held_rows), d))
    covs = np.full((len(held_rows), d, d), np.nan)
    SFF = 0.5 * (S[np.ix_(F, F)] + S[np.ix_(F, F)].T)
    try:  # the free objects' block factored once; each released row is then a d x d Schur
        GS = scipy.linalg.cho_solve(scipy.linalg.cho_factor(SFF, lower=True), S[np.ix_(F, A)])
    except np.linalg.LinAlgError:  # a free object the readings do not pin down: its null
        GS = scipy.linalg.pinvh(SFF) @ S[np.ix_(F, A)]  # directions left out (pseudo-inverse)
    T = S[np.ix_(A, A)] - S[np.ix_(A, F)] @ GS  # the held rows' information, free ones eliminated
    y = z[A] - GS.T @ z[F]  # and their reduced gradient
    ZA = Z[:, A] - Z[:, F] @ GS  # each block's reduced gradient of the held rows
    for n in range(len(held_rows)):
        k = slice(n * d, (n + 1) * d)
        M = 0.5 * (T[k, k] + T[k, k].T)
        if not np.linalg.eigvalsh(M)[0] > 1e-12 * max(float(np.abs(M).max()), 1e-300):
            covs[n] = np.inf  # released, the row is not pinned down
            continue
        Minv = np.linalg.inv(M)
        if prior is None:
            steps[n, n] = -Minv @ y[k]
        else:  # the other held rows keep their prior; their readings balance it (y = 0)
            T2 = T + prior * np.eye(len(A))
            T2[k, k] = T[k, k]
            y2 = np.zeros(len(A))
            y2[k] = y[k]
            steps[n] = -np.linalg.solve(T2, y2).reshape(-1, d)
        model = sigma2 * Minv
        a = ZA[:, k] @ Minv
        robust = a.T @ a * n_blocks / max(n_blocks - 1, 1)
        covs[n] = robust if np.trace(robust) > np.trace(model) else model
    return steps, covs


def _bearing(est: BearingAdjustment, X, mask, anchor_ids, blocks) -> np.ndarray:
    free = _frame(est, anchor_ids)[5]
    return _covariances(_bearing_parts(est, X, mask, anchor_ids, blocks, free),
                        est.embedding_, free)


def _range_bearing(est: RangeBearingAdjustment, X, masks, anchor_ids, blocks) -> np.ndarray:
    free = _frame(est, anchor_ids)[5]
    return _covariances(_range_bearing_parts(est, X, masks, anchor_ids, blocks, free),
                        est.embedding_, free)


def _adjustment(est):
    """The bundle adjustment inside a fitted estimator (itself, or a fused map's refinement)."""
    if isinstance(est, BearingAdjustment | RangeBearingAdjustment):
        return est
    inner = getattr(est, "adjustment_", None)
    return inner if isinstance(inner, BearingAdjustment | RangeBearingAdjustment) else None


def released_anchor(est, X, mask, anchor_ids, anchor_positions, j, timeline=None):
    """The ``j``-th anchor held out of the fitted adjustment in ``est``: the same adjustment
    (its parameters) fitted again from ``est``'s map with that anchor free and the others held,
    and the held-out anchor's ``(position, covariance)`` there (:func:`adjustment_covariances`).
    ``X``, ``mask`` and ``timeline`` as for :func:`adjustment_covariances`; ``anchor_ids`` rows of
    ``X``, ``anchor_positions`` (A, 2). The adjustment starts from the full map, so a held-out
    anchor is placed where the pipeline's start map could not place it without that anchor (a
    sparse logged run); the readings and the other anchors decide where it goes."""
    from sklearn.base import clone

    adj = _adjustment(est)
    if adj is None:
        raise ValueError(f"{type(est).__name__} holds no bundle adjustment")
    ids = np.asarray(anchor_ids, dtype=int)
    keep = np.arange(len(ids)) != j
    new = clone(adj)
    start = np.asarray(adj.embedding_, dtype=float)
    pos = np.asarray(anchor_positions, dtype=float)[keep]
    if isinstance(adj, RangeBearingAdjustment):
        new.fit(X, masks=mask, anchor_ids=ids[keep], anchor_positions=pos, start_positions=start)
    else:
        Xb, Mb = (X["bearing"], (mask or {}).get("bearing")) if isinstance(X, dict) else (X, mask)
        new.fit(Xb, mask=Mb, anchor_ids=ids[keep], anchor_positions=pos, start_positions=start)
    cov = adjustment_covariances(new, X, mask, ids[keep], timeline)
    return new.embedding_[ids[j]], cov[ids[j]]


def has_model_covariances(est) -> bool:
    """Whether the fitted estimator ``est`` is (or ends with) a bundle adjustment whose normal
    equations give covariances: BEARING-BA, and LOC-SMA refined by an adjustment."""
    return _adjustment(est) is not None


def adjustment_covariances(est, X, mask, anchor_ids, timeline=None) -> np.ndarray:
    """(M, 2, 2) marginal covariances of the objects of the fitted adjustment in ``est``, in its
    output frame (module docstring): zero for the anchors, NaN for objects it did not place.

    ``X`` and ``mask`` are what ``est`` was fitted on (a bearing history and mask, or fused
    histories and their masks); ``anchor_ids`` the anchors' rows; ``timeline`` ((N, 2) robot and
    tick of each step, or None) keeps each robot's steps apart in the sandwich's blocks.
    ValueError when ``est`` holds no adjustment (:func:`has_model_covariances`)."""
    adj = _adjustment(est)
    if adj is None:
        raise ValueError(f"{type(est).__name__} holds no bundle adjustment: no model covariances")
    blocks = step_blocks(len(adj.poses_), timeline)
    if isinstance(adj, RangeBearingAdjustment):
        return _range_bearing(adj, X, mask, anchor_ids, blocks)
    if isinstance(X, dict):  # a fused map refined by the bearing-only adjustment
        X, mask = X["bearing"], (mask or {}).get("bearing")
    return _bearing(adj, X, mask, anchor_ids, blocks)


def restricted_parts(parts, rows: np.ndarray):
    """``parts`` (a linearisation as :func:`_bearing_parts` gives it) with only the unknowns
    ``rows`` (increasing): the blocks and sandwich terms of the others dropped, each kept
    object renumbered -- the linearisation with the other objects held, as
    :func:`_bearing_parts` of those unknowns alone builds it (each kept object's blocks are sums
    over its own readings, and the poses' over all readings, in both)."""
    U, V, Wf, g, h, (t, f, gp, go, blocks), dof, n_rows, n_unknowns, index = parts
    d = V.shape[1]
    remap = np.full(len(V), -1)
    remap[rows] = np.arange(len(rows))
    cols = (np.asarray(rows)[:, None] * d + np.arange(d)[None, :]).ravel()
    renumber = lambda a: np.where(a >= 0, remap[np.maximum(a, 0)], -1)  # noqa: E731
    return (U, V[rows], Wf[:, :, cols], g, h[rows], (t, renumber(f), gp, go, blocks), dof,
            n_rows, n_unknowns, renumber(index))


def held_out_anchors(est, X, mask, anchor_ids, timeline=None, with_covariances: bool = False):
    """Each anchor of the fitted adjustment in ``est`` held out, linearised: its position
    (A, 2) and covariance (A, 2, 2) in the adjustment's frame when it alone is released and the
    other anchors held (:func:`released_steps`; one step from the solution, no adjustment
    again). Arguments as for :func:`adjustment_covariances`. An anchor its readings do not pin
    down (a non-finite covariance) gets NaN rows. ``with_covariances``: also the objects'
    covariances (M, 2, 2) of :func:`adjustment_covariances`, from the same linearisation (built
    once: ``uncertainty=True`` needs both)."""
    adj = _adjustment(est)
    if adj is None:
        raise ValueError(f"{type(est).__name__} holds no bundle adjustment")
    blocks = step_blocks(len(adj.poses_), timeline)
    if isinstance(adj, RangeBearingAdjustment):
        make = _range_bearing_parts
    else:
        make = _bearing_parts
        if isinstance(X, dict):  # a fused map refined by the bearing-only adjustment
            X, mask = X["bearing"], (mask or {}).get("bearing")
    ids = np.asarray(anchor_ids, dtype=int)
    P, _, _, _, placed, free, _ = _frame(adj, ids)
    parts = make(adj, X, mask, ids, blocks, placed)
    index = parts[-1]
    S = schur_information(*parts[:3])
    steps, covs = released_steps(parts, index[free], index[ids], S=S)
    pos = np.asarray(adj.embedding_, dtype=float)[ids] + np.diagonal(steps).T
    bad = ~np.all(np.isfinite(covs), axis=(1, 2)) | ~np.all(np.isfinite(pos), axis=1)
    pos[bad], covs[bad] = np.nan, np.nan
    if not with_covariances:
        return pos, covs
    rows = index[free]
    cols = (rows[:, None] * parts[1].shape[1] + np.arange(parts[1].shape[1])[None, :]).ravel()
    # (the free objects' reduced information is the block of the unknowns': the poses'
    # elimination is linear in the objects' columns)
    model = _covariances(restricted_parts(parts, rows), adj.embedding_, free, S[np.ix_(cols, cols)])
    return pos, covs, model

