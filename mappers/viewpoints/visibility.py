"""Visibility bundle adjustment of a visibility map (label ``"VIS-BA-WALK"``: with the walk prior).

The paper's methods, and the other visibility mappers here, never estimate where the robot was.
This one does: it starts from the map the visibility default draws (``start``: CAL-SMA for a
complete history, ``DROPOUT-BLEND`` for a masked one; for a flickering one, whose default is
VIS-BA-WALK, the complete default CAL-SMA, and so for any history whose default adjusts viewpoints)
and refines it by treating each step's viewpoint as a latent position. A visibility bit is read
as a noisy range threshold: at distance ``d`` between viewpoint and object

    P(visible | d) = (1 - eps) (1 - gamma min(d / R, 1.5)^k) sigmoid((R - d) / s)

with one visibility radius ``R``, one softness ``s``, one rate ``eps`` of misses that do not
depend on the geometry (a camera's dropouts) and a miss rate that grows with distance (gamma,
k: occlusion by other objects, which is rare near the viewpoint and common near ``R``), all
unknown to the mapper and fitted by maximum likelihood. Only the entries the mask calls
observed enter the likelihood (through a limited view an object outside it is unknown).

The viewpoints are not point estimates, which would sit in the middle of the region the bits
allow and bias the objects (a step sees about 5 objects: its position is known to about 0.1 m);
they are integrated out by EM over a grid of candidate viewpoints (``grid_cells`` cells per
radius over the objects' bounding box widened by ``R``):

1. *E-step*: each step's posterior over the cells, from the bits of the objects it observed
   (one (N, M) x (M, G) product), under a prior over the cells learnt from the data (the mean
   posterior, blurred by ``prior_blur`` cells: the robot's occupancy, which keeps viewpoints out
   of places no step went, such as beyond the walls);
2. *M-step*: each non-anchor object's position by Fisher scoring of its expected
   log-likelihood over the cells (one 2 x 2 system per object, a per-object step halving that
   never lowers it), then ``(R, s, eps, gamma, k)``; the anchors stay at their known positions,
   which fix the gauge (shift, rotation, scale);

for ``max_rounds`` rounds (or until no object moves more than ``tol`` [m]), vectorised with
numpy; the cells no step is likely to have been in are dropped after the start's E-steps.

*Continuity* (``continuity=True``; label ``"VIS-BA-WALK"``, the default for flickering
histories): the steps of a walk are ordered, consecutive viewpoints close together. The E-step is
then a forward-backward pass over the steps (a hidden Markov model over the cells,
:mod:`mappers.viewpoints.walk_prior`): a move is an isotropic Gaussian random walk of width
``step_sigma`` per axis (None: fitted by EM from the expected squared displacement between
consecutive steps; the mapper is not told the step length), a run's first step is drawn from the
learnt occupancy prior, and the marginal likelihood is the HMM's (the guard below compares the
start and refined maps under it). The runs of consecutive steps come from the timeline
(:func:`mappers.core.flicker.step_runs`); every step takes part, one that saw nothing too. The first
E-step treats the steps as independent (under the guessed model a walk can settle where nothing
is expected to be seen, and its fitted width collapse). No odometry, heading or velocity: only
"consecutive steps are close". Two options speed the M-step's slow modes up: ``align`` moves the
free objects by the mean offset between the anchors' known positions and where their bits put
them among the current viewpoints (the interior of a start map can sit shifted against its
anchors, which EM then moves by a few millimetres a round), and ``overrelax`` lengthens each
round's move of the objects by that factor (over-relaxed EM, from the second round);
``model_rounds`` refits the sensor model and the walk's width in the first rounds only. At
``miss_rate = 0.5`` (N = 2000, tuning layouts 100..119) the start CAL-SMA's 0.075 m becomes
0.045 (independent steps: 0.057; continuity alone 0.051, alignment alone 0.052), on the 25
fresh layouts 0.049 (largest run 0.068) against ``DROPOUT-BLEND``'s 0.069, in 0.70 s per map
(``docs/imperfect-sensing.md``).

Guards: an object seen from fewer than ``min_views`` usable steps keeps its start position (its
bits leave the problem); if the refined map's marginal likelihood is below the start map's (its
model and prior fitted the same way), or anything is not finite, the start map is returned.
Each case is a :class:`VisibilityAdjustmentWarning` (``build_map`` lists them in
``Map.warnings``).

*Assumes*: visibility is a range threshold up to misses (a distance, not a visual angle that
differs between objects; occlusion only as a miss rate that grows with distance, not from the
layout); a 360-degree view (through a narrower one the mask carries the heading, which is not
modelled: the viewpoints then sit too close to the objects, see ``docs/imperfect-sensing.md``);
a static world; the bits of one step are taken from one viewpoint. It estimates viewpoints,
which the paper's methods do not. No motion model and no odometry: the steps are independent
viewpoints, found from the history alone; with ``continuity``, the steps are ordered like a
walk's (by the timeline), consecutive viewpoints within a few tenths of the visibility radius:
shuffled or unordered steps break it (``build_map`` picks VIS-BA-WALK only for histories whose
:func:`mappers.core.flicker.persistence` says they are walk-ordered).
"""

