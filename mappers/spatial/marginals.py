"""Marginal covariances of the objects of the 6-DoF adjustment (``SPATIAL-BA``), the viewpoints
eliminated: the 3-D form of :mod:`mappers.viewpoints.marginals`.

At the adjustment's solution (before the similarity onto the anchors, when ``anchor_noise`` is
set) the Gauss-Newton normal blocks of the steps' poses (6 x 6: rotation vector and position)
and of the free objects (3 x 3) are built once more, undamped, with the robust loss's weights
at the final residuals (:func:`mappers.spatial.adjustment.normal_blocks`, the adjustment's own).
The poses are eliminated by the Schur complement
(:func:`mappers.viewpoints.marginals.schur_information`) and the (3, 3) diagonal blocks of the
inverse, times the robustly weighted residuals' variance ``sum(w |e|²) / (K - p)`` (K residual
rows: two angles per sighting and one per range; p unknowns: 6 per posed step, 3 per free
object), are the objects' marginal covariances (Triggs et al., *Bundle Adjustment — A Modern
Synthesis*, 2000, §9; Hartley & Zisserman, *Multiple View Geometry*, 2nd ed., §5.2.3). As in
2-D, each object gets the wider (by trace) of that and the cluster-robust ("sandwich")
covariance over blocks of ``ceil(sqrt(N))`` consecutive steps (Huber 1967; White 1980; Liang &
Zeger 1986; :func:`mappers.viewpoints.marginals.model_covariances`).

*Gauge*: the anchors are held fixed (zero covariance) — with ``anchor_noise`` too: their prior
is what places the map on them, and ``build_map`` takes the anchors' positions as exact. The
covariances are then carried to the output frame by the similarity ``s R`` (``s² R C Rᵀ``).
Objects the adjustment placed but :class:`~mappers.spatial.spatial_ba.SpatialAdjustment` left
out as inconsistent get NaN, like its positions.

*Free directions*: an object the posed steps fix only up to a turn (seen by one posed step with
two other objects) is placed along that turn by the start's pose-free distances; the directions
the objects' reduced information leaves free get the information of the distances of the steps
the adjustment left out with two objects, the others keep the adjustment's
(:mod:`mappers.spatial.pair_distances`).
"""

from __future__ import annotations

import numpy as np

from mappers.core.align_3d import umeyama
from mappers.spatial.adjustment import Problem, normal_blocks
from mappers.spatial.pair_distances import complete_free_directions, pair_distance_information
from mappers.viewpoints import (
    DENSE_COUPLING_MAX_BYTES,
    model_covariances,
    released_steps,
    restricted_parts,
    robust_weights,
    schur_information,
    step_blocks,
    use_sparse_coupling,
)

__all__ = ["spatial_covariances", "spatial_held_out"]


def _parts(est, unknown_anchors: bool):
    """The linearisation of a fitted SPATIAL-BA at its solution (before the similarity):
    ``(parts, placed, free, index)``, ``parts`` as :func:`mappers.viewpoints.released_steps`
    takes it, its unknowns the free objects (and the anchors, ``unknown_anchors``), ``index``
    each object's row among them (-1: none)."""
    if not hasattr(est, "adjusted_"):
        raise ValueError(f"{type(est).__name__} is not fitted: no model covariances")
    obs, res, ids = est.observations_, est.adjusted_, est.anchor_ids_
    P, R, C = res.points, res.rotations, res.positions
    placed = np.all(np.isfinite(P), axis=1)
    posed = np.all(np.isfinite(C), axis=1)
    keep = placed[obs.obj] & posed[obs.step]
    prob = Problem(obs, keep, est.bearing_noise, est.range_noise, est.range_growth)
    free = placed.copy()
    free[np.asarray(ids, dtype=int)] = False
    unknown = placed if unknown_anchors else free
    index = np.full(len(P), -1)
    index[unknown] = np.arange(unknown.sum())
    n_unknown = int(unknown.sum())
    steps = np.flatnonzero(posed)
    step_index = np.full(len(C), -1)
    step_index[steps] = np.arange(steps.size)
    Pz = np.where(placed[:, None], P, 0.0)
    e, v, nv, vh = prob.residuals(Pz, R, C)
    w = robust_weights(np.linalg.norm(e, axis=1), est.loss_scale, est.loss)
    Jc, Jp = prob.jacobians(R, v, nv, vh)
    t = step_index[prob.t]
    limit = getattr(est, "dense_coupling_bytes", DENSE_COUPLING_MAX_BYTES)
    if use_sparse_coupling(steps.size, 6, 3, n_unknown, limit):
        raise ValueError(
            f"model covariances of SPATIAL-BA hold the dense (N, 6, 3F) coupling, "
            f"{8 * 18 * steps.size * n_unknown / 2**30:.2f} GiB for N = {steps.size} steps "
            f"and F = {n_unknown} free objects (above its dense_coupling_bytes, "
            f"{limit:.3g}); use fewer steps")
    U, V, Wf, g, h = normal_blocks(prob, e, w, Jc, Jp, t, index, steps.size, n_unknown)
    we = w[:, None] * e
    g_pose = np.einsum("kri,kr->ki", Jc, we)
    g_obj = np.einsum("kri,kr->ki", Jp, we)
    blocks = np.unique(step_blocks(obs.n_steps)[steps], return_inverse=True)[1].ravel()
    n_rows = 2 * len(e) + int(prob.has_r.sum())
    parts = (U, V, Wf, g, h, (t, index[prob.i], g_pose, g_obj, blocks),
             float(np.sum(w * np.sum(e * e, axis=1))), n_rows,
             6 * steps.size + 3 * int(free.sum()), index)
    return parts, placed, free, index


