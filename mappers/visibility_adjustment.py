"""Visibility bundle adjustment of a visibility map (label ``"VIS-BA"``).

The paper's methods, and the other visibility mappers here, never estimate where the robot was.
This one does: it starts from the map the visibility default draws (``start``: CAL-SMA for a
complete history, ``dropout-blend`` for a flickering or masked one, as ``build_map`` picks it)
and refines it by treating each step's viewpoint ``c_t`` as a latent position. A visibility bit
is read as a noisy range threshold: at distance ``d = |c_t - p_j|``

    P(visible) = (1 - eps) * sigmoid((R - d) / s)

with one visibility radius ``R``, one softness ``s`` and one rate ``eps`` of misses (occlusion,
dropouts) for the whole history, all unknown to the mapper and fitted by maximum likelihood.
A bit "seen" says the viewpoint was within about ``R``; a bit "not seen" says little when
``eps`` is large (a camera that misses half its readings), and more when it is small. The
method alternates, vectorised over the steps and objects (Fisher scoring, one 2 x 2 system per
step or object, a per-row step halving that never raises a row's cost):

1. *viewpoints*: each step's position from the bits of the objects it observed, started at the
   centroid of the objects it saw; a step that saw fewer than ``min_step_objects`` objects is
   left out;
2. *parameters*: ``R``, ``s``, ``eps`` from the distances between the current viewpoints and
   objects;
3. *objects*: each non-anchor object's position from the bits of the steps that observed it;
   the anchors stay at their known positions, which fix the gauge (shift, rotation, scale);

for at most ``max_rounds`` rounds, or until no object moves more than ``tol`` [m]. Only the
entries the mask calls observed enter the likelihood: through a limited field of view an
object outside the view is unknown, not "not visible".

Guards: an object seen from fewer than ``min_views`` steps keeps its start position (its bits
leave the problem); if the refined map's likelihood is below the start map's (its viewpoints
and parameters fitted the same way), or anything is not finite, the start map is returned.
Each case is a :class:`VisibilityAdjustmentWarning` (``build_map`` lists them in
``Map.warnings``).

*Assumes*: visibility is a range threshold (an object is visible iff its centre is within one
distance of the viewpoint, up to misses that do not depend on the geometry; occlusion is
treated as a miss); a static world; the bits of one step are taken from one viewpoint. It
estimates viewpoints, which the paper's methods do not. No motion model and no odometry: the
steps are independent viewpoints, found from the history alone.
"""

from __future__ import annotations

import warnings
from numbers import Integral, Real

import numpy as np
from scipy.optimize import minimize
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval

from mappers.align import check_anchors
from mappers.registry import MethodSpec

__all__ = ["VisibilityAdjustment", "VisibilityAdjustmentWarning", "visibility_bits"]

_EPS_FLOOR = 1e-4
"""Smallest miss rate of the model (a perfect sensor's bits would otherwise make log(0))."""

_MIN_DISTANCE = 1e-6
"""Distance [m] below which a viewpoint is taken to sit on an object (direction undefined)."""


class VisibilityAdjustmentWarning(UserWarning):
    """The refinement kept (part of) the start map: too few views, no gain."""


def visibility_bits(X, mask=None) -> tuple[np.ndarray, np.ndarray]:
    """``(seen, observed)``, both (N, M) bool: whether each object was visible at each step, and
    whether the sensor measured that entry (the mask; all True without one). ValueError when
    ``X`` is not a 0/1 history or ``mask`` does not fit it."""
    try:
        X = np.asarray(X, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"a visibility history is a numeric (M, N) array of 0/1: {exc}") from exc
    if X.ndim != 2 or X.shape[0] < 3 or X.shape[1] < 1:
        raise ValueError(f"a visibility history is an (M, N) array with M >= 3 objects and N >= 1 "
                         f"steps, got shape {X.shape}")
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