from __future__ import annotations

import warnings
from numbers import Integral, Real

import numpy as np
from scipy.ndimage import gaussian_filter
from scipy.optimize import minimize
from scipy.special import expit
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval

from mappers.core.flicker import step_runs
from mappers.defaults import choose_for_history, localisation_free
from mappers.fitting import check_inputs
from mappers.viewpoints.start_map import anchored_start, fit_start

__all__ = ["VisibilityAdjustment", "VisibilityAdjustmentWarning", "visibility_bits"]

_EPS_FLOOR = 1e-4
"""Smallest miss rate of the model (a perfect sensor's bits would otherwise make log(0))."""

_MAX_POSTERIOR = 2e8
"""Largest steps x cells the E-step holds (float32: 800 MB)."""

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


_CAP = 1.5
"""The occlusion term grows with ``d / R`` up to this value and stays flat beyond it."""


def _miss_curve(d, theta):
    """``q(d) = (1 - eps) (1 - gamma min(d / R, cap)^k)``, the chance that an object within the
    threshold is seen, and its derivative in d."""
    R, _, eps, gamma, k = theta
    r = np.minimum(d / R, _CAP)
    q = (1.0 - eps) * (1.0 - gamma * r**k)
    dq = np.where(d / R < _CAP, -(1.0 - eps) * gamma * k * r ** (k - 1) / R, 0.0)
    return q, dq


def _log_terms(d, theta) -> tuple[np.ndarray, np.ndarray]:
    """``(log P(seen), log P(not seen))`` at distance ``d`` (stable forms)."""
    R, s = theta[0], theta[1]
    eta = (R - d) / s
    q, _ = _miss_curve(d, theta)
    sig = 0.5 * (1.0 + np.tanh(0.5 * eta))  # sigmoid without overflow
    return np.log(q) - np.logaddexp(0.0, -eta), np.log1p(-q * sig)


def _loglik(d, yes, no, theta) -> np.ndarray:
    """Per entry, the log-likelihood of ``yes`` bits seen and ``no`` not seen (counts)."""
    a, b = _log_terms(d, theta)
    return yes * a + no * b


def _score_fisher(d, yes, no, theta) -> tuple[np.ndarray, np.ndarray]:
    """Per entry, d loglik / d d and the Fisher information in d (expected -d2/dd2)."""
    R, s = theta[0], theta[1]
    eta = (R - d) / s
    sig = 0.5 * (1.0 + np.tanh(0.5 * eta))
    one_minus = 0.5 * (1.0 - np.tanh(0.5 * eta))
    q, dq = _miss_curve(d, theta)
    pi = q * sig
    dpi = dq * sig - q * sig * one_minus / s  # d P(seen) / d d
    not_seen = 1.0 - pi
    score = yes * (dq / q - one_minus / s) - no * dpi / not_seen
    fisher = dpi * dpi / np.maximum(pi * not_seen, 1e-300)
    return score, (yes + no) * fisher


def _distances(G: np.ndarray, P: np.ndarray) -> np.ndarray:
    """(G, M) distances between the cells and the objects."""
    return np.sqrt(np.maximum(np.sum(G * G, axis=1)[:, None] + np.sum(P * P, axis=1)[None]
                              - 2.0 * G @ P.T, 0.0))


def _guess_model(P, S) -> tuple:
    """Start values of ``(R, s, eps, gamma, k)``: R the 90th percentile of the distances from
    the seen objects to the centroid of the objects each step saw."""
    count = S.sum(axis=1, keepdims=True)
    C = S @ P / np.maximum(count, 1.0)
    d = np.linalg.norm(C[:, None, :] - P[None, :, :], axis=2)[S > 0]
    R = float(np.quantile(d, 0.9)) if d.size and np.quantile(d, 0.9) > 0 else 1.0
    return R, 0.1 * R, 0.1, 0.0, 3.0


