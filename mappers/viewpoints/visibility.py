"""Visibility bundle adjustment of a visibility map (label ``"VIS-BA-WALK"``: with the walk prior).

The paper's methods, and the other visibility mappers here, never estimate where the robot was.
This one does: it starts from the map the visibility default draws (``start``: CAL-SMA for a
complete history, ``DROPOUT-BLEND`` for a masked one; where the default is itself an adjustment,
the map before it) and refines it by treating each step's viewpoint as a latent position. A
visibility bit is read as a noisy range threshold with dropouts and occlusion whose parameters
are fitted by maximum likelihood (:mod:`mappers.viewpoints.visibility_model`); only the entries
the mask calls observed enter the likelihood.

The viewpoints are not point estimates, which would sit in the middle of the region the bits
allow and bias the objects; they are integrated out by EM over a grid of candidate viewpoints
(``grid_cells`` cells per radius over the objects' bounding box widened by the radius):

1. *E-step* (:mod:`mappers.viewpoints.viewpoint_posterior`): each step's posterior over the
   cells, from the bits of the objects it observed, under a prior over the cells learnt from the
   data (the mean posterior, blurred by ``prior_blur`` cells: the robot's occupancy, which keeps
   viewpoints out of places no step went, such as beyond the walls);
2. *M-step*: each non-anchor object's position by Fisher scoring of its expected
   log-likelihood over the cells (a per-object step halving that never lowers it), then the
   sensor model; the anchors stay at their known positions, which fix the gauge (shift,
   rotation, scale);

for ``max_rounds`` rounds (or until no object moves more than ``tol`` [m]); the cells no step
is likely to have been in are dropped after the start's E-steps.

*Continuity* (``continuity=True``; label ``"VIS-BA-WALK"``, the default for flickering
histories): the steps of a walk are ordered, consecutive viewpoints close together. The E-step is
then a forward-backward pass over the steps (a hidden Markov model over the cells,
:mod:`mappers.viewpoints.walk_prior`): a move is an isotropic Gaussian random walk of width
``step_sigma`` per axis (None: fitted by EM; the mapper is not told the step length), a run's
first step is drawn from the learnt occupancy prior, and the marginal likelihood is the HMM's.
The runs of consecutive steps come from the timeline (:func:`mappers.core.flicker.step_runs`);
every step takes part, one that saw nothing too. The first E-step treats the steps as
independent (under the guessed model a walk can settle where nothing is expected to be seen,
and its fitted width collapse). Two options speed the M-step's slow modes up: ``align`` moves
the free objects by the mean offset between the anchors' known positions and where their bits
put them among the current viewpoints, and ``overrelax`` lengthens each round's move of the
objects (over-relaxed EM); ``model_rounds`` refits the sensor model and the walk's width in the
first rounds only. What each option bought: ``docs/imperfect-sensing.md``, sections "VIS-BA"
and "VIS-BA-WALK".

Guards: an object seen from fewer than ``min_views`` usable steps keeps its start position (its
bits leave the problem); if the refined map's marginal likelihood is below the start map's (its
model and prior fitted the same way), or anything is not finite, the start map is returned.
Each case is a :class:`VisibilityAdjustmentWarning` (``build_map`` lists them in
``Map.warnings``).

*Assumes*: visibility is a range threshold up to misses (occlusion only as a miss rate that
grows with distance, not from the layout); a 360-degree view (through a narrower one the mask
carries the heading, which is not modelled: VIEW-BA, :mod:`mappers.viewpoints.view_cone`, does);
a static world; the bits of one step are taken from one viewpoint. No motion model and no
odometry: the steps are independent viewpoints, found from the history alone; with
``continuity``, the steps are ordered like a walk's (``build_map`` picks VIS-BA-WALK only for
histories whose :func:`mappers.core.flicker.persistence` says they are walk-ordered).

References: Triggs et al., *Bundle Adjustment — A Modern Synthesis* (2000); Dempster, Laird &
Rubin (1977) for EM; Rabiner (1989) for the forward-backward recursion.
"""

from __future__ import annotations

import warnings
from numbers import Integral, Real

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval

