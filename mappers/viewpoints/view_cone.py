"""View-cone adjustment of a masked visibility map (label ``"VIEW-BA"``).

Through a camera's limited view the mask of a visibility history says, at each step, which
objects were inside the view: every object within the view cone, near or far, whether or not it
was visible (visible means near and not hidden; the bit says that). The co-observation methods
read the mask only as "not measured"; it is geometry: from the step's viewpoint and heading the
observed objects lie inside one cone of half-angle ``h`` and the others outside it, one bit of
bearing for every object at every step. This method estimates each step's viewpoint and heading
as latent variables and the objects with them, as BEARING-BA (:mod:`mappers.viewpoints.bearing`)
does with bearings: a view-cone bundle adjustment. No motion model, no odometry: the steps are
independent viewpoints, found from the history alone.

The model, per (step, object) pair (``alpha`` the object's angle off the heading, ``d`` its
distance; :mod:`mappers.viewpoints.view_cone_kernels`):

- the cone, every pair: ``P(observed) = sigmoid(+-(cos(alpha) - cos(h)) / softness)``;
- the bit, observed pairs: ``P(visible) = (1 - miss_rate) sigmoid((R - d) / range_softness)``
  (plus a floor of 1e-3): visible within a radius ``R``, fitted by maximum likelihood; the miss
  rate absorbs occlusion.

The steps:

1. **The start map**, drawn by ``start`` (default ``DROPOUT-BLEND``, the masked visibility
   default before this method).
2. **The view's width**, a camera's calibration: ``fov_deg`` if given, else the width whose cone
   explains the observed sets best on the start map (:func:`estimate_fov`).
3. **Viewpoints**, per step, the best of a grid of positions x headings over the start map's
   bounding box (one (N, M) x (M, G) product), then ``pose_iters`` Newton steps each.
4. **Joint Gauss-Newton** (Levenberg-Marquardt) of the viewpoints and the free objects, the
   viewpoints eliminated per step (BEARING-BA's Schur complement); ``R`` by a 1-D search every
   few rounds; the anchors fixed (they fix the gauge).
5. **Passes**: steps 2-4 again from the adjusted map, ``passes`` in all (3 by default), while
   each lowers the loss.

Guards: steps that observed nothing are left out (their viewpoint is free); if the refined loss
is not below the start's (viewpoints fitted to the start map) or anything is not finite, the
start map is returned, with a :class:`ViewAdjustmentWarning`. So is it when the view is wider
than :data:`MAX_FOV_DEG` (the sets say little about a heading), and when the mask does not look
like a view cone: its loss per pair from the best viewpoints of the start map above
``max_start_loss`` (a 360-degree view with a range limit, say). A poor start map gives that
verdict too (its objects misplaced, no viewpoint explains the sets), so before it is accepted
the adjustment starts again from each of ``fallback_starts`` in turn and keeps the first that
does look like a view cone (a drawn start only: a given ``start_positions`` has none).

*Assumes*: the mask is a view cone centred on the heading (every object inside it observed at
any distance, none outside: a range limit is not modelled); visibility is a range threshold up
to misses; a static world; one viewpoint per step. What it gains over its start, and what was
tried: ``docs/imperfect-sensing.md``, section "VIEW-BA".

References: Triggs et al., *Bundle Adjustment — A Modern Synthesis* (2000), for the bundle
adjustment and its Schur complement; Böhning & Lindsay (1988) for the bound on the logistic's
curvature.
"""

from __future__ import annotations

import math
import warnings
from numbers import Integral, Real

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.special import log_expit
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval

from mappers.catalog import METHODS
from mappers.core.estimator_params import store_params
from mappers.core.validation import check_views
from mappers.defaults import localisation_free
from mappers.viewpoints import view_cone_kernels as view_kernels
from mappers.viewpoints.engine import Damping, damped_step, joint_step
from mappers.viewpoints.start_map import anchored_start, fit_start, free_objects, keep_if_better