def _grid(P, R, cells_per_radius) -> tuple[np.ndarray, tuple[int, int]]:
    """Candidate viewpoints: a square grid of spacing R / cells_per_radius over the objects'
    bounding box widened by R (a step that saw an object was within about R of it), and its
    shape (x-major)."""
    h = R / cells_per_radius
    lo, hi = P.min(axis=0) - R, P.max(axis=0) + R
    xs, ys = np.arange(lo[0], hi[0] + h / 2, h), np.arange(lo[1], hi[1] + h / 2, h)
    return (np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2),
            (len(xs), len(ys)))


def _log_emission(P, G, S, Obs, theta) -> np.ndarray:
    """(N, G) float32 log-likelihood of each step's bits at each cell. ``S`` and ``Obs`` are
    float32 (the (N, G) products and exponentials dominate the cost; the sums are float64)."""
    a, b = _log_terms(_distances(G, P), theta)  # (G, M)
    return Obs @ b.T.astype(np.float32) + S @ (a - b).T.astype(np.float32)


def _posterior(P, G, S, Obs, theta, log_prior=None) -> tuple[np.ndarray, float]:
    """Each step's posterior over the cells (``log_prior`` per cell; None: uniform), the steps
    independent, and the marginal log-likelihood of the bits."""
    L = _log_emission(P, G, S, Obs, theta)
    L += np.float32(-np.log(len(G))) if log_prior is None else log_prior.astype(np.float32)
    top = L.max(axis=1, keepdims=True)
    np.exp(L - top, out=L)
    total = L.sum(axis=1, keepdims=True, dtype=np.float64)
    L /= total.astype(np.float32)
    return L, float(np.sum(top[:, 0].astype(np.float64) + np.log(total[:, 0])))


def _walk_posterior(P, G, S, Obs, theta, log_prior, walk, fit_sigma) -> tuple:
    """Each step's posterior over the cells under the continuity prior (a hidden Markov model:
    :func:`mappers.viewpoints.walk_prior.forward_backward`, ``log_prior`` the distribution of a run's
    first step), its marginal log-likelihood, and the expected squared displacement [m^2]
    summed over the links. ``walk``: dict of the kept ``cells``, the full grid's ``shape``, its
    spacing ``h``, the walk's width ``sigma`` and the run ``starts``."""
    from mappers.viewpoints.walk_prior import forward_backward

    L = _log_emission(P, G, S, Obs, theta)
    top = L.max(axis=1, keepdims=True)
    np.exp(L - top, out=L)
    init = np.exp(log_prior - log_prior.max())
    return forward_backward(L, top[:, 0], init / init.sum(), walk["cells"], walk["shape"],
                            walk["sigma"], walk["h"], walk["starts"], want_disp=fit_sigma)


def _update_prior(post, cells, shape, blur) -> np.ndarray:
    """The log of the viewpoints' distribution over the ``cells`` (indices into the full grid of
    ``shape``): the mean posterior (the EM update of a mixture's weights) blurred by a Gaussian
    of ``blur`` cells (else, with more cells than steps, it collapses onto the current
    viewpoints), floored so that no cell is ruled out for good."""
    full = np.zeros(shape[0] * shape[1])
    full[cells] = post.mean(axis=0)
    if blur > 0:
        full = gaussian_filter(full.reshape(shape), blur, mode="constant").ravel()
    w = full[cells] + 1e-3 / len(cells)
    return np.log(w / w.sum())


def _expected_counts(S, Obs, post) -> tuple[np.ndarray, np.ndarray]:
    """(M, G) expected counts of the bits seen and not seen of each object from each cell under
    the steps' posteriors (float32 products, float64 results)."""
    seen = (S.T @ post).astype(np.float64)
    return seen, np.maximum((Obs.T @ post).astype(np.float64) - seen, 0.0)