from mappers.core.estimator_params import store_params
from mappers.core.flicker import step_runs
from mappers.core.iteration_params import ROUND_CONSTRAINTS
from mappers.core.sensors import check_matrix
from mappers.core.validation import check_views
from mappers.defaults import choose_for_history, localisation_free
from mappers.fitting import check_inputs
from mappers.viewpoints.start_map import anchored_start, fit_start
from mappers.viewpoints.viewpoint_posterior import (
    _MAX_POSTERIOR,
    _EStep,
    _expected_counts,
    _grid,
    _update_prior,
)
from mappers.viewpoints.visibility_model import _fit_model, _guess_model, _loglik, _score_fisher

__all__ = ["VisibilityAdjustment", "VisibilityAdjustmentWarning", "visibility_bits"]

_MIN_DISTANCE = 1e-6
"""Distance [m] below which a viewpoint is taken to sit on an object (direction undefined)."""

_S_MIN = 0.0
"""Smallest softness of the model: free (the grid's spacing does not bound it)."""


class VisibilityAdjustmentWarning(UserWarning):
    """The refinement kept (part of) the start map: too few views, no gain."""


def visibility_bits(X, mask=None) -> tuple[np.ndarray, np.ndarray]:
    """``(seen, observed)``, both (N, M) bool: whether each object was visible at each step, and
    whether the sensor measured that entry (the mask; all True without one). ValueError when
    ``X`` is not a 0/1 history or ``mask`` does not fit it."""
    X = check_matrix(X, "a visibility history", copy=False)
    if mask is None:
        observed = np.ones(X.shape, dtype=bool)
    else:
        observed = np.asarray(mask)
        if observed.dtype != bool:
            raise ValueError(f"mask must be a boolean array (True = observed), got dtype "
                             f"{observed.dtype}")
        if observed.shape != X.shape:
            raise ValueError(f"mask must have the shape of the history {X.shape}, got "
                             f"{observed.shape}")
    values = X[observed]
    bad = values[(values != 0) & (values != 1)]
    if bad.size:
        raise ValueError(
            "a visibility history holds 0/1 entries; found observed values "
            f"{np.unique(bad)[:3].round(3).tolist()} (a bearing or range history, or normalised "
            "rows? pass normalize=False)"
        )
    return (X == 1).T & observed.T, observed.T.copy()


def _solve_objects(P, G, Sg, Ng, free, theta, iters) -> np.ndarray:
    """Fisher scoring of the ``free`` objects' positions on the expected counts ``Sg`` (seen)
    and ``Ng`` (not seen) of each (object, cell); a per-object step halving that never lowers
    an object's expected log-likelihood."""
    R = theta[0]
    idx = np.flatnonzero(free)
    if not idx.size:
        return P
    # each object's window: the cells within 2.5 R of it (a step moves it at most R / 2)
    near = np.linalg.norm(P[idx][:, None] - G[None], axis=2) <= 2.5 * R
    width = max(int(near.sum(axis=1).max()), 1)
    order = np.argsort(~near, axis=1, kind="stable")[:, :width]  # (F, K) cells, near first
    inside = np.take_along_axis(near, order, axis=1)
    Gw = G[order]  # (F, K, 2)
    Sj = np.where(inside, np.take_along_axis(Sg[idx], order, axis=1), 0.0)
    Nj = np.where(inside, np.take_along_axis(Ng[idx], order, axis=1), 0.0)
    Q = P[idx].copy()

    def geometry(Q):
        diff = Q[:, None, :] - Gw  # (F, K, 2)
        d = np.sqrt(np.sum(diff * diff, axis=2))
        return d, diff / np.maximum(d, _MIN_DISTANCE)[..., None]

    def row_ll(Q):
        return np.sum(_loglik(geometry(Q)[0], Sj, Nj, theta), axis=1)

    current = row_ll(Q)
    for _ in range(iters):
        d, u = geometry(Q)
        score, fisher = _score_fisher(d, Sj, Nj, theta)
        g = np.einsum("fk,fki->fi", score, u)  # d d / d p = u
        F = np.einsum("fk,fki,fkj->fij", fisher, u, u)
        F += (1e-12 + 1e-6 * np.trace(F, axis1=1, axis2=2))[:, None, None] * np.eye(2)
        step = np.linalg.solve(F, g[..., None])[..., 0]
        step = np.clip(np.nan_to_num(step), -R / 2, R / 2)  # a longer step is not trusted
        best, best_ll = Q, current
        for alpha in (1.0, 0.5, 0.25, 0.125):
            trial = Q + alpha * step
            ll = row_ll(trial)
            better = np.isfinite(ll) & (ll > best_ll)
            best = np.where(better[:, None], trial, best)
            best_ll = np.where(better, ll, best_ll)
        Q, current = best, best_ll
    out = P.copy()
    out[idx] = Q
    return out


