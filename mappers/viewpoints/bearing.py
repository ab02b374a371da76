"""Bearing-only bundle adjustment of a bearing map (label ``"BEARING-BA"``).

The paper's methods, and every other mapper here, never estimate where the robot was. This one
does: it starts from the map the bearing default drew before it (``start``: CAL-SMA for a
complete history, ``COVIS-AUTO`` for a masked one) and refines it by treating each step's
viewpoint as a latent pose ``(x, y, heading)``:

1. *resection* of the start map: each step's pose from the bearings of the objects it observed,
   the objects where the start map puts them, in closed form (linear in ``cos``, ``sin`` of the
   heading and the rotated viewpoint; one 4 x 4 eigenproblem per step), then Gauss-Newton on
   the wrapped angle residuals (one 3 x 3 system per step, batched); a step that observed fewer
   than ``min_step_objects`` objects, or whose system is ill-conditioned, is left out;
2. *adjustment* (``solver="joint"``, the default): Levenberg-Marquardt on the poses and the
   non-anchor objects together, each step's 3 pose unknowns eliminated (Schur complement) so
   the system solved is the objects' 2F x 2F one; the anchors stay at their known positions,
   which fix the gauge (shift, rotation, scale). ``solver="alternate"`` instead alternates the
   resection with an *intersection*, each object from its rays (linear least squares on the
   perpendicular offsets over the range, a 2 x 2 system per object): simpler, but it converges
   linearly (docs/imperfect-sensing.md has the figures);
3. *robust weights*: Huber (or Cauchy) weights on the angle residuals, renewed at every step,
   the scale read from the start's residuals (their median absolute value), so 30 degrees of
   noise or a wrong reading does not dominate;

for at most ``max_rounds`` rounds, or until no object moves more than ``tol`` [m], the cost
stops falling, or (``gain_tol``) a round lowers it by a negligible fraction of the start's.

Guards: an object seen from fewer than ``min_views`` usable steps, or from nearly parallel rays
(the smallest to largest eigenvalue of its rays' normal matrix below ``min_spread``), keeps its
start position, and its bearings are left out (the start is not to be trusted); a viewpoint that
drifts beyond the map's bounding box widened by its size on every side (three objects nearly in
line leave a pose free to run away) leaves the problem; if the refined solution's robust angle
cost is above the start's (with the start's poses resected, over the same readings), or anything
is not finite, the start map is returned. Each case is a :class:`BearingAdjustmentWarning`
(``build_map`` lists them in ``Map.warnings``).

*Assumes*: the bearings of one step are taken from one viewpoint and are relative to the robot's
heading at that step (one unknown heading per step, no calibration offset); a static world;
bearings to the objects' centres. No motion model and no odometry: the steps are independent
viewpoints, found from the history alone.

References: Triggs et al., *Bundle Adjustment — A Modern Synthesis* (2000), for the adjustment
and its Schur complement; Huber & Ronchetti, *Robust Statistics* (2009), for the weights.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from numbers import Integral, Real

import numpy as np
import scipy.sparse as sp
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval, StrOptions

from mappers.core.iteration_params import ROUND_CONSTRAINTS
from mappers.core.validation import check_views
from mappers.defaults import localisation_free
from mappers.viewpoints.engine import (
    CG_RTOL,
    DENSE_COUPLING_MAX_BYTES,
    Damping,
    bearing_observations,
    bearing_residuals,
    damped_step,
    initial_poses,
    intersect,
    joint_step,
    normal_blocks,
    ray_spread,
    resect,
    robust_cost,
    robust_weights,
    scatter_sum,
    use_sparse_coupling,
    wrap_angles,
)
from mappers.viewpoints.start_map import anchored_start, fit_start, keep_if_better

__all__ = ["BearingAdjustment", "BearingAdjustmentWarning"]

DAMPING = Damping(up=10.0, down=10.0, floor=1e-9, tries=12, accept_equal=True)
"""BEARING-BA's Levenberg-Marquardt damping rule (:class:`mappers.viewpoints.engine.Damping`)."""


class BearingAdjustmentWarning(UserWarning):
    """The refinement kept (part of) the start map: too few views, parallel rays, no gain."""