__all__ = ["FALLBACK_STARTS", "MAX_FOV_DEG", "MAX_FREE_OBJECTS", "VIEWPOINT_SEARCH_CONSTRAINTS", "ConeProblem",
           "ViewAdjustment", "ViewAdjustmentWarning", "estimate_fov", "search_cells", "search_poses",
           "view_cone_score"]

DAMPING = Damping(up=5.0, down=3.0, floor=1e-6, tries=8, accept_equal=False)
"""VIEW-BA's Levenberg-Marquardt damping rule (:class:`mappers.viewpoints.engine.Damping`): a
rejected step raises the damping 5x, at most 8 times; an accepted one lowers it 3x."""

MAX_FOV_DEG = 150.0
"""Widest view [deg] the adjustment reads: a wider cone says little about the heading (with a
180-degree camera the views are estimated 165 or 195 degrees wide, and the adjustment moved
the map both ways)."""

MAX_FREE_OBJECTS = 2000
"""Most free (non-anchor) objects VIEW-BA takes: its joint step holds an (N, 3, 2F) block and
solves a (2F, 2F) system per round (at F = 2,000 and N = 2,000: 96 MB and 24 GFLOP a round)."""

VIEWPOINT_SEARCH_CONSTRAINTS: dict = {
    "grid": [Interval(Integral, 2, None, closed="left")],
    "headings": [Interval(Integral, 4, None, closed="left")],
    "pose_iters": [Interval(Integral, 0, None, closed="left")],
}
"""scikit-learn's constraints of the viewpoints' grid search parameters (``grid`` positions per
side x ``headings`` (:func:`search_cells`, :func:`search_poses`), then ``pose_iters`` Newton
steps of each viewpoint alone), shared by VIEW-BA and FRUSTUM-BA
(:class:`mappers.spatial.FrustumAdjustment`)."""

_PASS_ATTRS = ("embedding_", "refined_", "fov_deg_", "radius_", "poses_", "loss_",
               "start_loss_", "cone_rejected_")
"""What one pass of :meth:`ViewAdjustment.fit` sets."""

_FIT_ATTRS = (*_PASS_ATTRS, "start_", "start_method_")
"""What the passes from one start map set (compared between a start and its fallbacks)."""

FALLBACK_STARTS = ("COVIS-SPARSE",)
"""VIEW-BA's default ``fallback_starts``: the start maps tried, in turn, when the first start's
map does not look like a view cone (chosen on a second simulator, confirmed on the project's
world: ``docs/dead-ends.md``, "Defaults that carry")."""

_MAX_SCORE_ENTRIES = 5e8
"""Largest steps x candidate viewpoints the grid search holds (float64: 4 GB)."""


class ViewAdjustmentWarning(UserWarning):
    """VIEW-BA left objects or steps out, or kept its start map."""


def _cos_off(P, cells, headings: int):
    """``(cos_off, poses)``: the cosine of each object's angle off the heading (G * H, M) from
    each candidate viewpoint, and the candidates (G * H, 3) as (x, y, heading)."""
    th = np.linspace(-math.pi, math.pi, headings, endpoint=False)
    rel = P[None, :, :] - cells[:, None, :]
    phi = np.arctan2(rel[..., 1], rel[..., 0])
    cos_off = np.cos(phi[:, None, :] - th[None, :, None]).reshape(-1, P.shape[0])
    return cos_off, search_poses(cells, headings)


def search_poses(cells: np.ndarray, headings: int) -> np.ndarray:
    """The candidate viewpoints of the grid search: each of the floor positions ``cells``
    (G, 2) with each of ``headings`` evenly spaced headings from -pi, as (G * H, 3) rows
    ``(x, y, heading)`` (a cell's headings consecutive)."""
    th = np.linspace(-math.pi, math.pi, headings, endpoint=False)
    return np.column_stack([np.repeat(cells, headings, axis=0), np.tile(th, len(cells))])


def _cone_log_terms(cos_off, half_angle: float, softness: float):
    """``(log_in, log_out)``: each candidate's log-probability that each object is observed /
    not under a cone of ``half_angle``."""
    z = (cos_off - math.cos(half_angle)) / softness
    return log_expit(z), log_expit(-z)