def _completed(est, S: np.ndarray, free: np.ndarray) -> np.ndarray:
    """The free objects' reduced information ``S`` with the directions the adjustment leaves
    free given the information of the image pairs it left out
    (:func:`mappers.spatial.pair_distances.complete_free_directions`; ``S`` as it is when it
    has none)."""
    res = est.adjusted_
    index = np.full(len(free), -1)
    index[free] = np.arange(free.sum())
    D = pair_distance_information(
        est.observations_, res.points, np.all(np.isfinite(res.positions), axis=1), index,
        int(free.sum()), bearing_noise=est.bearing_noise, range_noise=est.range_noise,
        range_growth=est.range_growth, loss=est.loss, loss_scale=est.loss_scale)
    return complete_free_directions(S, D)


def _to_output(est, cov: np.ndarray) -> np.ndarray:
    """Covariances (M, 3, 3) of the adjusted map carried by its similarity onto the anchors."""
    Rs, scale, _ = est.similarity_
    A = scale * np.asarray(Rs)
    cov = np.array(cov, dtype=float)
    finite = np.all(np.isfinite(cov), axis=(1, 2))
    cov[finite] = np.einsum("ij,mjk,lk->mil", A, cov[finite], A)
    cov[np.any(np.isinf(cov), axis=(1, 2))] = np.inf  # unbounded in some direction: in any frame
    return cov


def spatial_covariances(est) -> np.ndarray:
    """(M, 3, 3) model covariances of a fitted :class:`~mappers.spatial.spatial_ba.SpatialAdjustment`
    ``est`` in its output frame (module docstring): zero for the anchors, NaN for the objects it
    did not place. ValueError for an estimator that was not fitted."""
    parts, placed, free, _ = _parts(est, False)
    U, V, Wf, _, _, sandwich, dof, n_rows, n_unknowns, _ = parts
    P = np.where(placed[:, None], est.adjusted_.points, np.nan)
    S = _completed(est, schur_information(U, V, Wf), free)
    cov = _to_output(est, model_covariances(S, U, Wf, sandwich, dof, n_rows, n_unknowns, P,
                                            free))
    cov[~np.all(np.isfinite(est.embedding_), axis=1)] = np.nan
    return cov


def spatial_held_out(est, anchor_positions, with_covariances: bool = False):
    """Each anchor of a fitted SPATIAL-BA held out, linearised: its position (A, 3) and
    covariance (A, 3, 3) in the output frame when it alone is released from the adjustment, by
    Gauss-Newton steps from the solution (:func:`mappers.viewpoints.released_steps`). Anchors
    held exactly: the others stay. With ``anchor_noise``: the released anchor loses its prior,
    the others keep theirs and move with it, and the similarity onto the anchors is fitted
    again to the others (``anchor_positions`` (A, 3), what ``est`` was fitted with). The
    covariance is the model's with the other anchors fixed (as :func:`spatial_covariances`),
    carried by the similarity. NaN rows for an anchor its readings do not pin down (a
    non-finite covariance). ``with_covariances``: also the objects' covariances (M, 3, 3) of
    :func:`spatial_covariances`, from the same linearisation (built once: ``uncertainty=True``
    needs both)."""
    parts, placed, free, index = _parts(est, True)
    ids = np.asarray(est.anchor_ids_, dtype=int)
    target = np.asarray(anchor_positions, dtype=float)
    soft = est.anchor_noise is not None
    S = schur_information(*parts[:3])
    steps, covs = released_steps(parts, index[free], index[ids],
                                 est.anchor_noise ** -2.0 if soft else None, S=S)
    covs = _to_output(est, covs)
    Rs, scale, shift = est.similarity_
    pos = np.full((len(ids), 3), np.nan)
    for j in range(len(ids)):
        moved = est.adjusted_.points[ids] + steps[j]
        if soft and len(ids) > 3:  # the similarity onto the other anchors, as a map without j
            keep = np.arange(len(ids)) != j
            Rs, scale, shift = umeyama(moved[keep], target[keep], True)
        pos[j] = scale * moved[j] @ np.asarray(Rs).T + shift
    bad = ~np.all(np.isfinite(covs), axis=(1, 2)) | ~np.all(np.isfinite(pos), axis=1)
    pos[bad], covs[bad] = np.nan, np.nan
    if not with_covariances:
        return pos, covs
    rows = index[free]
    cols = (rows[:, None] * 3 + np.arange(3)[None, :]).ravel()
    U, _, Wf, _, _, sandwich, dof, n_rows, n_unknowns, _ = restricted_parts(parts, rows)
    # (the free objects' reduced information is the block of the unknowns': the poses'
    # elimination is linear in the objects' columns)
    P = np.where(placed[:, None], est.adjusted_.points, np.nan)
    model = _to_output(est, model_covariances(_completed(est, S[np.ix_(cols, cols)], free), U,
                                              Wf, sandwich, dof, n_rows, n_unknowns, P, free))
    model[~np.all(np.isfinite(est.embedding_), axis=1)] = np.nan
    return pos, covs, model