class VisibilityAdjustment(TransformerMixin, BaseEstimator):
    """Visibility bundle adjustment: a visibility map refined by estimating the viewpoints.

    Parameters:
        start: label of the method that draws the start map (None: the visibility default
            ``build_map`` picks for the history; when that adjusts viewpoints, CAL-SMA for a
            complete history and ``DROPOUT-BLEND`` for a masked one).
        max_rounds: EM rounds (E-step, objects, model).
        inner_iters: Fisher-scoring iterations of the objects per round.
        tol: stop when no object moves more than this [m] in a round.
        min_step_objects: a step that saw fewer objects is left out (its viewpoint is free);
            with ``continuity`` every step takes part (it is linked to its neighbours).
        min_views: an object seen from fewer usable steps keeps its start position.
        grid_cells: candidate viewpoints per visibility radius (grid spacing ``R / grid_cells``).
        prior_iters: E-steps on the start map before the refinement (model and prior).
        occlusion: fit the distance-dependent miss rate (gamma, k); False: gamma = 0.
        prior_blur: width [cells] of the Gaussian blur of the learnt viewpoint prior.
        continuity: the steps' viewpoints are a walk (a hidden Markov model over the cells,
            consecutive steps linked by the timeline) instead of independent.
        step_sigma: with ``continuity``, the walk's width per axis [m]; None: fitted by EM
            (given without ``continuity``: ValueError).
        align: each round, move the free objects by the mean offset between the anchors' known
            positions and their positions fitted to the current viewpoints (anchors seen from at
            least ``min_views`` steps, two or more).
        overrelax: lengthen each round's move of the objects by this factor (from the second
            round; 0: plain EM).
        model_rounds: refit the sensor model (and the walk's width) in this many rounds only
            (None: every round).
        random_state: handed to the start method.

    Attributes:
        embedding_ (M, 2) in world coordinates; start_ the start map; viewpoints_ (N, 2) the
        posterior mean viewpoints (NaN rows: steps left out); radius_, softness_, miss_rate_,
        occlusion_gain_, occlusion_power_ the fitted model; step_sigma_ the walk's width [m]
        (NaN without ``continuity``); start_method_; kept_ (indices of
        objects that kept their start); n_rounds_; loglik_, start_loglik_ (per observed entry); refined_ (False: the start map was kept).
    """

    _parameter_constraints: dict = {
        "start": [str, None],
        **ROUND_CONSTRAINTS,
        "inner_iters": [Interval(Integral, 1, None, closed="left")],
        "min_step_objects": [Interval(Integral, 1, None, closed="left")],
        "min_views": [Interval(Integral, 1, None, closed="left")],
        "grid_cells": [Interval(Integral, 2, None, closed="left")],
        "prior_iters": [Interval(Integral, 1, None, closed="left")],
        "occlusion": ["boolean"],
        "prior_blur": [Interval(Real, 0, None, closed="left")],
        "continuity": ["boolean"],
        "step_sigma": [Interval(Real, 0, None, closed="neither"), None],
        "align": ["boolean"],
        "overrelax": [Interval(Real, 0, 1, closed="both")],
        "model_rounds": [Interval(Integral, 0, None, closed="left"), None],
        "random_state": ["random_state"],
    }

    def __init__(self, *, start: str | None = None, max_rounds: int = 5, inner_iters: int = 3,
                 tol: float = 1e-4, min_step_objects: int = 1, min_views: int = 5,
                 grid_cells: int = 6, prior_iters: int = 2,
                 occlusion: bool = True, prior_blur: float = 2.0, continuity: bool = False,
                 step_sigma: float | None = None, align: bool = False, overrelax: float = 0.0,
                 model_rounds: int | None = None, random_state=0) -> None:
        store_params(self, locals())

    def _start_map(self, X, mask, ids, pos, timeline) -> np.ndarray:
        if self.start is not None and self.start.strip().upper() in ("VIS-BA", "VIS-BA-WALK"):
            raise ValueError("start must name another method than the visibility adjustment "
                             f"(VIS-BA-WALK), got {self.start!r}")
        label, params = self.start, {}
        if label is None:  # the default's choice; were it an adjustment, the map before it
            Xc, maskc, _, steps = check_inputs(X, "visibility", mask, timeline)
            label, params = choose_for_history(Xc, maskc, "visibility", steps)
            if label in ("VIS-BA-WALK", "VIEW-BA"):
                label, params = localisation_free("visibility", mask is not None)
        P, self.start_method_ = fit_start(label, X, ids, pos, sensor="visibility", mask=mask,
                                          timeline=timeline, random_state=self.random_state,
                                          category=VisibilityAdjustmentWarning, params=params)
        return P

    def fit(self, X, y=None, *, mask=None, sensor: str = "visibility", anchor_ids=None,
            anchor_positions=None, timeline=None, start_positions=None):
        """Map the visibility history ``X`` ((M, N) of 0/1; ``mask`` True where observed) with
        the anchors (rows of X) held at their positions. ``start_positions`` ((M, 2), NaN rows:
        not placed) replaces the start method's map."""
        self._validate_params()
        if self.step_sigma is not None and not self.continuity:
            raise ValueError(f"step_sigma={self.step_sigma!r} is the width of the walk's steps, "
                             "which only continuity=True models")
        if sensor != "visibility":
            raise ValueError("the visibility adjustment (VIS-BA-WALK) maps visibility histories, "
                             f"got sensor {sensor!r}")
        X = check_views(self, X, mask)
        seen, observed = visibility_bits(X, mask)
        m = seen.shape[1]
        self.start_method_ = None if start_positions is None else "given"
        ids, pos, P0 = anchored_start(
            "the visibility adjustment", anchor_ids, anchor_positions, m, start_positions,
            lambda ids, pos: self._start_map(np.asarray(X, dtype=float), mask, ids, pos, timeline),
        )
        self.start_ = P0.copy()
        self.embedding_ = self._refine(seen, observed, P0, ids, timeline)
        return self

    def _refine(self, seen, observed, P0, ids, timeline) -> np.ndarray:
        """EM of the objects, the sensor model (and the walk's width) with the viewpoints
        integrated out over a grid of cells (module docstring); the start map where the result
        explains the bits no better."""
        n, m = seen.shape
        placed = np.all(np.isfinite(P0), axis=1)
        step_ok, free, use, views = self._usable(seen, placed, ids)
        if step_ok.sum() < 3 or not free.any():
            warnings.warn(f"{int(step_ok.sum())} step(s) saw at least {self.min_step_objects} "
                          f"placed object(s), and {int(free.sum())} object(s) may move: nothing "
                          "to refine, the start map is kept", VisibilityAdjustmentWarning,
                          stacklevel=3)
            return self._start_kept(P0, n)
        S = (seen & step_ok[:, None] & use).astype(float)  # (N, M) seen, in the likelihood
        Obs = (observed & step_ok[:, None] & use).astype(float)  # observed, in the likelihood
        order, starts = self._step_order(step_ok, timeline)
        S, Obs = S[order].astype(np.float32), Obs[order].astype(np.float32)
        P = np.where(placed[:, None], P0, 0.0)
        theta = _guess_model(P, S)
        G, shape = _grid(P[use], theta[0], self.grid_cells)
        cells = np.arange(len(G))
        e_step = self._e_step(S, Obs, starts, theta, cells, shape)
        if len(G) * len(S) > _MAX_POSTERIOR:
            raise ValueError(
                f"VIS-BA's E-step holds {len(S)} steps x {len(G)} candidate viewpoints "
                f"(more than {_MAX_POSTERIOR:.0e}): the objects span {np.ptp(P[use], axis=0)} "
                f"m against a visibility radius of about {theta[0]:.3g} m; lower grid_cells, or "
                "map fewer steps"
            )
        log_prior, theta, G, cells = self._start_model(e_step, P, G, cells, shape, theta)
        post, start_ll = e_step(P, G, theta, log_prior)
        self.start_loglik_ = start_ll / max(Obs.sum(), 1.0)
        start_post, start_theta, start_G, start_sigma = post, theta, G, e_step.sigma
        aligned = np.intersect1d(ids, np.flatnonzero(placed & (views >= self.min_views)))
        P, post, theta, ll = self._em_rounds(e_step, P, G, cells, shape, post, theta, log_prior,
                                             start_ll, free, aligned)
        self.loglik_ = ll / max(Obs.sum(), 1.0)
        finite = np.all(np.isfinite(P[placed])) and np.isfinite(ll)
        self.refined_ = bool(finite and ll >= start_ll)
        if not self.refined_:
            warnings.warn(f"the refined map explains the bits no better than the start "
                          f"(marginal log-likelihood per entry {self.loglik_:.5g} against "
                          f"{self.start_loglik_:.5g}{'' if finite else ', not finite'}): "
                          "the start map is kept", VisibilityAdjustmentWarning, stacklevel=3)
            P, post, theta = np.where(placed[:, None], P0, 0.0), start_post, start_theta
            G = start_G
            e_step.sigma = start_sigma
        (self.radius_, self.softness_, self.miss_rate_, self.occlusion_gain_,
         self.occlusion_power_) = (float(v) for v in theta)
        self.step_sigma_ = e_step.sigma
        self.viewpoints_ = np.full((n, 2), np.nan)
        self.viewpoints_[order] = post @ G  # posterior means
        out = P.copy()
        out[~placed] = np.nan
        return out

    def _usable(self, seen, placed, ids) -> tuple[np.ndarray, ...]:
        """``(step_ok, free, use, views)``: the steps in the likelihood, the objects that move,
        those whose bits take part, and each object's usable views; an object seen from fewer
        than ``min_views`` usable steps keeps its start position (with a warning)."""
        n = len(seen)
        free = placed.copy()
        free[ids] = False
        if self.continuity:  # every step is linked to its neighbours, even one that saw nothing
            step_ok = np.ones(n, dtype=bool)
        else:
            step_ok = (seen & placed).sum(axis=1) >= self.min_step_objects
        views = (seen & step_ok[:, None]).sum(axis=0)
        weak = free & (views < self.min_views)
        self.kept_ = np.flatnonzero(weak)
        if weak.any():
            warnings.warn(f"objects {self.kept_.tolist()} were seen from fewer than "
                          f"{self.min_views} usable steps: they keep the start map's positions",
                          VisibilityAdjustmentWarning, stacklevel=4)
        free &= ~weak
        return step_ok, free, placed & ~weak, views

    def _start_kept(self, P0, n) -> np.ndarray:
        """The start map, and the fitted attributes of a refinement that did not run."""
        self.refined_, self.n_rounds_ = False, 0
        self.loglik_ = self.start_loglik_ = float("nan")
        (self.radius_, self.softness_, self.miss_rate_, self.occlusion_gain_,
         self.occlusion_power_) = (float("nan"),) * 5
        self.viewpoints_ = np.full((n, 2), np.nan)
        self.step_sigma_ = float("nan")
        return P0.copy()

    def _step_order(self, step_ok, timeline) -> tuple[np.ndarray, np.ndarray | None]:
        """The steps in the likelihood, in walk order, and (with ``continuity``) where each run
        of consecutive steps (by the timeline) starts in that order."""
        if not self.continuity:
            return np.flatnonzero(step_ok), None
        n = len(step_ok)
        runs = step_runs(n, timeline)
        starts = np.zeros(n, dtype=bool)
        starts[np.cumsum([0] + [len(r) for r in runs[:-1]])] = True
        return np.concatenate(runs), starts

    def _e_step(self, S, Obs, starts, theta, cells, shape) -> _EStep:
        """The E-step of these bits: the steps independent, or (``continuity``) a walk over the
        ``cells`` of the grid of ``shape``, its width ``step_sigma`` or, if None, fitted from
        two cells."""
        if not self.continuity:
            return _EStep(S, Obs)
        h = theta[0] / self.grid_cells
        sigma = self.step_sigma if self.step_sigma is not None else 2.0 * h
        walk = dict(cells=cells, shape=shape, h=h, sigma=sigma, starts=starts)
        n_links = max(int(len(starts) - starts.sum()), 1)
        return _EStep(S, Obs, walk, n_links, fit_sigma=self.step_sigma is None)

    def _start_model(self, e_step, P, G, cells, shape, theta) -> tuple:
        """The sensor model and the viewpoints' prior of the start map (``prior_iters`` E-steps),
        then the cells no step is likely to have been in dropped: ``(log_prior, theta, G,
        cells)``."""
        log_prior = None
        for i in range(self.prior_iters):
            # (with continuity the first treats the steps as independent: under the guessed
            # model and a uniform prior a walk can settle where nothing is expected to be seen,
            # beyond the objects, and the walk's width collapse)
            post, _ = e_step(P, G, theta, log_prior, independent=i == 0)
            log_prior = _update_prior(post, cells, shape, self.prior_blur)
            theta = _fit_model(P, G, *_expected_counts(e_step.S, e_step.Obs, post), theta,
                               _S_MIN, self.occlusion)
        visited = post.sum(axis=0) > 1e-3
        G, cells = G[visited], cells[visited]
        log_prior = log_prior[visited] - np.log(np.exp(log_prior[visited]).sum())
        if e_step.walk is not None:
            e_step.walk["cells"] = cells
        return log_prior, theta, G, cells

    def _em_rounds(self, e_step, P, G, cells, shape, post, theta, log_prior, ll, free,
                   aligned) -> tuple:
        """EM rounds from the start map's E-step (``post``, log-likelihood ``ll``), at most
        ``max_rounds``, until no object moves more than ``tol``: ``(P, post, theta, ll)``."""
        S, Obs = e_step.S, e_step.Obs
        anchor_free = np.zeros(len(P), dtype=bool)
        anchor_free[aligned] = True
        self.n_rounds_ = 0
        for _ in range(self.max_rounds):
            self.n_rounds_ += 1
            P_old = P.copy()
            Sg, Ng = _expected_counts(S, Obs, post)
            P = _solve_objects(P, G, Sg, Ng, free, theta, self.inner_iters)
            if self.align and aligned.size >= 2:
                # where the anchors' bits put them among the current viewpoints, against where
                # they are: the free objects (and, at the next E-step, the viewpoints) move by
                # the mean difference, which the objects' own M-step moves only slowly
                found = _solve_objects(P, G, Sg, Ng, anchor_free, theta, self.inner_iters)
                P[free] += (P[aligned] - found[aligned]).mean(axis=0)
            if self.overrelax > 0 and self.n_rounds_ > 1:
                P[free] += self.overrelax * (P[free] - P_old[free])
            refit = self.model_rounds is None or self.n_rounds_ <= self.model_rounds
            if refit:
                theta = _fit_model(P, G, Sg, Ng, theta, _S_MIN, self.occlusion)
            post, ll = e_step(P, G, theta, log_prior, refit=refit)
            log_prior = _update_prior(post, cells, shape, self.prior_blur)
            if np.abs(P - P_old).max() <= self.tol:
                break
        return P, post, theta, ll

    def fit_transform(self, X, y=None, *, mask=None, sensor: str = "visibility", anchor_ids=None,
                      anchor_positions=None, timeline=None, start_positions=None):
        """Fit and return the (M, 2) map in world coordinates (NaN rows: not placed)."""
        return self.fit(X, mask=mask, sensor=sensor, anchor_ids=anchor_ids,
                        anchor_positions=anchor_positions, timeline=timeline,
                        start_positions=start_positions).embedding_