def _log_terms(eta: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
    """``(log P(seen), log P(not seen))`` at ``eta = (R - d) / s`` (stable forms)."""
    sp = np.logaddexp(0.0, -eta)  # -log sigmoid(eta)
    return np.log1p(-eps) - sp, np.logaddexp(np.log(eps), -eta) - sp


def _loglik(eta, yes, no, eps) -> np.ndarray:
    """Per entry, the log-likelihood of ``yes`` bits seen and ``no`` not seen (counts)."""
    a, b = _log_terms(eta, eps)
    return yes * a + no * b


def _score_fisher(eta, yes, no, eps) -> tuple[np.ndarray, np.ndarray]:
    """Per entry, d loglik / d eta and the Fisher information in eta (expected -d2/d eta2)."""
    sig = 0.5 * (1.0 + np.tanh(0.5 * eta))  # sigmoid without overflow
    one_minus = 0.5 * (1.0 - np.tanh(0.5 * eta))
    not_seen = eps + (1.0 - eps) * one_minus  # 1 - P(seen)
    fisher = (1.0 - eps) * sig * one_minus * one_minus / not_seen
    score = yes * one_minus - no * (1.0 - eps) * sig * one_minus / not_seen
    return score, (yes + no) * fisher


def _distances(G: np.ndarray, P: np.ndarray) -> np.ndarray:
    """(G, M) distances between the cells and the objects."""
    return np.sqrt(np.maximum(np.sum(G * G, axis=1)[:, None] + np.sum(P * P, axis=1)[None]
                              - 2.0 * G @ P.T, 0.0))


def _guess_model(P, S) -> tuple[float, float, float]:
    """Start values of ``(R, s, eps)``: R the 90th percentile of the distances from the seen
    objects to the centroid of the objects each step saw."""
    count = S.sum(axis=1, keepdims=True)
    C = S @ P / np.maximum(count, 1.0)
    d = np.linalg.norm(C[:, None, :] - P[None, :, :], axis=2)[S > 0]
    R = float(np.quantile(d, 0.9)) if d.size and np.quantile(d, 0.9) > 0 else 1.0
    return R, 0.1 * R, 0.1


def _grid(P, R, cells_per_radius) -> np.ndarray:
    """Candidate viewpoints: a square grid of spacing R / cells_per_radius over the objects'
    bounding box widened by R (a step that saw an object was within about R of it)."""
    h = R / cells_per_radius
    lo, hi = P.min(axis=0) - R, P.max(axis=0) + R
    xs, ys = np.arange(lo[0], hi[0] + h / 2, h), np.arange(lo[1], hi[1] + h / 2, h)
    return np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)


def _posterior(P, G, S, O, theta, log_prior=None) -> tuple[np.ndarray, float]:
    """Each step's posterior over the cells (``log_prior`` per cell; None: uniform) and the
    marginal log-likelihood of the bits."""
    R, s, eps = theta
    a, b = _log_terms((R - _distances(G, P)) / s, eps)  # (G, M)
    L = O @ b.T + S @ (a - b).T  # (N, G): sum over observed objects of log P(bit | cell)
    L += -np.log(len(G)) if log_prior is None else log_prior
    top = L.max(axis=1, keepdims=True)
    w = np.exp(L - top)
    total = w.sum(axis=1, keepdims=True)
    return w / total, float(np.sum(top[:, 0] + np.log(total[:, 0])))


def _update_prior(post) -> np.ndarray:
    """The log of the viewpoints' distribution over the cells: the mean posterior (the EM
    update of a mixture's weights), floored so that no cell is ruled out for good."""
    w = post.mean(axis=0) + 1e-3 / post.shape[1]
    return np.log(w / w.sum())


