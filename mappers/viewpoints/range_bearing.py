"""Range-and-bearing bundle adjustment of a fused map (LOC-SMA's ``refine=True``).

The bearing-only adjustment (:mod:`mappers.viewpoints.bearing`) with the ranges as residuals too:
each step's viewpoint is a latent pose ``(x, y, heading)``, and every reading of an object gives
an angle residual ``atan2(p - c) - heading - theta`` and a range residual ``|p - c| - r``. Steps:

1. *resection*: each step that sensed two or more placed objects gets its pose in closed form,
   the rigid motion (2-D Procrustes, Kabsch) taking the readings' points in the robot's frame,
   ``r (cos theta, sin theta)``, onto the start map's objects;
2. *adjustment*: Levenberg-Marquardt on the poses and the non-anchor objects together, the poses
   eliminated per step (Schur complement, as in the bearing-only solver), each residual divided
   by its sensor's robust scale (1.4826 times the median absolute residual) and Huber-weighted;
   the anchors fix the gauge;
3. the scales are read again from the adjusted residuals and the adjustment repeated
   (``passes``): the start map's errors inflate the first scales, and their ratio is what weighs
   range against bearing.

Guards as in the bearing-only solver: an object seen from fewer than ``min_views`` usable steps
keeps its start position (its readings leave the problem), a viewpoint that drifts beyond the
map's bounding box widened by its size leaves the problem, and if the adjusted map explains the
readings worse than the start (robust cost, final scales, start's poses resected) or anything is
not finite, the start map is returned. Each case is a :class:`BearingAdjustmentWarning`.

*Assumes*: one viewpoint per step, ranges and bearings to the objects' centres, a static world;
no motion model and no odometry.

References: Triggs et al., *Bundle Adjustment — A Modern Synthesis* (2000); Kabsch (1976) for
the rigid fit; Huber & Ronchetti, *Robust Statistics* (2009), for the weights and the scale.
"""

from __future__ import annotations

import warnings
from numbers import Integral

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval

from mappers.core.estimator_params import store_params
from mappers.core.validation import check_fused_input
from mappers.viewpoints.bearing import DAMPING, BearingAdjustment, BearingAdjustmentWarning
from mappers.viewpoints.engine import (
    DENSE_COUPLING_MAX_BYTES,
    Coupling,
    bearing_angles,
    damped_step,
    joint_step,
    pose_jacobian,
    robust_cost,
    robust_weights,
    scatter_sum,
    use_sparse_coupling,
    wrap_angles,
)
from mappers.viewpoints.start_map import anchored_start, keep_if_better

__all__ = ["DAMPING", "RangeBearingAdjustment"]
# DAMPING: the Levenberg-Marquardt damping rule, BEARING-BA's (handed on from bearing.py)


def _procrustes_poses(P, obs, n):
    """Each step's pose (C (N, 2), phi (N,)) from its readings' points in the robot's frame and
    the objects' map positions, and whether the step has two distinct points."""
    t, i, th, r = obs
    e = np.column_stack([r * np.cos(th), r * np.sin(th)])
    p = P[i]
    cnt = np.bincount(t, minlength=n).astype(float)
    safe = np.maximum(cnt, 1.0)[:, None]
    me, mp = scatter_sum(t, e, n) / safe, scatter_sum(t, p, n) / safe
    de, dp = e - me[t], p - mp[t]
    # rotation angle maximising sum dp . R(phi) de
    s_cos = scatter_sum(t, de[:, 0] * dp[:, 0] + de[:, 1] * dp[:, 1], n)
    s_sin = scatter_sum(t, de[:, 0] * dp[:, 1] - de[:, 1] * dp[:, 0], n)
    phi = np.arctan2(s_sin, s_cos)
    c, s = np.cos(phi), np.sin(phi)
    C = mp - np.column_stack([c * me[:, 0] - s * me[:, 1], s * me[:, 0] + c * me[:, 1]])
    spread = scatter_sum(t, np.einsum("kj,kj->k", de, de), n)
    return C, phi, (cnt >= 2) & (spread > 1e-12)


def bearing_residuals(P, C, phi, obs):
    """Angle and range residuals (K,) each, and the offsets object - viewpoint (K, 2)."""
    t, i, th, r = obs
    d = P[i] - C[t]
    dist = np.hypot(d[:, 0], d[:, 1])
    return wrap_angles(np.arctan2(d[:, 1], d[:, 0]) - phi[t] - th), dist - r, d


