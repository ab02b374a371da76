"""The 6-DoF viewpoint bundle adjustment: the 3-D form of BEARING-BA and of the range-bearing
adjustment.

Each step's viewpoint is a pose of space: a rotation (sensor -> world, updated by a rotation
vector, ``R <- R exp([delta]x)``) and a position ``c``. An object at ``p`` is seen along
``v = R^T (p - c)``. The residuals of a sighting are the ray's angle error in its two tangent
directions (divided by ``bearing_noise``) and, where a range was measured, ``|v| - range``
(divided by ``range_noise``). The objects and the poses are estimated jointly by
Levenberg-Marquardt with each pose's 6 x 6 block eliminated by the Schur complement, on the
engine the planar adjustments use (:func:`mappers.viewpoints.schur_step`, Triggs et al., *Bundle
Adjustment — A Modern Synthesis*, 2000), under a Cauchy or Huber loss (iteratively reweighted)
so that a wrong detection does not pull the map. The anchors are held fixed, which fixes the
gauge (position, rotation and, for rays alone, scale). No motion model: the steps' poses are
independent of one another.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial.transform import Rotation

from mappers.spatial import adjustment_kernels as kernels
from mappers.spatial.rays import RayObservations
from mappers.viewpoints import (
    DENSE_COUPLING_MAX_BYTES,
    Coupling,
    Damping,
    damped_step,
    robust_cost,
    robust_weights,
    scatter_sum,
    schur_step,
    use_sparse_coupling,
)

__all__ = ["DAMPING", "AdjustmentResult", "Problem", "adjust_viewpoints", "normal_blocks"]

DAMPING = Damping(up=10.0, down=10.0, floor=1e-9, tries=None, ceiling=1e8, accept_equal=False)
"""The 6-DoF adjustment's Levenberg-Marquardt damping rule (:class:`mappers.viewpoints.Damping`):
raised until a step lowers the cost or the damping reaches 1e8."""


class AdjustmentResult(NamedTuple):
    """The adjusted points (M, 3), rotations (N, 3, 3), positions (N, 3), the final robust cost
    the number of Levenberg-Marquardt iterations, and the factor the ranges were multiplied by
    (``fit_range_scale``)."""

    points: np.ndarray
    rotations: np.ndarray
    positions: np.ndarray
    cost: float
    n_iter: int
    range_scale: float = 1.0


def _skew(v: np.ndarray) -> np.ndarray:
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], 1), np.stack([v[:, 2], z, -v[:, 0]], 1),
                     np.stack([-v[:, 1], v[:, 0], z], 1)], 1)


def _tangent_bases(u: np.ndarray) -> np.ndarray:
    """(K, 3, 2): two unit vectors perpendicular to each unit ray and to each other."""
    helper = np.where(np.abs(u[:, [0]]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    b1 = np.cross(u, helper)
    b1 /= np.linalg.norm(b1, axis=1, keepdims=True)
    return np.stack([b1, np.cross(u, b1)], axis=2)


class Problem:
    """The sightings of the registered steps, with their noise, in the form the solver needs."""

    def __init__(self, obs: RayObservations, keep: np.ndarray, bearing_noise: float,
                 range_noise: float, range_growth: float):
        self.t, self.i, self.u = obs.step[keep], obs.obj[keep], obs.ray[keep]
        r = obs.range[keep]
        self.has_r = np.isfinite(r)
        self.r = np.where(self.has_r, r, 0.0)
        self.B = _tangent_bases(self.u)
        self.sb = bearing_noise
        self.sr = range_noise + range_growth * self.r**2

    def residuals(self, P, R, C):
        """(K, 3) normalised residuals (the range row 0 where none was measured) and the
        offsets ``v`` in the sensor's frame."""
        v = np.einsum("kji,kj->ki", R[self.t], P[self.i] - C[self.t])
        nv = np.maximum(np.linalg.norm(v, axis=1), 1e-9)
        vh = v / nv[:, None]
        e = np.zeros((len(v), 3))
        e[:, :2] = np.einsum("kjb,kj->kb", self.B, vh) / self.sb
        e[:, 2] = np.where(self.has_r, (nv - self.r) / self.sr, 0.0)
        return e, v, nv, vh

    def jacobians(self, R, v, nv, vh):
        """d residual / d pose (K, 3, 6) and d residual / d point (K, 3, 3)."""
        proj = np.eye(3)[None] - vh[:, :, None] * vh[:, None, :]
        de = np.empty((len(v), 3, 3))
        de[:, :2] = np.einsum("kjb,kjl->kbl", self.B, proj) / (nv * self.sb)[:, None, None]
        de[:, 2] = np.where(self.has_r[:, None], vh / self.sr[:, None], 0.0)
        Rt = R[self.t].transpose(0, 2, 1)
        Jp = de @ Rt
        Jc = np.concatenate([de @ _skew(v), -Jp], axis=2)
        return Jc, Jp