def _fit_model(P, G, S, O, post, theta, s_min) -> tuple[float, float, float]:
    """Maximum expected log-likelihood ``(R, s, eps)`` at the objects ``P`` under the steps'
    posteriors (the distances binned finely: a 3-parameter fit over a few hundred bins)."""
    R0 = theta[0]
    Sg, Ng = S.T @ post, (O - S).T @ post  # (M, G)
    d = _distances(G, P).T
    edges = np.linspace(0.0, 3.0 * R0, 601)
    k = np.minimum(np.searchsorted(edges, d, side="right") - 1, len(edges) - 1)
    yes = np.bincount(k.ravel(), weights=Sg.ravel(), minlength=len(edges))
    no = np.bincount(k.ravel(), weights=Ng.ravel(), minlength=len(edges))
    wsum = np.bincount(k.ravel(), weights=(Sg + Ng).ravel(), minlength=len(edges))
    dsum = np.bincount(k.ravel(), weights=((Sg + Ng) * d).ravel(), minlength=len(edges))
    used = wsum > 0
    dv, yes, no = dsum[used] / wsum[used], yes[used], no[used]
    if yes.sum() <= 0 or no.sum() <= 0:
        return theta
    scale = 1.0 / (yes.sum() + no.sum())

    def unpack(z):
        return (z[0], s_min + np.exp(z[1]),
                _EPS_FLOOR + (1 - 2 * _EPS_FLOOR) / (1 + np.exp(-z[2])))

    def nll(z):
        R, s, eps = unpack(z)
        return -scale * float(np.sum(_loglik((R - dv) / s, yes, no, eps)))

    R, s, eps = theta
    eps = min(max(eps, 2 * _EPS_FLOOR), 1 - 2 * _EPS_FLOOR)
    z0 = np.array([R, np.log(max(s - s_min, 1e-3 * s_min + 1e-12)),
                   np.log((eps - _EPS_FLOOR) / (1 - _EPS_FLOOR - eps))])
    res = minimize(nll, z0, method="Nelder-Mead",
                   options={"xatol": 1e-6, "fatol": 1e-10, "maxiter": 600})
    z = res.x if np.isfinite(res.fun) and res.fun <= nll(z0) else z0
    return tuple(float(v) for v in unpack(z))