def search_cells(P, grid: int) -> np.ndarray:
    """The floor positions of the grid search: ``grid`` x ``grid`` points evenly spaced over the
    bounding box of the plan ``P`` (M, 2), as (grid^2, 2) rows."""
    lo, hi = P.min(axis=0), P.max(axis=0)
    xs, ys = np.linspace(lo[0], hi[0], grid), np.linspace(lo[1], hi[1], grid)
    return np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)


def _check_score_input(P, Ob, grid, headings, softness):
    if P.ndim != 2 or P.shape[1] != 2:
        raise ValueError(f"positions must have shape (M, 2), got {P.shape}")
    if Ob.ndim != 2 or Ob.shape[1] != P.shape[0]:
        raise ValueError(f"observed must have shape (N, {P.shape[0]}), got {Ob.shape}")
    if grid < 2 or headings < 1 or not softness > 0:
        raise ValueError(f"need grid >= 2, headings >= 1 and softness > 0; got {grid}, "
                         f"{headings}, {softness}")
    if np.sum(np.all(np.isfinite(P), axis=1)) < 2:
        raise ValueError("the view-cone score needs at least 2 placed objects")
    if Ob.shape[0] * grid * grid * headings > _MAX_SCORE_ENTRIES:
        raise ValueError(f"{Ob.shape[0]} steps x {grid * grid * headings} candidate viewpoints "
                         f"exceed {_MAX_SCORE_ENTRIES:.0e} entries: lower grid or headings")


def view_cone_score(positions, observed, half_angle, *, grid: int = 10, headings: int = 24,
                    softness: float = 0.1):
    """How well a view cone of ``half_angle`` [rad] explains each step's observed set: per step
    the log-likelihood of the set from the best viewpoint of a grid (positions over the map's
    bounding box x headings), averaged over the steps; higher is better, comparable between
    maps or half-angles on the same history only. An array of half-angles gives an array.

    Args:
        positions: (M, 2) map; NaN rows (unplaced objects) leave the score.
        observed: (N, M) bool, True where step t observed object j.
        half_angle: the cone's half-angle [rad] in (0, pi), a float or an array.
        grid, headings: candidate positions per side, candidate headings.
        softness: the cone's softness in units of ``cos(alpha)``.
    """
    P = np.asarray(positions, dtype=float)
    Ob = np.asarray(observed, dtype=bool)
    halves = np.asarray(half_angle, dtype=float)
    _check_score_input(P, Ob, grid, headings, softness)
    if not np.all((halves > 0.0) & (halves < math.pi)):
        raise ValueError(f"half_angle must be in (0, pi) radians, got {half_angle}")
    placed = np.all(np.isfinite(P), axis=1)
    P = P[placed]
    cos_off, _ = _cos_off(P, search_cells(P, grid), headings)
    scores = _profile(cos_off, Ob[:, placed], halves.ravel(), softness)
    return float(scores[0]) if halves.ndim == 0 else scores.reshape(halves.shape)


def _profile(cos_off, observed, halves, softness: float) -> np.ndarray:
    """:func:`view_cone_score` of each half-angle in ``halves`` from the candidates' ``cos_off``
    ((G * H, M), placed objects only) and ``observed`` ((N, M) of those objects)."""
    Ob = np.asarray(observed, dtype=float)
    scores = np.empty(len(halves))
    for k, half in enumerate(halves):
        log_in, log_out = _cone_log_terms(cos_off, float(half), softness)
        ll = Ob @ (log_in - log_out).T + log_out.sum(axis=1)[None, :]  # (N, G * H)
        scores[k] = ll.max(axis=1).mean()
    return scores


def estimate_fov(positions, observed, *, step_stride: int = 16, softness: float = 0.03) -> float:
    """The view's width [deg] whose cone explains the observed sets best on a map: the
    half-angle of the highest :func:`view_cone_score` (every ``step_stride``-th step, a sharp
    ``softness``) over 7.5-degree steps from 15 to 127.5 degrees, doubled."""
    if not (isinstance(step_stride, Integral) and step_stride >= 1):
        raise ValueError(f"step_stride must be an integer >= 1, got {step_stride!r}")
    scores = view_cone_score(positions, np.asarray(observed, dtype=bool)[::step_stride],
                             np.radians(_FOV_HALVES), softness=softness)
    return 2.0 * float(_FOV_HALVES[int(np.argmax(scores))])