def adjust_viewpoints(obs: RayObservations, P0: np.ndarray, R0: np.ndarray, C0: np.ndarray,
                      fixed: np.ndarray, *, bearing_noise: float = np.deg2rad(1.0),
                      range_noise: float = 0.02, range_growth: float = 0.0,
                      loss: str | None = "cauchy", loss_scale: float = 3.0,
                      max_iter: int = 100, tol: float = 1e-10,
                      fit_range_scale: bool = False, scale_rounds: int = 4,
                      anchor_noise: float | None = None,
                      dense_coupling_bytes: float = DENSE_COUPLING_MAX_BYTES,
                      gain_tol: float = 0.0) -> AdjustmentResult:
    """Adjust the points and the steps' poses to the sightings (see the module's docstring).

    Args:
        obs: the sightings (:func:`mappers.spatial.rays.ray_observations`).
        P0: (M, 3) start points; NaN rows are objects not placed (their sightings are unused).
        R0, C0: (N, 3, 3) rotations sensor -> world and (N, 3) positions; NaN: step not used.
        fixed: (M,) bool, the objects held where they are (the anchors).
        bearing_noise: the rays' angle noise [rad] the residuals are divided by.
        range_noise, range_growth: a range's noise [m] is ``range_noise + range_growth *
            range**2`` (a stereo camera's depth error grows with the square of the depth).
        loss: "cauchy", "huber" or None (least squares), at ``loss_scale`` noise units.
        max_iter, tol: at most this many iterations; stop when the cost falls by less than
            ``tol`` of itself.
        gain_tol: also stop when an iteration lowers the cost by at most this share of the cost
            the adjustment started from (as BEARING-BA's ``gain_tol``; 0: only ``tol``): the
            sightings are explained no better, while a robust loss's reweighting and a
            weakly fixed pose can keep the cost creeping down for dozens of iterations.
        fit_range_scale: also estimate one factor of all ranges (a stereo camera's depth is
            ``focal * baseline / disparity``, so an error of its calibration scales every range
            alike; STAR-loc's are 1.5-3 % short): after each adjustment the ranges are
            multiplied by the median ratio of the adjusted distances to them, ``scale_rounds``
            times at most (the anchors, held fixed, set the scale).
        anchor_noise: None: the ``fixed`` objects are held exactly where they are; a number
            [m]: they are adjusted too, held by a prior of that standard deviation (the anchors'
            survey error), so that the map keeps the shape its sightings give it.
        dense_coupling_bytes: the pose-point coupling is a dense (N, 6, 3F) array up to this
            many bytes, above it one block per sighting with the points' reduced system sparse
            (:mod:`mappers.viewpoints.sparse_schur`, the same step to rounding).
    """
    if anchor_noise is not None and not anchor_noise > 0:
        raise ValueError(f"anchor_noise must be None or > 0, got {anchor_noise!r}")
    if not 0.0 <= gain_tol < 1.0:
        raise ValueError(f"gain_tol must be in [0, 1), got {gain_tol!r}")
    result = _adjust(obs, P0, R0, C0, fixed, bearing_noise, range_noise, range_growth, loss,
                     loss_scale, max_iter, tol, anchor_noise, dense_coupling_bytes, gain_tol)
    has_r = np.isfinite(obs.range)
    factor = 1.0
    for _ in range(scale_rounds if fit_range_scale and has_r.any() else 0):
        P, R, C = result.points, result.rotations, result.positions
        used = has_r & np.all(np.isfinite(P[obs.obj]), axis=1) & np.isfinite(C[obs.step, 0])
        if not used.any():
            break
        dist = np.linalg.norm(P[obs.obj[used]] - C[obs.step[used]], axis=1)
        k = float(np.median(dist / obs.range[used]))
        factor *= k
        obs = obs._replace(range=obs.range * k)
        result = _adjust(obs, P, R, C, fixed, bearing_noise, range_noise, range_growth, loss,
                         loss_scale, max_iter, tol, anchor_noise, dense_coupling_bytes, gain_tol)
        if abs(k - 1.0) < 1e-4:
            break
    return result._replace(range_scale=factor)