class BearingAdjustment(TransformerMixin, BaseEstimator):
    """Refine a bearing map by estimating each step's viewpoint (module docstring).

    Parameters:
        start: label of the method that draws the start map (None: the bearing default before
            this method, CAL-SMA for a complete history and ``COVIS-AUTO`` for a masked one).
        start_params: parameters of the start method (None: its defaults), e.g. fewer rounds
            of ``COVIS-SPARSE`` when the adjustment refines its map anyway.
        loss: ``"huber"``, ``"cauchy"`` or None (least squares) on the angle residuals.
        robust_scale: the loss's scale in robust standard deviations of the residuals (1.4826
            times their median absolute value).
        max_rounds: rounds (Levenberg-Marquardt steps, or resection and intersection) at most.
        tol: stop when no object moves more than this [m].
        gain_tol: (``"joint"``) stop when a round lowers the robust cost by at most this fraction
            of the cost the adjustment started from (the readings explained no better: 0, the
            default, stops only on ``tol``, ``max_rounds`` or a relative gain below 1e-6).
        pose_iters: Gauss-Newton iterations of the resection per round (``"alternate"``).
        min_step_objects: a step that observed fewer objects gives no pose (3 unknowns).
        min_views: an object observed from fewer usable steps keeps its start position.
        min_spread: an object whose rays' normal matrix has a smaller eigenvalue ratio (nearly
            parallel rays) keeps its start position.
        solver: ``"joint"`` (Levenberg-Marquardt on poses and objects) or ``"alternate"``.
        random_state: handed to the start method.
        dense_coupling_bytes: the joint step holds the pose-object coupling as a dense
            (N, 3, 2F) array up to this many bytes, and above it one block per observation with
            the objects' reduced system sparse (:mod:`mappers.viewpoints.sparse_schur`; the same
            step to rounding), so that thousands of objects and tens of thousands of steps fit.
        schur_solver: how the sparse step solves the objects' reduced system: ``"lu"`` (sparse
            LU) or ``"cg"`` (block-Jacobi preconditioned conjugate gradients).
        schur_rtol: the relative residual at which the conjugate gradients stop (an inexact
            Levenberg-Marquardt step: Agarwal et al., *Bundle Adjustment in the Large*, 2010).

    Attributes:
        embedding_ (M, 2) in world coordinates; start_ the start map; poses_ (N, 3) the
        estimated viewpoints (NaN rows: steps left out); kept_ indices of non-anchor objects
        that kept their start; n_rounds_, cost_, start_cost_ (robust angle cost, start's scale);
        refined_ whether the refinement was kept; scale_ the robust loss's scale [rad] (read from
        the start's residuals).
    """

    _parameter_constraints: dict = {
        "start": [str, None],
        "start_params": [Mapping, None],
        "loss": [StrOptions({"huber", "cauchy"}), None],
        "robust_scale": [Interval(Real, 0, None, closed="neither")],
        **ROUND_CONSTRAINTS,
        "pose_iters": [Interval(Integral, 1, None, closed="left")],
        "min_step_objects": [Interval(Integral, 3, None, closed="left")],
        "min_views": [Interval(Integral, 2, None, closed="left")],
        "min_spread": [Interval(Real, 0, 1, closed="both")],
        "solver": [StrOptions({"joint", "alternate"})],
        "random_state": ["random_state"],
        "dense_coupling_bytes": [Interval(Real, 0, None, closed="left")],
        "schur_solver": [StrOptions({"lu", "cg"})],
        "schur_rtol": [Interval(Real, 0, 1, closed="neither")],
        "gain_tol": [Interval(Real, 0, 1, closed="left")],
    }

    def __init__(self, *, start: str | None = None, loss: str | None = "huber",
                 robust_scale: float = 2.0, max_rounds: int = 6, tol: float = 1e-7,
                 pose_iters: int = 2, min_step_objects: int = 3, min_views: int = 5,
                 min_spread: float = 1e-3, solver: str = "joint", random_state=0,
                 dense_coupling_bytes: float = DENSE_COUPLING_MAX_BYTES,
                 schur_solver: str = "lu", schur_rtol: float = CG_RTOL,
                 gain_tol: float = 0.0, start_params: Mapping | None = None) -> None:
        self.start = start
        self.start_params = start_params
        self.loss = loss
        self.robust_scale = robust_scale
        self.max_rounds = max_rounds
        self.tol = tol
        self.pose_iters = pose_iters
        self.min_step_objects = min_step_objects
        self.min_views = min_views
        self.min_spread = min_spread
        self.solver = solver
        self.random_state = random_state
        self.dense_coupling_bytes = dense_coupling_bytes
        self.schur_solver = schur_solver
        self.schur_rtol = schur_rtol
        self.gain_tol = gain_tol

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.sparse = True  # compact (scipy.sparse) histories are read as they are
        return tags

    def _start_map(self, X, mask, ids, pos) -> np.ndarray:
        masked = mask is not None and (mask.nnz < np.prod(mask.shape) if sp.issparse(mask)
                                       else not np.all(mask))
        label = self.start or localisation_free("bearing", masked)[0]
        if label.strip().upper() == "BEARING-BA":
            raise ValueError("start must name another method than 'BEARING-BA'")
        return fit_start(label, X, ids, pos, sensor="bearing", mask=mask if masked else None,
                         random_state=self.random_state, category=BearingAdjustmentWarning,
                         params=self.start_params)[0]

    def fit(self, X, y=None, *, mask=None, sensor: str = "bearing", anchor_ids=None,
            anchor_positions=None, start_positions=None):
        """Map the bearing history ``X`` ((M, 2N), unit (cos, sin) per step; ``mask`` True where
        observed) with the anchors (rows of X) held at their positions. ``start_positions``
        ((M, 2), NaN rows: not placed) replaces the start method's map."""
        self._validate_params()
        if sensor != "bearing":
            raise ValueError(f"BEARING-BA maps bearing histories, got a {sensor} history")
        if sp.issparse(X):  # kept sparse: only the observations are read
            X = sp.csr_array(X, dtype=np.float64)
            if X.shape[0] < 3 or not np.all(np.isfinite(X.data)):
                raise ValueError(f"BEARING-BA needs at least 3 objects and finite readings, got "
                                 f"shape {X.shape}")
        else:
            X = check_views(self, X, mask)
        obs, n, m = bearing_observations(X, mask)
        ids, pos, P0 = anchored_start(
            "BEARING-BA", anchor_ids, anchor_positions, m, start_positions,
            lambda ids, pos: self._start_map(X, mask, ids, pos),
        )
        self.start_ = P0.copy()
        self.embedding_ = self._refine(obs, n, m, P0, ids)
        return self

    def _refine(self, obs, n, m, P0, ids) -> np.ndarray:
        placed = np.all(np.isfinite(P0), axis=1)
        free = placed.copy()
        free[ids] = False
        t, i, th = obs
        keep = placed[i]
        t, i, th = t[keep], i[keep], th[keep]
        keep = np.bincount(t, minlength=n)[t] >= self.min_step_objects
        t, i = t[keep], i[keep]
        obs = (t, i, th[keep])
        P = np.where(placed[:, None], P0, 0.0)
        self.kept_ = np.array([], dtype=int)
        # a problem beyond the dense coupling sums its systems by compiled loops (the same sums)
        large = use_sparse_coupling(n, 3, 2, int(free.sum()), self.dense_coupling_bytes)
        C, phi, ok0 = initial_poses(P, obs, n, compiled=large)
        C, phi, ok = resect(P, C, phi, obs, np.ones(len(t)), 3, compiled=large)
        ok &= ok0
        lo, hi = P[placed].min(0), P[placed].max(0)
        self._box = (lo - (hi - lo).max(), hi + (hi - lo).max())
        ok &= self._inside(C)
        wb = ok[t].astype(float)  # steps whose pose the start map pins down
        res, _ = bearing_residuals(P, C, phi, obs)
        used = wb > 0
        scale = self.robust_scale * 1.4826 * max(
            float(np.median(np.abs(res[used]))) if used.any() else 0.0, 1e-9)
        start_rho = robust_cost(res, scale, self.loss)
        self.scale_ = scale
        # objects the usable steps do not pin down keep their start
        views = scatter_sum(i, wb, m)
        weak = free & ((views < self.min_views) | (ray_spread(phi, obs, wb, m) < self.min_spread))
        if weak.any():
            self.kept_ = np.flatnonzero(weak)
            warnings.warn(f"objects {self.kept_.tolist()} are seen from too few steps or along "
                          "nearly parallel rays: they keep the start map's positions",
                          BearingAdjustmentWarning, stacklevel=3)
        free &= ~weak
        if weak.any():  # their start is not to be trusted: their bearings leave the problem
            wb = wb * ~weak[i]
            wb = wb * (scatter_sum(t, wb, n) >= self.min_step_objects)[t]
        if self.solver == "joint":
            P, C, phi, wb, rounds = self._joint(P, C, phi, obs, wb, free, scale)
            ok = np.zeros(n, dtype=bool)
            ok[t[wb > 0]] = True
        else:
            P, C, phi, wb, ok, rounds = self._alternate(P, C, phi, obs, wb, free, scale)
        res, _ = bearing_residuals(P, C, phi, obs)
        self.cost_ = float(np.sum(wb * robust_cost(res, scale, self.loss)))
        self.start_cost_ = float(np.sum(wb * start_rho))  # the same readings, start's poses
        self.n_rounds_ = rounds
        self.poses_ = np.where(ok[:, None], np.column_stack([C, phi]), np.nan)
        self.refined_, out = keep_if_better(P, P0, placed, self.cost_, self.start_cost_,
                                            "bearings", BearingAdjustmentWarning)
        return out

    def _inside(self, C):
        """Viewpoints within the map's bounding box widened by its size on every side: a pose
        beyond drifted along a degenerate direction (three objects nearly in line)."""
        return np.all((C >= self._box[0]) & (C <= self._box[1]), axis=1)

    def _alternate(self, P, C, phi, obs, wb, free, scale):
        """Resection and intersection in turn (see the module docstring)."""
        rounds, ok, t = 0, wb > 0, obs[0]
        for rounds in range(1, self.max_rounds + 1):  # noqa: B007 - the count is returned
            res, _ = bearing_residuals(P, C, phi, obs)
            w = wb * robust_weights(res, scale, self.loss)
            Q = intersect(P, C, phi, obs, w)
            move = np.abs(Q[free] - P[free]).max() if free.any() else 0.0
            P[free] = Q[free]
            C, phi, ok_steps = resect(P, C, phi, obs, w, self.pose_iters)
            ok = ok_steps & self._inside(C)
            wb = wb * ok[t]
            if move <= self.tol:
                break
        return P, C, phi, wb, ok, rounds

    def _joint(self, P, C, phi, obs, wb, free, scale):
        """Levenberg-Marquardt on the poses and the free objects together, robust weights
        renewed at every step (IRLS), the poses eliminated per step (Schur complement)."""

        def cost(res):
            return float(np.sum(wb * robust_cost(res, scale, self.loss)))

        free_index = np.full(len(P), -1)
        free_index[free] = np.arange(free.sum())
        sparse = use_sparse_coupling(len(C), 3, 2, int(free.sum()), self.dense_coupling_bytes)
        # the residuals (and offsets) at the current poses and objects, kept from the accepted
        # trial: the weights and the normal equations of the next round read them
        res_d = bearing_residuals(P, C, phi, obs)
        lam, current, rounds = 1e-4, cost(res_d[0]), 0
        first = current
        for rounds in range(1, self.max_rounds + 1):  # noqa: B007 - the count is returned
            blocks = normal_blocks(P, C, phi, obs, wb * robust_weights(res_d[0], scale, self.loss),
                                   free_index, int(free.sum()), sparse=sparse, residuals=res_d)

            def trial(lam, blocks=blocks, P=P, C=C, phi=phi, cost=cost):
                dc, dp = joint_step(*blocks, lam, solver=self.schur_solver, rtol=self.schur_rtol)
                P2 = P.copy()
                P2[free] += dp
                C2, phi2 = C + dc[:, :2], wrap_angles(phi + dc[:, 2])
                res_d2 = bearing_residuals(P2, C2, phi2, obs)
                return (P2, C2, phi2, dp, res_d2), cost(res_d2[0])

            state, new, lam, accepted = damped_step(trial, current, lam, DAMPING)
            if not accepted:
                break  # no step lowers the cost: converged (or stuck)
            P, C, phi, dp, res_d = state
            done = (current - new <= 1e-6 * current or not dp.size or np.abs(dp).max() <= self.tol
                    or current - new <= self.gain_tol * first)
            current = new
            out = ~self._inside(C)
            if out.any():  # drifting viewpoints leave the problem
                wb = wb * ~out[obs[0]]
                current = cost(res_d[0])
                done = False
            if done:
                break
        return P, C, phi, wb, rounds

    def fit_transform(self, X, y=None, *, mask=None, sensor: str = "bearing", anchor_ids=None,
                      anchor_positions=None, start_positions=None):
        """Fit and return the (M, 2) map in world coordinates (NaN rows: not placed)."""
        return self.fit(X, mask=mask, sensor=sensor, anchor_ids=anchor_ids,
                        anchor_positions=anchor_positions,
                        start_positions=start_positions).embedding_
