"""RANGE-3D: a 3-D map from ranges alone (issue 34), complete or masked.

A range history holds ``r_it = |x_i - p_t|``, the distance between object ``i`` and the sensor at
step ``t``; a step's orientation does not enter, so each viewpoint is a point of space. The map
is the least-squares fit of the objects and the viewpoints to the ranges (a range-only bundle
adjustment: multilateration of both sets at once, as in range-only SLAM without a motion model),
with the anchors held at their positions (which fixes the gauge: translation, rotation and
reflection; ranges carry their own scale). Its start:

- a complete history (every object ranged at every step): the 2-D default's idea in three
  dimensions, classical metric unfolding of the squared ranges
  (:class:`mappers.calibrated.unfolding.ClassicalUnfolding` with ``n_components=3``; Schönemann,
  *Psychometrika* 35, 1970), an affine image of the objects taken onto the anchors by the 3-D
  affine fit (:func:`mappers.core.align_3d.fit_affine_3d`: 4 anchors not on one plane);
- a masked one (a range limit, a field of view): what was ranged together is near (the
  co-observation map of the sightings, :class:`mappers.spatial.covisibility_3d.CoVisibility3D`).

Then ``n_rounds`` rounds: each step's position is fitted to its ranges from the current map
(:func:`fit_steps`: multilateration, then Levenberg-Marquardt), and the objects and positions
are adjusted jointly (Levenberg-Marquardt with each step's 3 x 3 block eliminated by the Schur
complement, :func:`mappers.viewpoints.schur_step`; Triggs et al., *Bundle Adjustment — A Modern
Synthesis*, 2000) under a Cauchy loss. A round uses the steps that ranged at least
``min_ranges`` objects spread at least ``min_spread`` across space in the current map: 3 ranges
leave a point of space two mirror images, and a step whose objects lie on one plane (the tags of
one wall) fits its ranges as well from its mirror image in that plane, where it pulls the map
the wrong way. A fresh fit each round lets a step cross to the right side, which the adjustment
alone cannot.

What ranges cannot tell: when the viewpoints all lie on one plane (a camera on a planar robot),
an object and its mirror image in that plane have the same ranges from every step. A complete
history then unfolds to rank 2 and is refused (ValueError naming it); in a masked one the
sightings' start picks each object's side (an object the adjustment carried across the plane is
reflected back at the end: the two fit the ranges alike) and the ranges its distance
from the plane.
"""

from __future__ import annotations

from numbers import Integral, Real

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.utils._param_validation import Interval, StrOptions

from mappers.calibrated import ClassicalUnfolding
from mappers.core.align_3d import apply_affine_3d, check_anchors_3d, fit_affine_3d
from mappers.core.embedding_transformer import EmbeddingTransformer
from mappers.core.errors import MappingError
from mappers.core.iteration_params import ITERATION_CONSTRAINTS
from mappers.core.validation import check_views
from mappers.spatial.adjustment import DAMPING
from mappers.spatial.covisibility_3d import CoVisibility3D
from mappers.viewpoints import (
    DENSE_COUPLING_MAX_BYTES,
    Coupling,
    damped_step,
    robust_cost,
    robust_weights,
    scatter_sum,
    schur_step,
    use_sparse_coupling,
)

__all__ = ["PLANAR_SHARE", "Range3D", "fit_steps", "same_side", "unfold_3d", "viewpoint_plane"]

PLANAR_SHARE = 0.1
"""The fitted viewpoints lie on one plane when their median distance from it is below this share
of their spread along it (a note says so: each object's side of that plane is not measured)."""

NOISE_RATIO = 3.0
"""The unfolding's third singular value must exceed this many times the fourth (the noise
level) for the history to span space; below it the viewpoints (or the objects) lie on one
plane."""