_FOV_HALVES = np.arange(15.0, 130.0, 7.5)
"""The half-angles [deg] :func:`estimate_fov` tries."""


class ConeProblem:
    """The view-cone loss of fixed observations and its Gauss-Newton steps.

    ``obs`` and ``seen`` ((N, U) bool): which of the U objects each of N steps observed, and
    saw; ``free_index[j]`` is object j's row among the ``n_free`` free objects, or -1 (an
    anchor: held). The half-angle, the softnesses and the miss rate are VIEW-BA's. Shared by
    :class:`ViewAdjustment` and the online update of its map (:mod:`mappers.online.view_cone`).
    """

    def __init__(self, obs, seen, free_index, n_free: int, half: float, softness: float,
                 range_softness: float, miss_rate: float) -> None:
        self.obs = np.ascontiguousarray(obs, dtype=bool)
        self.seen = np.ascontiguousarray(seen, dtype=bool)
        self.free_index, self.n_free = free_index, int(n_free)
        self.half, self.cos_h = float(half), math.cos(half)
        self.s_c, self.s_r, self.eps = softness, range_softness, miss_rate
        self._none = np.full(len(free_index), -1, dtype=np.int64)

    def cost(self, P, C, R) -> float:
        """The loss of objects ``P`` (U, 2), viewpoints ``C`` (N, 3) and radius ``R``."""
        return view_kernels.cone_cost(P, C, self.obs, self.seen, self.cos_h, R, self.s_c,
                                      self.s_r, self.eps)

    def blocks(self, P, C, R, *, objects: bool = True):
        """``(loss, U, V, W, g, h)``: the normal equations' blocks; ``objects=False``: the
        viewpoints' blocks only (the objects held)."""
        fi, nf = (self.free_index, self.n_free) if objects else (self._none, 0)
        n = len(C)
        U, g = np.zeros((n, 3, 3)), np.zeros((n, 3))
        V, h, W = np.zeros((nf, 2, 2)), np.zeros((nf, 2)), np.zeros((n, 3, 2 * nf))
        loss, _ = view_kernels.cone_blocks(P, C, self.obs, self.seen, fi, self.cos_h, R,
                                           self.s_c, self.s_r, self.eps, U, V, W, g, h)
        return loss, U, V, W, g, h

    def fit_radius(self, P, C, R) -> float:
        """The visibility radius of least loss (a bounded 1-D search), or ``R`` if not lower."""
        span = float(np.ptp(P, axis=0).max())
        res = minimize_scalar(lambda r: self.cost(P, C, r), bounds=(0.02 * span, span),
                              method="bounded", options={"xatol": 5e-3 * span})
        return float(res.x) if res.fun < self.cost(P, C, R) else R

    def pose_step(self, P, C, R, loss):
        """``(C, loss)`` after one damped Newton step of every viewpoint alone (the objects
        held), kept only if it lowers the total loss ``loss`` of ``C``."""
        _, U, _, _, g, _ = self.blocks(P, C, R, objects=False)
        U[:, [0, 1, 2], [0, 1, 2]] *= 1.1
        U[:, [0, 1, 2], [0, 1, 2]] += 1e-9
        C2 = C - np.linalg.solve(U, g[..., None])[..., 0]
        trial = self.cost(P, C2, R)
        return (C2, trial) if trial < loss else (C, loss)

    def lm_round(self, P, C, R, loss, lam):
        """``(P, C, loss, lam, moved)``: one Levenberg-Marquardt round of the viewpoints and the
        free objects (BEARING-BA's Schur step), the damping raised until the loss falls (at
        most 8 tries; ``moved`` False: none did, nothing changed)."""
        _, U, V, W, g, h = self.blocks(P, C, R)

        def trial(lam):
            dc, dp = joint_step(U, V, W, g, h, lam)
            C2, P2 = C + dc, P.copy()
            P2[self.free_index >= 0] += dp
            return (P2, C2), self.cost(P2, C2, R)

        state, loss, lam, moved = damped_step(trial, loss, lam, DAMPING)
        return (*(state if moved else (P, C)), loss, lam, moved)