def _adjust(obs, P0, R0, C0, fixed, bearing_noise, range_noise, range_growth, loss, loss_scale,
            max_iter, tol, anchor_noise=None,
            dense_coupling_bytes=DENSE_COUPLING_MAX_BYTES, gain_tol=0.0) -> AdjustmentResult:
    """One adjustment of :func:`adjust_viewpoints` (the ranges as they are)."""
    if loss not in ("cauchy", "huber", None):
        raise ValueError(f"loss must be 'cauchy', 'huber' or None, got {loss!r}")
    if not bearing_noise > 0 or not range_noise > 0 or range_growth < 0:
        raise ValueError("bearing_noise and range_noise must be > 0, range_growth >= 0")
    P, R, C = P0.copy(), R0.copy(), C0.copy()
    placed = np.all(np.isfinite(P), axis=1)
    posed = np.all(np.isfinite(C), axis=1)
    keep = np.flatnonzero(placed[obs.obj] & posed[obs.step])
    # by step (ray_observations gives them so): the compiled step takes each step's sightings
    # as one run
    keep = keep[np.argsort(obs.step[keep], kind="stable")]
    prob = Problem(obs, keep, bearing_noise, range_noise, range_growth)
    fixed = np.asarray(fixed, dtype=bool)
    free = placed & (~fixed if anchor_noise is None else np.ones(len(P), dtype=bool))
    free_index = np.full(len(P), -1)
    free_index[free] = np.arange(free.sum())
    soft = np.flatnonzero(fixed & free)  # anchors held by a prior of anchor_noise [m]
    target = P0[soft]
    steps = np.flatnonzero(posed)
    step_index = np.full(len(C), -1)
    step_index[steps] = np.arange(steps.size)
    sparse = use_sparse_coupling(steps.size, 6, 3, int(free.sum()), dense_coupling_bytes)

    t_rows = step_index[prob.t]
    if not sparse:
        indptr = np.zeros(steps.size + 1, dtype=np.int64)
        np.cumsum(np.bincount(t_rows, minlength=steps.size), out=indptr[1:])

    def cost_of(P, R, C):
        res = prob.residuals(P, R, C)
        prior = 0.0 if not soft.size else 0.5 * np.sum((P[soft] - target) ** 2) / anchor_noise**2
        return float(robust_cost(np.linalg.norm(res[0], axis=1), loss_scale, loss).sum()) + prior, res

    cost, res = cost_of(P, R, C)
    first, lam, it = cost, 1e-3, 0
    for it in range(1, max_iter + 1):  # noqa: B007 - the count is returned
        e, v, nv, vh = res
        w = robust_weights(np.linalg.norm(e, axis=1), loss_scale, loss)
        if sparse:
            Jc, Jp = prob.jacobians(R, v, nv, vh)
            step_blocks = normal_blocks(prob, e, w, Jc, Jp, t_rows, free_index, steps.size,
                                        int(free.sum()), True)
        else:
            step_blocks = _compiled_blocks(prob, res, w, R, t_rows, free_index, indptr,
                                           steps.size, int(free.sum()))
        if soft.size:  # the anchors' prior: (p - anchor) / anchor_noise, Jacobian I / noise
            step_blocks[1][free_index[soft]] += np.eye(3) / anchor_noise**2
            step_blocks[4][free_index[soft]] += (P[soft] - target) / anchor_noise**2

        def trial(lam, step_blocks=step_blocks, P=P, R=R, C=C):
            dc, dp = (schur_step if sparse else _compiled_step)(*step_blocks, lam)
            Pn, Rn, Cn = P.copy(), R.copy(), C.copy()
            Pn[free] += dp
            Rn[steps] = R[steps] @ Rotation.from_rotvec(dc[:, :3]).as_matrix()
            Cn[steps] += dc[:, 3:]
            new, res_n = cost_of(Pn, Rn, Cn)
            return (Pn, Rn, Cn, res_n), new

        state, new, lam, improved = damped_step(trial, cost, lam, DAMPING)
        if improved:
            P, R, C, res = state
        if not improved or cost - new <= max(tol * cost, gain_tol * first):
            cost = new if improved else cost
            break
        cost = new
    return AdjustmentResult(P, R, C, cost, it)