def unfold_3d(R: np.ndarray, ids: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """(M, 3) start of a complete range history ``R`` (M, N): its classical unfolding in three
    dimensions, taken onto the anchors (``ids``, ``pos`` (A, 3)) by the least-squares affine map.
    ValueError when the squared ranges do not span space above their noise (the third singular
    value of the double-centred squares is at most :data:`NOISE_RATIO` times the fourth): the
    viewpoints or the objects lie on one plane, where an object and its mirror image have the
    same ranges."""
    unfold = ClassicalUnfolding(n_components=3)
    flat = ("the viewpoints (or the objects) lie on one plane, where an object and its mirror "
            "image in that plane have the same ranges from every step, so a complete range "
            "history cannot place them in 3-D. Give viewpoints that span space, or a masked "
            "history (its sightings pick the side)")
    try:
        Y = unfold.fit_transform(R)
    except MappingError:
        raise ValueError(f"RANGE-3D: the double-centred squared ranges have rank 2: {flat}") from None
    s = unfold.singular_values_
    noise = s[3] if len(s) > 3 else 0.0
    if not s[2] > NOISE_RATIO * noise:
        raise ValueError(f"RANGE-3D: the double-centred squared ranges' third singular value "
                         f"({s[2]:.3g}) is not above their noise (the fourth, {noise:.3g}): {flat}")
    return apply_affine_3d(Y, fit_affine_3d(Y[ids], pos))


def fit_steps(points: np.ndarray, rows: np.ndarray, cols: np.ndarray, ranges: np.ndarray,
              n_steps: int, *, n_iter: int = 30) -> np.ndarray:
    """(n_steps, 3) positions of the steps fitted to their ranges from fixed ``points`` (M, 3):
    the observation ``k`` is the range ``ranges[k]`` of the point ``rows[k]`` from the step
    ``cols[k]``. Each step is multilaterated: the differences of its squared ranges are linear
    in its position (``r_k^2 - r_l^2 = |x_k|^2 - |x_l|^2 - 2 (x_k - x_l) . p``), solved in least
    squares with a light pull towards the mean of its points moved towards the points' centre by
    its mean range (what fixes the direction its points do not span: see the module's docstring),
    then refined by Levenberg-Marquardt on the ranges themselves, step by step (a step's damping
    rises when its cost would not fall). A step with no observation is NaN."""
    counts = np.bincount(cols, minlength=n_steps).astype(float)
    safe = np.maximum(counts, 1.0)[:, None]

    def per_step(values):
        return np.stack([np.bincount(cols, values[:, d], n_steps) for d in range(values.shape[1])], 1)

    x = points[rows]
    mean = per_step(x) / safe
    mean_r = np.bincount(cols, ranges, n_steps) / safe[:, 0]
    towards = points.mean(axis=0) - mean
    norm = np.linalg.norm(towards, axis=1, keepdims=True)
    towards = np.where(norm > 0, towards / np.where(norm > 0, norm, 1.0), 0.0)
    guess = mean + mean_r[:, None] * towards
    # linear multilateration about each step's mean: 2 (x_k - xbar) . p = |x_k|^2 - r_k^2 - c
    a = x - mean[cols]
    b = np.sum(x * x, axis=1) - ranges**2
    b = b - (np.bincount(cols, b, n_steps) / safe[:, 0])[cols]
    A = np.zeros((n_steps, 3, 3))
    np.add.at(A, cols, 4.0 * a[:, :, None] * a[:, None, :])
    rhs = per_step(2.0 * a * b[:, None])
    reg = 1e-6 * np.maximum(np.trace(A, axis1=1, axis2=2), 1e-12)[:, None, None] * np.eye(3)
    P = np.linalg.solve(A + reg, (rhs + reg[:, 0, 0, None] * guess)[:, :, None])[:, :, 0]

    def costs(P):
        e = np.linalg.norm(P[cols] - x, axis=1) - ranges
        return np.bincount(cols, e * e, n_steps)

    lam = np.full(n_steps, 1e-3)
    cost = costs(P)
    for _ in range(n_iter):
        diff = P[cols] - x
        dist = np.maximum(np.linalg.norm(diff, axis=1), 1e-12)
        u = diff / dist[:, None]
        H = np.zeros((n_steps, 3, 3))
        np.add.at(H, cols, u[:, :, None] * u[:, None, :])
        g = per_step(u * (dist - ranges)[:, None])
        Hd = H + (lam * np.maximum(np.trace(H, axis1=1, axis2=2), 1e-12))[:, None, None] * np.eye(3)
        trial = P - np.linalg.solve(Hd, g[:, :, None])[:, :, 0]
        new = costs(trial)
        better = new < cost
        P[better], cost[better] = trial[better], new[better]
        lam = np.where(better, lam / 10.0, lam * 10.0)
    P[counts == 0] = np.nan
    return P


def _adjust(points, free, steps, obj, step, ranges, *, loss, loss_scale, max_iter, tol):
    """Levenberg-Marquardt on the ``free`` objects' rows of ``points`` (M, 3) and the
    ``steps``' positions (S, 3): observation ``k`` is the range ``ranges[k]`` of object
    ``obj[k]`` from step ``step[k]``; each step's 3 x 3 block is eliminated by the Schur
    complement (:func:`mappers.viewpoints.schur_step`, the engine of the viewpoint
    adjustments), under ``loss`` (None, ``"huber"`` or ``"cauchy"``, iteratively reweighted) of
    scale ``loss_scale`` [m]. The other objects (the anchors) stay fixed. Returns ``(points,
    steps, cost, iterations)``."""
    P, C = points.copy(), steps.copy()
    S, F = len(C), free.size
    free_index = np.full(len(P), -1)
    free_index[free] = np.arange(F)
    f = free_index[obj]
    k = np.flatnonzero(f >= 0)
    sparse = use_sparse_coupling(S, 3, 3, F, DENSE_COUPLING_MAX_BYTES)

    def residuals(P, C):
        diff = P[obj] - C[step]
        dist = np.maximum(np.linalg.norm(diff, axis=1), 1e-12)
        return dist - ranges, diff / dist[:, None]

    def cost_of(P, C):
        return float(robust_cost(residuals(P, C)[0], loss_scale, loss).sum())

    cost, lam, it = cost_of(P, C), 1e-3, 0
    for it in range(1, max_iter + 1):  # noqa: B007 - the count is returned
        e, u = residuals(P, C)
        w = robust_weights(np.abs(e), loss_scale, loss)
        uu = w[:, None, None] * u[:, :, None] * u[:, None, :]
        # d e / d step = -u, d e / d object = u
        U, g = scatter_sum(step, uu, S), scatter_sum(step, -(w * e)[:, None] * u, S)
        V, h = scatter_sum(f[k], uu[k], F), scatter_sum(f[k], (w * e)[k, None] * u[k], F)
        if sparse:
            Wf = Coupling(-uu[k], step[k], f[k], S, F)
        else:
            W = np.zeros((S, 3, F, 3))
            np.add.at(W, (step[k], slice(None), f[k], slice(None)), -uu[k])
            Wf = W.reshape(S, 3, 3 * F)

        def trial(lam, U=U, V=V, Wf=Wf, g=g, h=h, P=P, C=C):
            dc, dp = schur_step(U, V, Wf, g, h, lam)
            Pn, Cn = P.copy(), C + dc
            Pn[free] += dp
            return (Pn, Cn), cost_of(Pn, Cn)

        state, new, lam, improved = damped_step(trial, cost, lam, DAMPING)
        if improved:
            P, C = state
        if not improved or cost - new <= tol * cost:
            cost = new if improved else cost
            break
        cost = new
    return P, C, cost, it


def _sightings_start(seen: np.ndarray, ids: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """(M, 3) co-observation map of the sightings ``seen`` (M, N) (COVIS-3D) with the anchors
    that were ranged with another object (the others cannot be placed by it; they still hold the
    adjustment), NaN rows for the objects never ranged with another."""
    together = (seen.astype(np.int64) @ seen.T.astype(np.int64))
    np.fill_diagonal(together, 0)
    linked = together[ids].sum(axis=1) > 0
    return CoVisibility3D().fit_transform(seen.astype(float), anchor_ids=ids[linked],
                                          anchor_positions=pos[linked])


class Range3D(EmbeddingTransformer, BaseEstimator):
    """Range histories (M, N) -> (M, 3) world positions (see the module's docstring).

    Parameters:
        start: ``"auto"`` (the unfolding for a complete history, the sightings' map for a masked
            one), ``"unfold"`` or ``"sightings"``.
        min_ranges: steps that ranged fewer objects are left out of the adjustment (at least 4
            fix a point of space).
        min_spread: steps whose objects (in the map of the round before) lie nearly on one
            plane are left out of a round: the smallest standard deviation of their positions
            across space below this [m] (0: keep them). Such a step and its mirror image in that plane fit its ranges
            alike, and a step on the wrong side pulls the map.
        n_rounds: rounds of (fit every step to the current map, adjust jointly): a fresh fit
            lets a step cross to its mirror image, which the adjustment alone cannot.
        max_iter, tol: each round's Levenberg-Marquardt iterations at most, and the relative fall
            of the cost below which it stops.
        loss, loss_scale: ``"cauchy"``, ``"huber"`` or None (least squares), and its scale [m]
            (a few times the range noise): a wrong range does not pull the map.

    ``fit(X, mask=None, *, anchor_ids, anchor_positions)``: ``X`` the ranges [m] (> 0 where
    observed), ``mask`` True where observed (None: the entries > 0), the anchors (A, 3), at least
    4 not on one plane. Attributes: ``embedding_`` (M, 3), NaN rows for objects no kept step
    ranged; ``start_`` (M, 3); ``step_positions_`` (N, 3), NaN for the steps left out;
    ``cost_`` (the final robust cost [m^2]); ``notes_`` (what the map could not measure);
    ``n_features_in_``.
    """

    _parameter_constraints: dict = {
        "start": [StrOptions({"auto", "unfold", "sightings"})],
        "min_ranges": [Interval(Integral, 1, None, closed="left")],
        "min_spread": [Interval(Real, 0, None, closed="left")],
        "n_rounds": [Interval(Integral, 1, None, closed="left")],
        **ITERATION_CONSTRAINTS,
        "loss": [StrOptions({"cauchy", "huber"}), None],
        "loss_scale": [Interval(Real, 0, None, closed="neither")],
    }

    def __init__(self, *, start: str = "auto", min_ranges: int = 4, min_spread: float = 0.1,
                 n_rounds: int = 2, max_iter: int = 40, tol: float = 1e-8, loss: str | None = "cauchy",
                 loss_scale: float = 0.05):
        self.start = start
        self.min_ranges = min_ranges
        self.min_spread = min_spread
        self.n_rounds = n_rounds
        self.max_iter = max_iter
        self.tol = tol
        self.loss = loss
        self.loss_scale = loss_scale

    def fit(self, X, y=None, *, anchor_ids=None, anchor_positions=None, mask=None):
        """Map the range history ``X`` (M, N) in 3-D (``mask`` True where observed)."""
        self._validate_params()
        X = check_views(self, X, mask)
        if anchor_ids is None or anchor_positions is None:
            raise ValueError("RANGE-3D needs anchors: anchor_ids and anchor_positions (A, 3)")
        if mask is not None:
            mask = np.asarray(mask)
            if mask.dtype != np.bool_ or mask.shape != X.shape:
                raise ValueError(f"mask must be a bool array of shape {X.shape}, got "
                                 f"{mask.dtype} {mask.shape}")
        seen = X > 0 if mask is None else mask.copy()
        if np.any(X[seen] <= 0):
            raise ValueError("RANGE-3D maps ranges: an observed range is <= 0 (a range is a "
                             "distance; mask the entries that were not sensed)")
        ids, pos = check_anchors_3d(anchor_ids, anchor_positions, X.shape[0], fit="affine")
        complete = bool(seen.all())
        start = ("unfold" if complete else "sightings") if self.start == "auto" else self.start
        if start == "unfold":
            if not complete:
                raise ValueError(f"start='unfold' needs every object ranged at every step; "
                                 f"{int(np.count_nonzero(~seen))} entries were not sensed")
            Y0 = unfold_3d(X, ids, pos)
        else:
            Y0 = _sightings_start(seen, ids, pos)
        Y0[ids] = pos
        keep = seen & (seen.sum(axis=0) >= self.min_ranges)[None, :]
        keep &= np.all(np.isfinite(Y0), axis=1)[:, None]
        Y = np.where(np.isfinite(Y0), Y0, 0.0)
        for _ in range(self.n_rounds):
            rows, cols = _kept_observations(keep, Y, self.min_spread, self.min_ranges)
            step_ids = np.unique(cols)
            local = np.searchsorted(step_ids, cols)
            r = X[rows, cols]
            free = np.setdiff1d(rows, ids)
            steps = fit_steps(Y, rows, local, r, step_ids.size)
            Y, P, cost, _ = _adjust(Y, free, steps, rows, local, r, loss=self.loss,
                                    loss_scale=self.loss_scale, max_iter=self.max_iter,
                                    tol=self.tol)
        plane = viewpoint_plane(P)
        if plane is not None and start == "sightings":
            Y = same_side(Y, Y0, plane, free)
        placed = np.zeros(X.shape[0], dtype=bool)
        placed[rows] = True
        Y[~placed] = np.nan
        Y[ids] = pos
        self.start_ = Y0
        self.step_positions_ = np.full((X.shape[1], 3), np.nan)
        self.step_positions_[step_ids] = P
        self.cost_ = float(cost)
        self.notes_ = _plane_notes(plane, start)
        self.embedding_ = Y
        return self


def _kept_observations(keep, Y, min_spread, min_ranges):
    """``(rows, cols)`` of the observations ``keep`` (M, N) of the steps whose objects, placed at
    ``Y``, spread at least ``min_spread`` [m] across space (:func:`_spread`)."""
    rows, cols = np.nonzero(keep)
    if min_spread > 0:
        spans = _spread(Y, rows, cols, keep.shape[1])
        rows, cols = rows[spans[cols] >= min_spread], cols[spans[cols] >= min_spread]
    if rows.size == 0:
        raise ValueError(f"no step ranged {min_ranges} or more mapped objects spread "
                         f"{min_spread} m or more across space: RANGE-3D cannot place a viewpoint")
    return rows, cols


def _spread(points: np.ndarray, rows: np.ndarray, cols: np.ndarray, n_steps: int) -> np.ndarray:
    """(n_steps,) the smallest standard deviation [m] of the ``points`` each step ranged (the
    square root of the least eigenvalue of their covariance); 0 for a step with none."""
    counts = np.maximum(np.bincount(cols, minlength=n_steps), 1).astype(float)
    x = points[rows]
    mean = np.stack([np.bincount(cols, x[:, d], n_steps) for d in range(3)], 1) / counts[:, None]
    c = x - mean[cols]
    cov = np.zeros((n_steps, 3, 3))
    np.add.at(cov, cols, c[:, :, None] * c[:, None, :])
    return np.sqrt(np.maximum(np.linalg.eigvalsh(cov / counts[:, None, None])[:, 0], 0.0))


def viewpoint_plane(steps: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """``(centre, normal)`` of the plane the fitted ``steps`` (S, 3) lie on, or None when they
    span space: most of them lie on it when their median distance from it is below
    :data:`PLANAR_SHARE` of their spread along it (the plane is refitted on the steps within 3
    median distances of a first fit, so that a few steps stuck at a mirror image do not hide
    it)."""
    if len(steps) < 4:
        return None
    inliers = steps
    for _ in range(2):
        centre = inliers.mean(axis=0)
        _, s, vt = np.linalg.svd(inliers - centre, full_matrices=False)
        dist = np.abs((steps - centre) @ vt[2])
        inliers = steps[dist <= 3.0 * np.median(dist) + 1e-12]
    if not np.median(dist) < PLANAR_SHARE * s[0] / np.sqrt(len(inliers)):
        return None
    return centre, vt[2]


def same_side(Y: np.ndarray, start: np.ndarray, plane, rows: np.ndarray) -> np.ndarray:
    """``Y`` with each of the objects ``rows`` reflected in ``plane`` (centre, normal) when it is
    on the other side of it from its ``start``: ranges from the plane's points cannot tell the two
    apart, so the start's side is kept (the adjustment may carry an object across)."""
    centre, normal = plane
    flip = rows[np.sign((Y[rows] - centre) @ normal) * np.sign((start[rows] - centre) @ normal) < 0]
    Y = Y.copy()
    Y[flip] -= 2.0 * ((Y[flip] - centre) @ normal)[:, None] * normal
    return Y


def _plane_notes(plane, start: str) -> tuple[str, ...]:
    """A note when the viewpoints lie on one ``plane`` (None: they span space): each object's
    side of that plane is not measured by the ranges."""
    if plane is None:
        return ()
    return ("RANGE-3D: the viewpoints lie on one plane: ranges cannot tell an object from its "
            "mirror image in that plane, so each object's side of it is the one it has in the "
            f"{'sightings' if start == 'sightings' else 'start'} map, not measured by the ranges",)