class RangeBearingAdjustment(TransformerMixin, BaseEstimator):
    """Refine a range-and-bearing map by estimating each step's viewpoint (module docstring).

    Parameters:
        loss: ``"huber"``, ``"cauchy"`` or None (least squares) on the scaled residuals.
        robust_scale: the loss's scale in robust standard deviations of the residuals.
        max_rounds: Levenberg-Marquardt steps per pass at most.
        passes: adjustments, the residual scales read again before each after the first.
        tol: a pass stops when no object moves more than this [m].
        min_views: an object read from fewer usable steps keeps its start position.
        dense_coupling_bytes: the joint step's pose-object coupling is dense up to this many
            bytes, one block per reading above (the sparse Schur step,
            :mod:`mappers.viewpoints.sparse_schur`).

    Attributes:
        embedding_ (M, 2) in world coordinates (NaN rows: not placed); start_; poses_ (N, 3)
        (NaN rows: steps left out); scales_ (angle [rad], range [m]); kept_; cost_, start_cost_;
        refined_ whether the adjustment was kept.
    """

    # the parameters it shares with BEARING-BA are checked as BEARING-BA checks them
    _parameter_constraints: dict = {
        **{name: BearingAdjustment._parameter_constraints[name]
           for name in ("loss", "robust_scale", "max_rounds", "tol", "min_views",
                        "dense_coupling_bytes")},
        "passes": [Interval(Integral, 1, None, closed="left")],
    }

    def __init__(self, *, loss: str | None = "huber", robust_scale: float = 2.0,
                 max_rounds: int = 8, passes: int = 2, tol: float = 1e-7,
                 min_views: int = 3,
                 dense_coupling_bytes: float = DENSE_COUPLING_MAX_BYTES) -> None:
        store_params(self, locals())

    def fit(self, X, y=None, *, masks=None, anchor_ids=None, anchor_positions=None,
            start_positions=None):
        """Refine ``start_positions`` ((M, 2), NaN rows: not placed) with the fused histories
        ``X`` ({"range": (M, N), "bearing": (M, 2N)}, ``masks`` keyed alike, None: complete);
        the anchors (rows of X) are held at their positions."""
        self._validate_params()
        check_fused_input(self, X, ("range", "bearing"))
        masks = dict(masks or {})
        theta, seen = bearing_angles(X["bearing"], masks.get("bearing"))
        R = np.asarray(X["range"], dtype=float).T
        if R.shape != theta.shape:
            raise ValueError(f"the range history {R.T.shape} and the bearing history "
                             f"{theta.T.shape} must hold the same objects and steps")
        if masks.get("range") is not None:
            seen &= np.asarray(masks["range"], dtype=bool).T
        seen &= np.isfinite(R) & (R > 0)
        m = theta.shape[1]
        ids, pos, P0 = anchored_start("the range-bearing adjustment", anchor_ids,
                                      anchor_positions, m, start_positions)
        self.start_ = P0.copy()
        self.embedding_ = self._refine(theta, R, seen, P0, ids)
        return self

    def _refine(self, theta, R, seen, P0, ids):
        n, m = theta.shape
        placed = np.all(np.isfinite(P0), axis=1)
        free = placed.copy()
        free[ids] = False
        seen = seen & placed[None, :]
        t, i = np.nonzero(seen)
        obs = (t, i, theta[t, i], R[t, i])
        P = np.where(placed[:, None], P0, 0.0)
        self.kept_ = np.array([], dtype=int)
        C, phi, ok = _procrustes_poses(P, obs, n)
        lo, hi = P[placed].min(0), P[placed].max(0)
        box = (lo - (hi - lo).max(), hi + (hi - lo).max())
        ok &= np.all((C >= box[0]) & (C <= box[1]), axis=1)
        wb = ok[t].astype(float)
        weak = free & (scatter_sum(i, wb, m) < self.min_views)
        if weak.any():
            self.kept_ = np.flatnonzero(weak)
            warnings.warn(f"objects {self.kept_.tolist()} are read from too few steps: they keep "
                          "the start map's positions", BearingAdjustmentWarning, stacklevel=3)
            wb = wb * ~weak[i]
            wb = wb * (scatter_sum(t, wb, n) >= 2)[t]
        free &= ~weak
        start = (P.copy(), C.copy(), phi.copy())
        rounds = 0
        for _ in range(self.passes):
            scales = self._scales(P, C, phi, obs, wb)
            P, C, phi, wb, k = self._joint(P, C, phi, obs, wb, free, scales, box)
            rounds += k
        self.scales_ = self._scales(P, C, phi, obs, wb)
        self.cost_ = self._cost(P, C, phi, obs, wb, self.scales_)
        self.start_cost_ = self._cost(*start, obs, wb, self.scales_)
        self.n_rounds_ = rounds
        used = np.zeros(n, dtype=bool)
        used[t[wb > 0]] = True
        self.poses_ = np.where(used[:, None], np.column_stack([C, phi]), np.nan)
        self.refined_, out = keep_if_better(P, P0, placed, self.cost_, self.start_cost_,
                                            "readings", BearingAdjustmentWarning)
        return out

    def _scales(self, P, C, phi, obs, wb):
        """The robust standard deviation of the angle and of the range residuals."""
        ra, rr, _ = bearing_residuals(P, C, phi, obs)
        used = wb > 0
        if not used.any():
            return 1.0, 1.0
        return (1.4826 * max(float(np.median(np.abs(ra[used]))), 1e-9),
                1.4826 * max(float(np.median(np.abs(rr[used]))), 1e-9))

    def _cost(self, P, C, phi, obs, wb, scales):
        ra, rr, _ = bearing_residuals(P, C, phi, obs)
        k = self.robust_scale
        return float(np.sum(wb * (robust_cost(ra / scales[0], k, self.loss)
                                  + robust_cost(rr / scales[1], k, self.loss))))

    def _blocks(self, P, C, phi, obs, wb, scales, free_index, n_free, sparse=False):
        """Normal-equation blocks (as :func:`mappers.viewpoints.engine.normal_blocks`) of the
        scaled, robustly weighted angle and range residuals (``sparse``: the coupling as a
        :class:`mappers.viewpoints.engine.Coupling`)."""
        t, i = obs[0], obs[1]
        n = len(C)
        ra, rr, d = bearing_residuals(P, C, phi, obs)
        dist = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
        ua, ur = ra / scales[0], rr / scales[1]
        aa = pose_jacobian(d) / scales[0]
        ar = np.column_stack([-d[:, 0] / dist, -d[:, 1] / dist, np.zeros_like(dist)]) / scales[1]
        wa = wb * robust_weights(ua, self.robust_scale, self.loss)
        wr = wb * robust_weights(ur, self.robust_scale, self.loss)
        # both residuals of a reading share its step and object: their blocks add up
        J = np.stack([aa, ar], axis=1)  # (K, 2 residuals, 3 pose unknowns)
        w = np.column_stack([wa, wr])
        JtW = (J * w[:, :, None]).transpose(0, 2, 1)  # (K, 3, 2)
        JtWJ = JtW @ J  # (K, 3, 3)
        JtWu = (JtW @ np.column_stack([ua, ur])[:, :, None])[..., 0]  # (K, 3)
        U = scatter_sum(t, JtWJ, n)
        g = scatter_sum(t, JtWu, n)
        f = free_index[i]
        k = np.flatnonzero(f >= 0)
        tf, ff = t[k], f[k]
        V = scatter_sum(ff, JtWJ[k][:, :2, :2], n_free)
        h = scatter_sum(ff, -JtWu[k][:, :2], n_free)
        if sparse:
            return U, V, Coupling(-JtWJ[k][:, :, :2], tf, ff, n, n_free), g, h
        Wf = np.zeros((n, n_free, 3, 2))  # the object's Jacobian is minus the viewpoint's
        Wf[tf, ff] = -JtWJ[k][:, :, :2]
        Wf = Wf.transpose(0, 2, 1, 3)
        return U, V, Wf.reshape(n, 3, 2 * n_free), g, h

    def _joint(self, P, C, phi, obs, wb, free, scales, box):
        """Levenberg-Marquardt on the poses and the free objects (IRLS weights per step)."""
        free_index = np.full(len(P), -1)
        free_index[free] = np.arange(free.sum())
        n_free = int(free.sum())
        sparse = use_sparse_coupling(len(C), 3, 2, n_free, self.dense_coupling_bytes)
        lam, rounds = 1e-4, 0
        current = self._cost(P, C, phi, obs, wb, scales)
        while rounds < self.max_rounds:
            rounds += 1
            blocks = self._blocks(P, C, phi, obs, wb, scales, free_index, n_free, sparse)

            def trial(lam, blocks=blocks, P=P, C=C, phi=phi, wb=wb):
                dc, dp = joint_step(*blocks, lam)
                P2 = P.copy()
                P2[free] += dp
                C2, phi2 = C + dc[:, :2], wrap_angles(phi + dc[:, 2])
                return (P2, C2, phi2, dp), self._cost(P2, C2, phi2, obs, wb, scales)

            state, new, lam, accepted = damped_step(trial, current, lam, DAMPING)
            if not accepted:
                break
            P, C, phi, dp = state
            done = current - new <= 1e-6 * current or not dp.size or np.abs(dp).max() <= self.tol
            current = new
            out = ~np.all((C >= box[0]) & (C <= box[1]), axis=1)
            if out.any():
                wb = wb * ~out[obs[0]]
                current = self._cost(P, C, phi, obs, wb, scales)
                done = False
            if done:
                break
        return P, C, phi, wb, rounds

    def fit_transform(self, X, y=None, *, masks=None, anchor_ids=None, anchor_positions=None,
                      start_positions=None):
        """Fit and return the (M, 2) map in world coordinates (NaN rows: not placed)."""
        return self.fit(X, masks=masks, anchor_ids=anchor_ids, anchor_positions=anchor_positions,
                        start_positions=start_positions).embedding_