def _fit_model(P, G, Sg, Ng, theta, s_min, occlusion=True) -> tuple:
    """Maximum expected log-likelihood ``(R, s, eps, gamma, k)`` (``occlusion`` False: gamma
    stays 0) at the objects ``P`` under the expected counts (the distances binned finely: a fit
    of a few parameters over a few hundred bins)."""
    R0 = theta[0]
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
        k = 1.0 + 5.0 * expit(z[4])  # in (1, 6)
        return (z[0], s_min + np.exp(min(z[1], 50.0)),
                _EPS_FLOOR + (1 - 2 * _EPS_FLOOR) * expit(z[2]),
                (1 - _EPS_FLOOR) * expit(z[3]) / _CAP**k, k)

    def nll(z):
        return -scale * float(np.sum(_loglik(dv, yes, no, unpack(z))))

    R, s, eps, gamma, k = theta
    eps = min(max(eps, 2 * _EPS_FLOOR), 1 - 2 * _EPS_FLOOR)
    g = min(max(gamma * _CAP**k / (1 - _EPS_FLOOR), 1e-4), 1 - 1e-4)
    kk = min(max((k - 1.0) / 5.0, 1e-4), 1 - 1e-4)
    z0 = np.array([R, np.log(max(s - s_min, 1e-3 * s_min + 1e-12)),
                   np.log((eps - _EPS_FLOOR) / (1 - _EPS_FLOOR - eps)), np.log(g / (1 - g)),
                   np.log(kk / (1 - kk))])
    if not occlusion:
        z0, full = z0[:3], z0

        def nll3(z):
            return nll(np.concatenate([z, full[3:]]))
        res = minimize(nll3, z0, method="Nelder-Mead",
                       options={"xatol": 1e-4, "fatol": 1e-8, "maxiter": 200})
        z = np.concatenate([res.x if np.isfinite(res.fun) and res.fun <= nll3(z0) else z0,
                            full[3:]])
        return tuple(float(v) for v in unpack(z))
    res = minimize(nll, z0, method="Nelder-Mead",
                   options={"xatol": 1e-4, "fatol": 1e-8, "maxiter": 300})
    z = res.x if np.isfinite(res.fun) and res.fun <= nll(z0) else z0
    return tuple(float(v) for v in unpack(z))


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
        "max_rounds": [Interval(Integral, 1, None, closed="left")],
        "inner_iters": [Interval(Integral, 1, None, closed="left")],
        "tol": [Interval(Real, 0, None, closed="left")],
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
        self.start = start
        self.max_rounds = max_rounds
        self.inner_iters = inner_iters
        self.tol = tol
        self.min_step_objects = min_step_objects
        self.min_views = min_views
        self.grid_cells = grid_cells
        self.prior_iters = prior_iters
        self.occlusion = occlusion
        self.prior_blur = prior_blur
        self.continuity = continuity
        self.step_sigma = step_sigma
        self.align = align
        self.overrelax = overrelax
        self.model_rounds = model_rounds
        self.random_state = random_state

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
        n, m = seen.shape
        placed = np.all(np.isfinite(P0), axis=1)
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
                          VisibilityAdjustmentWarning, stacklevel=3)
        free &= ~weak
        use = placed & ~weak  # objects whose bits take part
        if step_ok.sum() < 3 or not free.any():
            warnings.warn(f"{int(step_ok.sum())} step(s) saw at least {self.min_step_objects} "
                          f"placed object(s), and {int(free.sum())} object(s) may move: nothing "
                          "to refine, the start map is kept", VisibilityAdjustmentWarning,
                          stacklevel=3)
            self.refined_, self.n_rounds_ = False, 0
            self.loglik_ = self.start_loglik_ = float("nan")
            (self.radius_, self.softness_, self.miss_rate_, self.occlusion_gain_,
             self.occlusion_power_) = (float("nan"),) * 5
            self.viewpoints_ = np.full((n, 2), np.nan)
            self.step_sigma_ = float("nan")
            return P0.copy()
        S = (seen & step_ok[:, None] & use).astype(float)  # (N, M) seen, in the likelihood
        Obs = (observed & step_ok[:, None] & use).astype(float)  # observed, in the likelihood
        order = np.flatnonzero(step_ok)  # the steps in the likelihood, in walk order
        walk = None
        if self.continuity:
            runs = step_runs(n, timeline)
            order = np.concatenate(runs)
            starts = np.zeros(n, dtype=bool)
            starts[np.cumsum([0] + [len(r) for r in runs[:-1]])] = True
        S, Obs = S[order].astype(np.float32), Obs[order].astype(np.float32)
        P = np.where(placed[:, None], P0, 0.0)
        theta = _guess_model(P, S)
        G, shape = _grid(P[use], theta[0], self.grid_cells)
        cells = np.arange(len(G))
        if self.continuity:
            h = theta[0] / self.grid_cells
            sigma = self.step_sigma if self.step_sigma is not None else 2.0 * h
            walk = dict(cells=cells, shape=shape, h=h, sigma=sigma, starts=starts)
            n_links = max(int(n - starts.sum()), 1)

        def e_step(P, G, theta, log_prior, independent=False, refit=True):
            if walk is None or independent:
                return _posterior(P, G, S, Obs, theta, log_prior)
            fit_sigma = refit and self.step_sigma is None
            post, ll, disp = _walk_posterior(P, G, S, Obs, theta, log_prior, walk, fit_sigma)
            if fit_sigma:  # EM update of the walk's width per axis (kept off a degenerate 0)
                walk["sigma"] = float(np.clip(np.sqrt(disp / (2.0 * n_links)),
                                              0.5 * walk["h"], 2.0 * theta[0]))
            return post, ll
        if len(G) * len(S) > _MAX_POSTERIOR:
            raise ValueError(
                f"the visibility adjustment's E-step holds {len(S)} steps x {len(G)} candidate viewpoints "
                f"(more than {_MAX_POSTERIOR:.0e}): the objects span {np.ptp(P[use], axis=0)} "
                f"m against a visibility radius of about {theta[0]:.3g} m; lower grid_cells, or "
                "map fewer steps"
            )
        s_min = 0.0  # the softness is free (the grid's spacing does not bound it)
        log_prior = None
        for i in range(self.prior_iters):  # the start map's model and viewpoints' distribution
            # (with continuity the first treats the steps as independent: under the guessed
            # model and a uniform prior a walk can settle where nothing is expected to be seen,
            # beyond the objects, and the walk's width collapse)
            post, _ = e_step(P, G, theta, log_prior, independent=i == 0)
            log_prior = _update_prior(post, cells, shape, self.prior_blur)
            theta = _fit_model(P, G, *_expected_counts(S, Obs, post), theta, s_min, self.occlusion)
        visited = post.sum(axis=0) > 1e-3  # cells no step is likely to have been in leave
        G, cells = G[visited], cells[visited]
        log_prior = log_prior[visited] - np.log(np.exp(log_prior[visited]).sum())
        if walk is not None:
            walk["cells"] = cells
        post, start_ll = e_step(P, G, theta, log_prior)
        self.start_loglik_ = start_ll / max(Obs.sum(), 1.0)
        start_post, start_theta, start_G = post, theta, G
        start_sigma = walk["sigma"] if walk is not None else float("nan")
        self.n_rounds_, ll = 0, start_ll
        aligned = np.intersect1d(ids, np.flatnonzero(placed & (views >= self.min_views)))
        anchor_free = np.zeros(m, dtype=bool)
        anchor_free[aligned] = True
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
                theta = _fit_model(P, G, Sg, Ng, theta, s_min, self.occlusion)
            post, ll = e_step(P, G, theta, log_prior, refit=refit)
            log_prior = _update_prior(post, cells, shape, self.prior_blur)
            if np.abs(P - P_old).max() <= self.tol:
                break
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
            if walk is not None:
                walk["sigma"] = start_sigma
        (self.radius_, self.softness_, self.miss_rate_, self.occlusion_gain_,
         self.occlusion_power_) = (float(v) for v in theta)
        self.step_sigma_ = walk["sigma"] if walk is not None else float("nan")
        self.viewpoints_ = np.full((n, 2), np.nan)
        self.viewpoints_[order] = post @ G  # posterior means
        out = P.copy()
        out[~placed] = np.nan
        return out

    def fit_transform(self, X, y=None, *, mask=None, sensor: str = "visibility", anchor_ids=None,
                      anchor_positions=None, timeline=None, start_positions=None):
        """Fit and return the (M, 2) map in world coordinates (NaN rows: not placed)."""
        return self.fit(X, mask=mask, sensor=sensor, anchor_ids=anchor_ids,
                        anchor_positions=anchor_positions, timeline=timeline,
                        start_positions=start_positions).embedding_


def _vis_ba(*, start=None, max_rounds=5, inner_iters=3, tol=1e-4, min_step_objects=1,
            min_views=5, grid_cells=6, prior_iters=2, occlusion=True,
            prior_blur=2.0, continuity=False, step_sigma=None, align=False, overrelax=0.0,
            model_rounds=None, random_state=0) -> VisibilityAdjustment:
    return VisibilityAdjustment(start=start, max_rounds=max_rounds, inner_iters=inner_iters,
                                tol=tol, min_step_objects=min_step_objects, min_views=min_views,
                                grid_cells=grid_cells,
                                prior_iters=prior_iters, occlusion=occlusion,
                                prior_blur=prior_blur, continuity=continuity,
                                step_sigma=step_sigma, align=align, overrelax=overrelax,
                                model_rounds=model_rounds, random_state=random_state)