class ViewAdjustment(TransformerMixin, BaseEstimator):
    """View-cone bundle adjustment of a masked visibility map (module docstring).

    Parameters:
        start: label of the method that draws the start map (None: ``DROPOUT-BLEND``). A
            method that maps masked histories gets the mask; another gets the history with the
            unobserved entries as 0.
        fov_deg: the camera's field of view [deg] in (0, 360), or None: estimated.
        rounds: Levenberg-Marquardt rounds per start.
        softness: the cone's softness in units of ``cos(alpha)``.
        range_softness: the visibility radius' softness [m].
        miss_rate: the bits' miss rate (occlusion, dropouts).
        grid, headings: the viewpoints' search grid (positions per side, headings).
        pose_iters: Newton steps of each viewpoint after the search.
        max_start_loss: the loss per pair of the start map (viewpoints fitted) above which the
            mask is not read as a view cone and the start map is kept (between a cone's mask
            and a range limit's: ``docs/imperfect-sensing.md``, section "VIEW-BA", Guards).
        fallback_starts: labels of the methods whose start maps are tried, in turn, when the
            first start's map does not look like a view cone (its loss per pair from the best
            viewpoints above ``max_start_loss``): the first whose map does is adjusted and kept,
            with a warning naming it; when none does, the first start's verdict stands. Only
            for a drawn start (not ``start_positions``); None or ``()``: none tried. Each is
            drawn only when needed (on the project's world never: ``docs/dead-ends.md``,
            "Defaults that carry").
        passes: adjustments in a row, each from the map of the one before with the view's
            width (unless given), the radius and the viewpoints found afresh on it; a pass that
            does not lower its start's loss ends them and the map before it stands. Later
            passes correct a width misread on a poor start map. Default 3: the only count whose
            mean MPE through a 90-degree view stays <= 0.05 m on both simulators, each on two
            sets of 25 layouts (one pass misses on the second simulator; three cost about twice
            the CPU of one): ``docs/dead-ends.md``, "Defaults that carry".
        random_state: handed to the start methods.

    Attributes:
        embedding_ (M, 2) in world coordinates; start_ the start map; start_method_ its label;
        fov_deg_ the view's width used; radius_ the fitted visibility radius; poses_ (N, 3) the
        viewpoints (NaN rows: steps left out); loss_, start_loss_ (per pair, of the last pass
        kept); refined_ (False: the start map was kept); cone_rejected_ (True: the observed sets
        did not look like a view cone from the kept start); starts_tried_ the labels of the
        start maps adjusted, in order (the first, then any fallbacks).
    """

    _parameter_constraints: dict = {
        "start": [str, None],
        "fov_deg": [Interval(Real, 0, 360, closed="neither"), None],
        "rounds": [Interval(Integral, 1, None, closed="left")],
        "softness": [Interval(Real, 0, None, closed="neither")],
        "range_softness": [Interval(Real, 0, None, closed="neither")],
        "miss_rate": [Interval(Real, 0, 1, closed="left")],
        **VIEWPOINT_SEARCH_CONSTRAINTS,
        "max_start_loss": [Interval(Real, 0, None, closed="neither")],
        "fallback_starts": [tuple, list, None],
        "passes": [Interval(Integral, 1, None, closed="left")],
        "random_state": ["random_state"],
    }

    def __init__(self, *, start: str | None = None, fov_deg: float | None = None,
                 rounds: int = 6, softness: float = 0.05, range_softness: float = 0.02,
                 miss_rate: float = 0.1, grid: int = 10, headings: int = 24,
                 pose_iters: int = 3, max_start_loss: float = 0.35,
                 fallback_starts: tuple[str, ...] | None = FALLBACK_STARTS, passes: int = 3,
                 random_state=0) -> None:
        store_params(self, locals())

    def _start_map(self, label, X, mask, ids, pos, timeline) -> np.ndarray:
        spec = METHODS.get(label) or {k.lower(): v for k, v in METHODS.items()}.get(
            label.strip().lower())
        if spec is not None and "masked" not in spec.histories:
            X, mask = np.where(mask, X, 0.0), None  # a complete-history method: 0 = not seen
        P, self.start_method_ = fit_start(label, X, ids, pos, sensor="visibility", mask=mask,
                                          timeline=timeline, random_state=self.random_state,
                                          category=ViewAdjustmentWarning)
        return P

    def fit(self, X, y=None, *, mask=None, sensor: str = "visibility", anchor_ids=None,
            anchor_positions=None, timeline=None, start_positions=None):
        """Map the masked visibility history ``X`` ((M, N) of 0/1, ``mask`` True where
        observed) with the anchors (rows of X) held at their positions. ``start_positions``
        ((M, 2), NaN rows: not placed) replaces the start map."""
        self._validate_params()
        if sensor != "visibility":
            raise ValueError(f"VIEW-BA maps visibility histories, got sensor {sensor!r}")
        X = check_views(self, X, mask)
        if mask is None or np.all(mask):
            raise ValueError("VIEW-BA needs the mask of a limited view (which objects each step "
                             "observed); this history observed every object at every step: map "
                             "it with CAL-SMA or VIS-BA-WALK")
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != X.shape:
            raise ValueError(f"mask must have the history's shape {X.shape}, got {mask.shape}")
        self.start_method_ = None if start_positions is None else "given"
        first = localisation_free("visibility", True)[0] if self.start is None else self.start
        fallbacks = self._check_starts(first)
        ids, pos, P0 = anchored_start(
            "VIEW-BA", anchor_ids, anchor_positions, X.shape[0], start_positions,
            lambda ids, pos: self._start_map(first, X, mask, ids, pos, timeline),
        )
        obs, seen = mask.T, (X.T > 0.5) & mask.T
        self.starts_tried_ = [self.start_method_]
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            self._passes(P0, ids, obs, seen)
        if start_positions is None and self.cone_rejected_ and fallbacks:
            caught = self._fallback(fallbacks, caught, X, mask, ids, pos, timeline, obs, seen)
        for w in caught:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        return self

    def _check_starts(self, first: str) -> tuple[str, ...]:
        """The fallback labels, checked (neither they nor the first start may be VIEW-BA), the
        first start's own label left out."""
        fallbacks = () if self.fallback_starts is None else tuple(self.fallback_starts)
        for name, label in (("start", first), *(("fallback_starts", f) for f in fallbacks)):
            if not isinstance(label, str):
                raise ValueError(f"{name} must hold method labels, got {label!r}")
            if label.strip().upper() == "VIEW-BA":
                raise ValueError(f"{name} must name another method than 'VIEW-BA'")
        return tuple(f for f in fallbacks if f.strip().upper() != first.strip().upper())

    def _fallback(self, labels, caught, X, mask, ids, pos, timeline, obs, seen):
        """After the first start's map was judged no view cone: the passes from each of
        ``labels``' start maps in turn until one is judged a cone; returns the warnings to
        issue (the first start's, and a note, when none is)."""
        first = {k: getattr(self, k) for k in _FIT_ATTRS}
        tried = []
        for label in labels:
            with warnings.catch_warnings(record=True) as again:
                warnings.simplefilter("always")
                try:
                    P0 = self._start_map(label, X, mask, ids, pos, timeline)
                except ValueError as exc:  # this start cannot map the history: the next one
                    tried.append(f"{label} failed ({exc})")
                    continue
                P0 = np.array(P0, dtype=float)
                P0[ids] = pos  # the anchors at their known positions, as anchored_start does
                self.starts_tried_.append(self.start_method_)
                self._passes(P0, ids, obs, seen)
                if not self.cone_rejected_:
                    warnings.warn(
                        f"from {first['start_method_']}'s start map the observed sets did not "
                        f"look like a view cone (loss {first['start_loss_']:.3g} per pair, "
                        f"above max_start_loss = {self.max_start_loss:g}); from "
                        f"{self.start_method_}'s they do ({self.start_loss_:.3g}): the map is "
                        "adjusted from it", ViewAdjustmentWarning, stacklevel=2)
                    return list(again)
            tried.append(f"{self.start_method_} {self.start_loss_:.3g} per pair")
        for k, v in first.items():
            setattr(self, k, v)
        with warnings.catch_warnings(record=True) as note:
            warnings.simplefilter("always")
            warnings.warn(f"no fallback start map looked like a view cone either: "
                          f"{'; '.join(tried)}", ViewAdjustmentWarning, stacklevel=2)
        return [*caught, *note]

    def _passes(self, P0, ids, obs, seen) -> None:
        """The adjustments from the start map ``P0`` (``passes`` in a row); sets ``start_`` and
        the fitted attributes of the last pass kept."""
        self.start_ = P0.copy()
        self._adjust(P0, ids, obs, seen)
        for _ in range(self.passes - 1):  # the view's width and viewpoints afresh on the map
            if not self.refined_:
                break
            before = {k: getattr(self, k) for k in _PASS_ATTRS}
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                self._adjust(self.embedding_.copy(), ids, obs, seen)
            if not self.refined_:  # no lower loss: the previous pass's map stands, silently
                for k, v in before.items():
                    setattr(self, k, v)
                break
            for w in caught:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)

    def _adjust(self, P0, ids, obs, seen) -> None:
        """One pass from the map ``P0``: the view's width (unless given), the viewpoints and the
        joint rounds; sets the fitted attributes."""
        placed = np.all(np.isfinite(P0), axis=1)
        _check_score_input(P0, obs, self.grid, self.headings, self.softness)
        # the candidate viewpoints, shared by the view's width and the viewpoints' search
        cells, cos_off, poses = self._candidates(P0[placed])
        if self.fov_deg is not None:
            self.fov_deg_ = float(self.fov_deg)
        else:  # estimate_fov's profile on the candidates already drawn
            widths = _profile(cos_off, obs[::16, placed], np.radians(_FOV_HALVES), 0.03)
            self.fov_deg_ = 2.0 * float(_FOV_HALVES[int(np.argmax(widths))])
        self.radius_ = float("nan")
        self.poses_ = np.full((obs.shape[0], 3), np.nan)
        self.cone_rejected_ = False
        free_objects(placed, ids, "VIEW-BA", 2, MAX_FREE_OBJECTS,
                     "DROPOUT-BLEND (build_map's default above 500 objects)")
        if self.fov_deg_ > MAX_FOV_DEG:
            warnings.warn(f"a {self.fov_deg_:.0f}-degree view says little about a heading "
                          f"(above {MAX_FOV_DEG:.0f}): the start map is kept",
                          ViewAdjustmentWarning, stacklevel=3)
            self.embedding_, self.refined_ = P0.copy(), False
            self.loss_ = self.start_loss_ = float("nan")
            return
        P, loss, start_loss, C, R, steps = self._refine(P0, ids, obs, seen, placed,
                                                         (cells, cos_off, poses))
        n_pairs = max(int(steps.sum()) * int(placed.sum()), 1)
        self.loss_, self.start_loss_ = loss / n_pairs, start_loss / n_pairs
        if not np.isfinite(R):  # _refine's verdict: not a view cone
            warnings.warn(f"the observed sets do not look like a view cone: from the best "
                          f"viewpoints the cone's loss is {self.start_loss_:.3g} per pair "
                          f"(above max_start_loss = {self.max_start_loss:g}); the start map is "
                          "kept", ViewAdjustmentWarning, stacklevel=3)
            self.embedding_, self.refined_, self.cone_rejected_ = P0.copy(), False, True
            return
        self.refined_, self.embedding_ = keep_if_better(
            P, P0.copy(), placed, self.loss_ if np.isfinite(loss) else np.inf,
            self.start_loss_, "observed sets and bits", ViewAdjustmentWarning)
        if self.refined_:
            self.radius_ = R
            self.poses_[steps] = C

    # -- the adjustment ------------------------------------------------------------------------
    def _candidates(self, P):
        """The grid's candidate viewpoints over the objects ``P`` (placed only): ``(cells,
        cos_off, poses)`` (:func:`_cos_off`)."""
        cells = search_cells(P, self.grid)
        return (cells, *_cos_off(P, cells, self.headings))

    def _problem(self, obs, seen, free_index, n_free) -> ConeProblem:
        return ConeProblem(obs, seen, free_index, n_free, math.radians(self.fov_deg_) / 2.0,
                           self.softness, self.range_softness, self.miss_rate)

    def _refine(self, P0, ids, obs, seen, placed, candidates):
        """``(P, loss, start_loss, poses, R, steps)`` from one start map; ``R`` is NaN when the
        start's loss per pair is above ``max_start_loss`` (not a view cone: no rounds).
        ``candidates``: the grid's ``(cells, cos_off, poses)`` over the placed objects."""
        m = len(P0)
        free = placed.copy()
        free[ids] = False
        steps = (obs & placed).any(axis=1)
        if not steps.all():
            warnings.warn(f"{int((~steps).sum())} step(s) observed no placed object: they are "
                          "left out", ViewAdjustmentWarning, stacklevel=4)
        use = np.flatnonzero(placed)
        free_index = np.full(len(use), -1, dtype=np.int64)
        n_free = int(free[use].sum())
        free_index[free[use]] = np.arange(n_free)
        prob = self._problem(obs[steps][:, use], seen[steps][:, use], free_index, n_free)
        P = np.ascontiguousarray(P0[use], dtype=float)
        R = 0.2 * float(np.ptp(P, axis=0).max())
        C = self._search(P, prob.obs, prob.seen, prob.half, R, *candidates)
        loss = prob.cost(P, C, R)
        for _ in range(self.pose_iters):  # each viewpoint alone (the objects held)
            C, loss = prob.pose_step(P, C, R, loss)
        R = prob.fit_radius(P, C, R)
        start_loss = loss = prob.cost(P, C, R)
        if start_loss / max(prob.obs.size, 1) > self.max_start_loss:  # not a view cone
            return P0.copy(), start_loss, start_loss, C, float("nan"), steps
        lam = 1e-2
        for r in range(self.rounds):
            P, C, loss, lam, moved = prob.lm_round(P, C, R, loss, lam)
            if not moved:
                break
            if r == self.rounds // 2:
                R = prob.fit_radius(P, C, R)
                loss = prob.cost(P, C, R)
        out = np.full((m, 2), np.nan)
        out[use] = P
        out[ids] = P0[ids]
        return out, loss, start_loss, C, R, steps

    def _search(self, P, o, s, half, R, cells, cos_off, poses):
        """Each step's best viewpoint among the candidates (positions x headings), the objects
        held."""
        log_in, log_out = _cone_log_terms(cos_off, half, 0.1)
        d = np.linalg.norm(P[None, :, :] - cells[:, None, :], axis=2)
        q = 1.0 / (1.0 + np.exp(-(R - d) / self.range_softness))
        p1 = (1.0 - self.miss_rate - view_kernels.FLOOR) * q + view_kernels.FLOOR
        l1 = np.repeat(np.log(p1), self.headings, axis=0)
        l0 = np.repeat(np.log1p(-p1), self.headings, axis=0)
        Ob, S = o.astype(float), s.astype(float)
        score = Ob @ (log_in - log_out + l0).T + S @ (l1 - l0).T + log_out.sum(axis=1)[None, :]
        return poses[score.argmax(axis=1)].copy()

    def fit_transform(self, X, y=None, *, mask=None, sensor: str = "visibility", anchor_ids=None,
                      anchor_positions=None, timeline=None, start_positions=None):
        """Fit and return the (M, 2) map in world coordinates (NaN rows: not placed)."""
        return self.fit(X, mask=mask, sensor=sensor, anchor_ids=anchor_ids,
                        anchor_positions=anchor_positions, timeline=timeline,
                        start_positions=start_positions).embedding_