def normal_blocks(prob, e, w, Jc, Jp, t, free_index, n_steps, n_free, sparse=False):
    """The Gauss-Newton normal blocks of the poses and the free points, as
    :func:`mappers.viewpoints.schur_step` takes them (``sparse``: the coupling as a
    :class:`mappers.viewpoints.Coupling`)."""
    U = scatter_sum(t, w[:, None, None] * np.einsum("kri,krj->kij", Jc, Jc), n_steps)
    g = scatter_sum(t, w[:, None] * np.einsum("kri,kr->ki", Jc, e), n_steps)
    f = free_index[prob.i]
    k = np.flatnonzero(f >= 0)
    V = scatter_sum(f[k], w[k, None, None] * np.einsum("kri,krj->kij", Jp[k], Jp[k]), n_free)
    h = scatter_sum(f[k], w[k, None] * np.einsum("kri,kr->ki", Jp[k], e[k]), n_free)
    if sparse:
        blocks = w[k, None, None] * np.einsum("kri,krj->kij", Jc[k], Jp[k])
        return U, V, Coupling(blocks, t[k], f[k], n_steps, n_free), g, h
    W = np.zeros((n_steps, 6, n_free, 3))
    # a step sees an object once (one sighting per step and object), so each block is written
    # once: an assignment, the same numbers as np.add.at at a fraction of its cost
    W[t[k], :, f[k], :] = w[k, None, None] * np.einsum("kri,krj->kij", Jc[k], Jp[k])
    return U, V, W.reshape(n_steps, 6, 3 * n_free), g, h


class _SightingCoupling(NamedTuple):
    """The pose-point coupling of the compiled step: one (6, 3) block per kept sighting (zero
    for a fixed object), ordered by step, with its free object's row (-1: fixed) and where each
    step's sightings start (``indptr`` (N + 1,))."""

    blocks: np.ndarray
    free: np.ndarray
    indptr: np.ndarray


def _compiled_blocks(prob, res, w, R, t, free_index, indptr, n_steps, n_free):
    """:func:`normal_blocks` by one compiled loop over the sightings
    (:func:`mappers.spatial.adjustment_kernels.normal_equations`; equal to rounding), the
    coupling per sighting (:class:`_SightingCoupling`) for :func:`_compiled_step`."""
    e, v, nv, vh = res
    U, g = np.zeros((n_steps, 6, 6)), np.zeros((n_steps, 6))
    V, h = np.zeros((n_free, 3, 3)), np.zeros((n_free, 3))
    W = np.empty((len(e), 6, 3))
    f = np.ascontiguousarray(free_index[prob.i], dtype=np.int64)
    kernels.normal_equations(np.ascontiguousarray(R), np.ascontiguousarray(prob.t, dtype=np.int64),
                             np.ascontiguousarray(t, dtype=np.int64), f, v, nv, vh, e,
                             np.ascontiguousarray(w, dtype=np.float64), prob.B, prob.has_r,
                             np.ascontiguousarray(prob.sr, dtype=np.float64), float(prob.sb),
                             U, g, V, h, W)
    return U, V, _SightingCoupling(W, f, indptr), g, h


def _compiled_step(U, V, W: _SightingCoupling, g, h, lam):
    """The damped Gauss-Newton step of :func:`mappers.viewpoints.schur_step` (the same damping
    ``diag *= 1 + lam`` and the same 1e-12 added to the diagonals) with the objects' reduced
    system summed step by step over each step's own sightings
    (:mod:`mappers.spatial.adjustment_kernels`): the same step to rounding, at a fraction of
    the dense coupling's cost."""
    n, f = U.shape[0], V.shape[0]
    diag = np.arange(6)
    U = U.copy()
    U[:, diag, diag] *= 1.0 + lam
    U[:, diag, diag] += 1e-12
    Ui = np.linalg.inv(U)
    S = np.zeros((3 * f, 3 * f))
    Vd = V * np.where(np.eye(3, dtype=bool), 1.0 + lam, 1.0)
    idx = 3 * np.arange(f)
    for r in range(3):
        for c in range(3):
            S[idx + r, idx + c] = Vd[:, r, c]
    rhs = -h.reshape(-1)
    kernels.reduced_system(Ui, W.blocks, W.free, W.indptr, g, S, rhs)
    S[np.diag_indices(3 * f)] += 1e-12
    dp = np.linalg.solve(S, rhs).reshape(f, 3)
    dc = np.empty((n, 6))
    kernels.pose_steps(Ui, W.blocks, W.free, W.indptr, g, dp, dc)
    return dc, dp