def _solve_objects(P, G, Sg, Ng, free, theta, iters) -> np.ndarray:
    """Fisher scoring of the ``free`` objects' positions on the expected counts ``Sg`` (seen)
    and ``Ng`` (not seen) of each (object, cell); a per-object step halving that never lowers
    an object's expected log-likelihood."""
    R, s, eps = theta
    idx = np.flatnonzero(free)
    if not idx.size:
        return P
    Q, Sj, Nj = P[idx].copy(), Sg[idx], Ng[idx]

    def geometry(Q):
        diff = Q[:, None, :] - G[None, :, :]  # (F, G, 2)
        d = np.sqrt(np.sum(diff * diff, axis=2))
        return d, diff / np.maximum(d, _MIN_DISTANCE)[..., None]

    def row_ll(Q):
        return np.sum(_loglik((R - geometry(Q)[0]) / s, Sj, Nj, eps), axis=1)

    current = row_ll(Q)
    for _ in range(iters):
        d, u = geometry(Q)
        score, fisher = _score_fisher((R - d) / s, Sj, Nj, eps)
        g = -np.einsum("fg,fgi->fi", score, u) / s  # d eta / d p = -u / s
        F = np.einsum("fg,fgi,fgj->fij", fisher, u, u) / s**2
        F += (1e-12 + 1e-6 * np.trace(F, axis1=1, axis2=2))[:, None, None] * np.eye(2)
        step = np.linalg.solve(F, g[..., None])[..., 0]
        step = np.clip(np.nan_to_num(step), -R, R)  # a step of more than the radius is not trusted
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
            ``build_map`` picks for the history).
        max_rounds: rounds of (viewpoints, parameters, objects).
        inner_iters: Fisher-scoring iterations per block and round.
        tol: stop when no object moves more than this [m] in a round.
        min_step_objects: a step that saw fewer objects is left out (its viewpoint is free).
        min_views: an object seen from fewer usable steps keeps its start position.
        random_state: handed to the start method.

    Attributes:
        embedding_ (M, 2) in world coordinates; start_ the start map; viewpoints_ (N, 2) the
        estimated viewpoints (NaN rows: steps left out); radius_, softness_, miss_rate_ the
        fitted model; kept_ (indices of objects that kept their start); n_rounds_;
        loglik_, start_loglik_ (per observed entry); refined_ (False: the start map was kept).
    """

    _parameter_constraints: dict = {
        "start": [str, None],
        "max_rounds": [Interval(Integral, 1, None, closed="left")],
        "inner_iters": [Interval(Integral, 1, None, closed="left")],
        "tol": [Interval(Real, 0, None, closed="left")],
        "min_step_objects": [Interval(Integral, 1, None, closed="left")],
        "min_views": [Interval(Integral, 1, None, closed="left")],
        "grid_cells": [Interval(Integral, 2, None, closed="left")],
        "min_softness": [Interval(Real, 0, None, closed="neither")],
        "prior_iters": [Interval(Integral, 1, None, closed="left")],
        "random_state": ["random_state"],
    }

    def __init__(self, *, start: str | None = None, max_rounds: int = 8, inner_iters: int = 3,
                 tol: float = 1e-4, min_step_objects: int = 1, min_views: int = 5,
                 grid_cells: int = 8, min_softness: float = 0.25, prior_iters: int = 3,
                 random_state=0) -> None:
        self.start = start
        self.max_rounds = max_rounds
        self.inner_iters = inner_iters
        self.tol = tol
        self.min_step_objects = min_step_objects
        self.min_views = min_views
        self.grid_cells = grid_cells
        self.min_softness = min_softness
        self.prior_iters = prior_iters
        self.random_state = random_state

    def _start_map(self, X, mask, ids, pos, timeline) -> np.ndarray:
        from mappers.pipeline import build_map  # the pipeline imports the registry of methods

        if self.start is not None and self.start.strip().upper() == "VIS-BA":
            raise ValueError("start must name another method than 'VIS-BA'")
        m = build_map(X, ids, pos, self.start, sensor="visibility", mask=mask, timeline=timeline,
                      random_state=self.random_state)
        for note in m.warnings:
            warnings.warn(f"start map ({m.method}): {note}", VisibilityAdjustmentWarning,
                          stacklevel=3)
        self.start_method_ = m.method
        return m.positions

    def fit(self, X, y=None, *, mask=None, sensor: str = "visibility", anchor_ids=None,
            anchor_positions=None, timeline=None, start_positions=None):
        """Map the visibility history ``X`` ((M, N) of 0/1; ``mask`` True where observed) with
        the anchors (rows of X) held at their positions. ``start_positions`` ((M, 2), NaN rows:
        not placed) replaces the start method's map."""
        self._validate_params()
        if sensor != "visibility":
            raise ValueError(f"VIS-BA maps visibility histories, got sensor {sensor!r}")
        seen, observed = visibility_bits(X, mask)
        m = seen.shape[1]
        if anchor_ids is None or anchor_positions is None:
            raise ValueError("VIS-BA needs anchor_ids and anchor_positions (they fix the gauge)")
        ids, pos = check_anchors(anchor_ids, anchor_positions, m)
        if start_positions is None:
            self.start_method_ = None
            P0 = self._start_map(np.asarray(X, dtype=float), mask, ids, pos, timeline)
        else:
            self.start_method_ = "given"
            P0 = np.array(start_positions, dtype=float)
            if P0.shape != (m, 2):
                raise ValueError(f"start_positions must have shape ({m}, 2), got {P0.shape}")
        P0[ids] = pos
        self.start_ = P0.copy()
        self.embedding_ = self._refine(seen, observed, P0, ids)
        return self

    def _refine(self, seen, observed, P0, ids) -> np.ndarray:
        n, m = seen.shape
        placed = np.all(np.isfinite(P0), axis=1)
        free = placed.copy()
        free[ids] = False
        step_ok = (seen & placed).sum(axis=1) >= self.min_step_objects
        views = (seen & step_ok[:, None]).sum(axis=0)
        weak = free & (views < self.min_views)
        self.kept_ = np.flatnonzero(weak)
        if weak.any():
            warnings.warn(f"objects {self.kept_.tolist()} were seen from fewer than "
                          f"{self.min_views} usable steps: they keep the start map's positions",
                          VisibilityAdjustmentWarning, stacklevel=3)
        free &= ~weak
        use = placed & ~weak  # objects whose bits take part
        S = (seen & step_ok[:, None] & use).astype(float)  # (N, M) seen, in the likelihood
        O = (observed & step_ok[:, None] & use).astype(float)  # observed, in the likelihood
        S, O = S[step_ok], O[step_ok]
        P = np.where(placed[:, None], P0, 0.0)
        theta = _guess_model(P, S)
        G = _grid(P[use], theta[0], self.grid_cells)
        h = float(G[1, 0] - G[0, 0]) if len(G) > 1 else theta[0]
        s_min = self.min_softness * h
        theta = (theta[0], max(theta[1], s_min), theta[2])
        log_prior = None
        for _ in range(self.prior_iters):  # the start map's model and viewpoints' distribution
            post, _ = _posterior(P, G, S, O, theta, log_prior)
            log_prior = _update_prior(post)
            theta = _fit_model(P, G, S, O, post, theta, s_min)
        post, start_ll = _posterior(P, G, S, O, theta, log_prior)
        self.start_loglik_ = start_ll / max(O.sum(), 1.0)
        start_post, start_theta = post, theta
        rounds, ll = 0, start_ll
        for rounds in range(1, self.max_rounds + 1):
            P_old = P.copy()
            Sg, Ng = S.T @ post, (O - S).T @ post  # (M, G) expected seen / not-seen counts
            P = _solve_objects(P, G, Sg, Ng, free, theta, self.inner_iters)
            theta = _fit_model(P, G, S, O, post, theta, s_min)
            post, ll = _posterior(P, G, S, O, theta, log_prior)
            log_prior = _update_prior(post)
            if np.abs(P - P_old).max() <= self.tol:
                break
        self.n_rounds_ = rounds
        self.loglik_ = ll / max(O.sum(), 1.0)
        finite = np.all(np.isfinite(P[placed])) and np.isfinite(ll)
        self.refined_ = bool(finite and ll >= start_ll)
        if not self.refined_:
            warnings.warn(f"the refined map explains the bits no better than the start "
                          f"(marginal log-likelihood per entry {self.loglik_:.5g} against "
                          f"{self.start_loglik_:.5g}{'' if finite else ', not finite'}): "
                          "the start map is kept", VisibilityAdjustmentWarning, stacklevel=3)
            P, post, theta = np.where(placed[:, None], P0, 0.0), start_post, start_theta
        self.radius_, self.softness_, self.miss_rate_ = (float(v) for v in theta)
        self.viewpoints_ = np.full((n, 2), np.nan)
        self.viewpoints_[step_ok] = post @ G  # posterior means
        out = P.copy()
        out[~placed] = np.nan
        return out

    def fit_transform(self, X, y=None, *, mask=None, sensor: str = "visibility", anchor_ids=None,
                      anchor_positions=None, timeline=None, start_positions=None):
        """Fit and return the (M, 2) map in world coordinates (NaN rows: not placed)."""
        return self.fit(X, mask=mask, sensor=sensor, anchor_ids=anchor_ids,
                        anchor_positions=anchor_positions, timeline=timeline,
                        start_positions=start_positions).embedding_


def _vis_ba(*, start=None, max_rounds=8, inner_iters=3, tol=1e-4, min_step_objects=1,
            min_views=5, grid_cells=8, min_softness=0.25, prior_iters=3,
            random_state=0) -> VisibilityAdjustment:
    return VisibilityAdjustment(start=start, max_rounds=max_rounds, inner_iters=inner_iters,
                                tol=tol, min_step_objects=min_step_objects, min_views=min_views,
                                grid_cells=grid_cells, min_softness=min_softness,
                                prior_iters=prior_iters, random_state=random_state)


SPEC = MethodSpec(
    "VIS-BA",
    _vis_ba,
    {},
    {"max_rounds": [4, 8, 16]},
    "the visibility default's map refined by estimating the viewpoints (visibility bundle "
    "adjustment: a range threshold with misses), anchors fixed",
    uses_anchors=True,
    sensors=("visibility",),
    normalize=False,
    histories=("complete", "masked"),
    uses_timeline=True,
)
