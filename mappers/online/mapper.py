"""Online mapping: the map of a robot still moving, updated as its histories grow.

The paper calls LFMDR "basically an off-line process" and leaves an online algorithm open (§6).
:class:`OnlineMapper` takes the new steps' columns after each batch of steps and returns the
current :class:`~mappers.pipeline.Map`, the same kind of map :func:`~mappers.pipeline.build_map`
returns for the whole history.

For CAL-SMA (:mod:`mappers.calibrated.cal_sma`, the default of complete visibility histories, and the
start of BEARING-BA, the default of bearing histories) on complete histories, the update is
incremental:

- Statistics: CAL-SMA needs only the dissimilarities of the L2-normalised rows (paper eq. 7),
  and both its cosine (visibility) and RMS Euclidean (bearing) dissimilarities are functions of
  the Gram matrix ``G = X X^T`` and the column count. ``G`` is accumulated as ``C C^T`` over the
  new columns ``C``: O(M^2 k) for k new columns, never a pass over the whole history, and no
  column is kept.
- Embedding: the last map is the start of a short CAL-SMA refinement (``warm_rounds``
  calibrate/re-embed rounds, anchors held fixed, Guttman updates stopped at the looser
  ``warm_tol``: the start is nearly converged); objects sensed for the first time start at the
  mean position of their three most similar mapped objects. CAL-SMA's fold check runs on every
  warm update while the map is young (before its second scheduled refit), then every
  ``fold_check_every`` warm updates, and whenever objects join the map; a warm map that looks
  folded is refitted from scratch once the steps have grown by 1.5 since the last full fit
  (until then it is kept, with a note in ``Map.warnings``); such a refit leaves the schedule of
  the scheduled ones where it was.
- Full refits: from scratch (CAL-SMA's two deterministic starts and all its rounds) whenever the
  number of steps has grown by the factor ``refit_growth`` since the last full fit, so a map
  whose early shape was poor is rebuilt a logarithmic number of times in all. They skip
  CAL-SMA's random restarts (tried only when both deterministic starts look folded, which
  happens in the first few dozen steps, at 3-4x the cost of a fit): such a map is refitted
  later, with more steps.
- Both run CAL-SMA's rounds in fewer array passes than
  :class:`~mappers.calibrated.cal_sma.CalibratedSMACOF` (one solve of the anchored Guttman system per
  neighbour graph, kept between warm updates whose graph did not change; the calibration summed
  term by term): the same maps to rounding, at about 3/4 of the cost. ``build_map`` and the
  offline estimator are untouched.

Cost per update, with M objects: O(M^2 k) for the statistics plus O(M^2 log M) for the
neighbours plus ``warm_rounds`` rounds of anchored weighted SMACOF (O(M^2) per Guttman update,
a few updates per round), independent of the number of steps so far. A full refit costs about
3/4 of what ``build_map`` costs (``2 x n_rounds`` rounds), more in the first hundred steps,
whose maps converge slowly; with ``refit_growth = g`` there are about ``log_g(N / N_0)`` of
them over a run of N steps, N_0 the steps of the first map, plus the few a fold check asks for.
``benchmarks/bench_online.py`` measures both against rebuilding the map (figures in the README
and in ``docs/online-and-exploration.md``).

BEARING-BA on complete bearing histories (the default) is updated incrementally from that
CAL-SMA map by :class:`mappers.online.bearing.OnlineBundle`: each new step's pose resected
against the current objects, a warm Levenberg-Marquardt round of the joint problem every
``bundle_every`` updates (or once the steps have grown by 5 %), and a full BEARING-BA fit, from
the CAL-SMA map, whenever CAL-SMA is refitted or objects join its map; a refit that is not kept
(BEARING-BA's guards) leaves the CAL-SMA map until the next one.

VIEW-BA on masked visibility histories (a limited view; the default) is refitted with
``build_map``'s own fit on a geometric schedule of its own (``refit_growth`` 1.25: its refits,
from a new start map, are what move the map to a better basin) and carried on in between by
:class:`mappers.online.view_cone.OnlineView`: each new step's viewpoint placed against the current
objects, a warm joint round every ``bundle_every`` updates, and, with a slower schedule
(``refit_growth`` above 1.25), VIEW-BA refined from the current map (no start map drawn)
whenever the steps have grown by a quarter; an object seen for the first time is refitted into
the map at once.

Other methods (and masked histories, whose methods need the steps' co-observation patterns)
keep the columns and refit with :func:`~mappers.pipeline.build_map` on the same geometric
schedule; between refits the last map is returned with a note in ``Map.warnings`` saying which
steps it covers. A first map that fails (too few steps: a limited view's co-observations fall
apart) is tried again once the steps have grown by a tenth, not at every update.

References: de Leeuw (1977) and Borg & Groenen, *Modern Multidimensional Scaling* (2005), on
warm-started SMACOF (majorisation decreases stress from any start).
"""

from __future__ import annotations

import dataclasses
import warnings
from numbers import Integral, Real
from typing import Any

import numpy as np

from mappers.calibrated import CalibratedSMACOF, fit_calibration, fold_score, log_floor
from mappers.calibrated.factory import dense_keywords
from mappers.catalog import resolve_method
from mappers.core.align import apply_affine, check_anchor_ids, check_anchors
from mappers.core.errors import MappingError
from mappers.core.graph import informative_pairs, knn_mask
from mappers.core.sensors import COLUMNS_PER_STEP, check_sensor, infer_sensor
from mappers.fitting import Map, _thread_limit
from mappers.online.bearing import OnlineBundle
from mappers.online.view_cone import OnlineView
from mappers.pipeline import _fit_map, build_map

__all__ = ["OnlineMapper", "gram_dissimilarity"]

_INCREMENTAL = "CAL-SMA"
_BUNDLE = "BEARING-BA"  # updated incrementally from the incremental CAL-SMA map (online_bearing)
_VIEW = "VIEW-BA"  # masked visibility, updated incrementally between its refits (online_view)
_REFIT_GROWTH = 4.0  # refit_growth's default
# ... for VIEW-BA: its refits, from a new start map, are what find a better basin; every 1.25x
# (about 7 in a run to N = 2,000) since DROPOUT-BLEND, their start, drops a failed member
# (2 before: docs/online-and-exploration.md)
_VIEW_REFIT_GROWTH = 1.25
# a warm map that looks folded is refitted from scratch once the steps have grown by this factor
# since the last full fit (at most refit_growth), not at every update while it still looks folded
_FOLD_REFIT_GROWTH = 1.5
# a refitted method that found nothing to map yet is tried again once the steps have grown by this
_RETRY_GROWTH = 1.1
# Guttman updates per round in a full CAL-SMA fit (CAL-SMA's own max_iter is 100): a map of a few
# dozen steps converges slowly and its fits hit the cap, which made the refits of the first 250
# steps half of a run's CPU; later fits converge before 30 (docs/online-and-exploration.md)
_FULL_FIT_MAX_ITER = 30


def gram_dissimilarity(gram: np.ndarray, n_columns: int, kind: str) -> np.ndarray:
    """CAL-SMA's dissimilarity of the L2-normalised history rows, from their Gram matrix.

    ``gram`` is ``X X^T`` of the raw rows (no empty row), ``n_columns`` the columns of ``X``.
    ``kind`` ``"cosine"`` gives ``1 - cos``; ``"euclidean"`` gives ``||y_i - y_j|| / sqrt(D)``
    of the unit rows ``y``: the values :func:`mappers.calibrated.cal_sma.history_dissimilarity` gives.
    """
    norms = np.sqrt(np.diag(gram))
    cos = np.clip(gram / np.outer(norms, norms), -1.0, 1.0)
    if kind == "cosine":
        delta = 1.0 - cos
    elif kind == "euclidean":
        delta = np.sqrt(np.maximum(2.0 - 2.0 * cos, 0.0) / n_columns)
    else:
        raise ValueError(f"kind must be 'cosine' or 'euclidean', got {kind!r}")
    delta = 0.5 * (delta + delta.T)
    np.fill_diagonal(delta, 0.0)
    return np.maximum(delta, 0.0)


class _AnchoredGuttman:
    """Anchored Guttman updates (:func:`mappers.smacof.weighted.weighted_smacof` with ``fixed``) for one
    weight matrix, its system solved once.

    CAL-SMA's weights depend only on the neighbour graph, so every calibrate/re-embed round of
    a fit, and every warm update whose graph did not change, solves the same system
    ``V_ff X_f = [B(X) X]_f - V_fa X_a``. Every pair has a positive weight (far pairs
    ``far_weight``, or 1e-6), so ``V_ff`` is positive definite: its inverse is the
    pseudo-inverse ``weighted_smacof`` computes in every call. :meth:`run` makes the same
    updates with the same stopping rule, in fewer array passes and without input checks; its
    results equal ``weighted_smacof``'s to rounding (not bit for bit).
    """

    def __init__(self, W: np.ndarray, fixed: np.ndarray) -> None:
        self.W = W
        self.free = np.ones(len(W), dtype=bool)
        self.free[fixed] = False
        V = np.diag(W.sum(axis=1)) - W
        self.V_ff_inv = np.linalg.inv(V[np.ix_(self.free, self.free)])
        self.V_fa = V[np.ix_(self.free, ~self.free)]

    @staticmethod
    def _squared_distances(X: np.ndarray) -> np.ndarray:
        sq = np.einsum("ij,ij->i", X, X)
        D2 = np.add.outer(sq, sq)
        D2 -= 2.0 * (X @ X.T)
        return np.maximum(D2, 0.0, out=D2)

    def run(self, delta: np.ndarray, X: np.ndarray, max_iter: int, tol: float):
        """(X, raw stress, updates) from start ``X`` (its fixed rows kept), as weighted_smacof."""
        W, free, V_ff_inv = self.W, self.free, self.V_ff_inv
        X = np.array(X, dtype=float)
        rhs_fixed = self.V_fa @ X[~free]
        wd = W * delta
        base = float(np.vdot(W, delta * delta))
        D2 = self._squared_distances(X)
        D = np.sqrt(D2)
        # raw stress 1/2 sum w (delta - d)^2, expanded: two dot products, no (M, M) temporaries
        stress = 0.5 * (base - 2.0 * float(np.vdot(wd, D)) + float(np.vdot(W, D2)))
        n_iter = 0
        for n_iter in range(1, max_iter + 1):  # noqa: B007 - n_iter is returned
            D[D <= 0] = np.inf  # B(X)_ij = 0 where d_ij = 0 (the diagonal, coinciding points)
            R = wd / D  # B(X) = diag(R 1) - R
            BX = R.sum(axis=1)[:, None] * X - R @ X
            X_new = X.copy()
            X_new[free] = V_ff_inv @ (BX[free] - rhs_fixed)
            D2 = self._squared_distances(X_new)
            D = np.sqrt(D2)
            X, old = X_new, stress
            stress = 0.5 * (base - 2.0 * float(np.vdot(wd, D)) + float(np.vdot(W, D2)))
            if old <= 0 or (old - stress) <= tol * old:
                break
        return X, stress, n_iter


def _midpoint_terms(x: np.ndarray, y: np.ndarray, degree: int):
    """The terms of :func:`mappers.calibrated.cal_sma._features`, in its order, one array at a time."""
    if degree >= 1:
        yield x
        yield y
    if degree >= 2:
        yield x * x
        yield y * y
        yield x * y
    if degree >= 3:
        yield x**3
        yield y**3
        yield x * x * y
        yield x * y * y


class _OnlineCalSMA(CalibratedSMACOF):
    """CalibratedSMACOF with the same rounds in fewer array passes (its maps to rounding).

    Used by :class:`OnlineMapper` for its full fits and warm updates: the Guttman system is
    solved once per neighbour graph (:class:`_AnchoredGuttman`, the last one kept in
    ``solver_``, so warm updates whose graph did not change reuse it), and the calibration sums
    its terms instead of building an (M, M, features) array. The offline estimator is untouched.
    It overrides only :meth:`_embed` and :meth:`_calibrate`: the rounds are
    :meth:`CalibratedSMACOF._refine`'s.
    """

    solver_: tuple | None = None

    def _solver(self, loc: np.ndarray, fixed: np.ndarray) -> _AnchoredGuttman:
        key = (loc.tobytes(), np.asarray(fixed).tobytes(), float(self.far_weight))
        if self.solver_ is None or self.solver_[0] != key:
            self.solver_ = (key, _AnchoredGuttman(self._weights(loc), np.asarray(fixed)))
        return self.solver_[1]

    def _calibrate(self, D, X, pairs, lo_delta):
        # CalibratedSMACOF._calibrate without the (M, M, features) array: the calibrated log
        # distance summed term by term
        i, j = np.nonzero(np.triu(pairs, 1))
        L = np.log(np.maximum(D, lo_delta))
        fit = fit_calibration(L[i, j], X, i, j, self.dissimilarity_degree, self.position_degree)
        coef, target = fit.coef, fit.target
        dd = self.dissimilarity_degree
        expo = np.full(L.shape, coef[dd])
        Lp = L
        for p in range(dd):
            expo += coef[p] * Lp
            if p + 1 < dd:
                Lp = Lp * L
        u = (X - fit.centre) / fit.half  # the pair's midpoint features from the objects' own
        x = 0.5 * (u[:, 0, None] + u[:, 0])
        y = 0.5 * (u[:, 1, None] + u[:, 1])
        for c, f in zip(coef[dd + 1:], _midpoint_terms(x, y, self.position_degree), strict=True):
            expo += c * f
        np.clip(expo, target.min() - 1.0, target.max() + 1.0, out=expo)
        Dh = np.exp(expo)
        Dh = 0.5 * (Dh + Dh.T)
        np.fill_diagonal(Dh, 0.0)
        return Dh, coef

    def _embed(self, T, X, loc, fixed):
        # the estimator's rounds (CalibratedSMACOF._refine), each re-embedding by the cached
        # solver of this neighbour graph instead of weighted_smacof
        if fixed is None:  # no anchors (never in OnlineMapper): the estimator's own embedding
            return super()._embed(T, X, loc, fixed)
        X, _, it = self._solver(loc, fixed).run(T, X, self.max_iter, self.tol)
        return X, it


class OnlineMapper:
    """The map of M objects, updated as batches of steps arrive (see the module docstring).

    Args:
        anchor_ids: (A,) ids of the anchor objects, A >= 3 (checked against M at the first
            update).
        anchor_positions: (A, 2) their known positions [m]; not collinear.
        sensor: ``"visibility"``, ``"bearing"`` or ``"range"``; None = inferred from the first
            update that senses anything (pass it when you know it).
        method: a label of :data:`mappers.METHODS`; None = ``build_map``'s default for the
            sensor and the kind of history. CAL-SMA on complete visibility and bearing
            histories, BEARING-BA (started from CAL-SMA) on complete bearing ones, and VIEW-BA
            on masked visibility ones (between its refits) are updated incrementally; other
            methods are refitted on the schedule.
        refit_growth: a full refit whenever the steps have grown by this factor (> 1) since the
            last scheduled one; None: 4, or 1.25 for VIEW-BA (masked visibility).
        warm_rounds: CAL-SMA rounds of the warm-started update between full refits.
        warm_tol: relative stress decrease at which a warm round's Guttman updates stop, in
            [0, 1) (CAL-SMA's own ``tol`` is 1e-6; from a nearly converged start 1e-4 halves
            the updates and leaves the maps as accurate).
        fold_check_every: CAL-SMA's fold check on every this many warm updates (integer >= 1;
            1 = every update) once the map is past its second scheduled refit (``refit_growth``
            squared times the steps of the first map); before that, and whenever objects join
            the map, on every warm update.
        bundle_every: BEARING-BA (complete bearing) and VIEW-BA (masked visibility): a warm
            joint round of the bundle adjustment every this many updates (integer >= 1), sooner
            once the steps have grown by 5 % since the last.
        bundle_rounds: Levenberg-Marquardt rounds per warm joint round (integer >= 1).
        random_state: seed handed to the method, as ``build_map``'s.
        **params: the method's parameters, as for ``build_map``.

    Attributes:
        n_steps: steps received so far; n_full_fits: full refits so far (the scheduled ones and
        those a fold check asked for); n_fold_refits: those a fold check asked for; map: the
        last map (None before the first update).

    Cost per update (``benchmarks/bench_online.py``: M = 50 objects, updates of 10 steps,
    N = 2,000, CPU time, one BLAS thread; 25 fresh layouts per sensor): visibility (CAL-SMA),
    median about 1.9 ms, 65x cheaper than rebuilding the map at N = 2,000 with ``build_map``;
    the mean, the full refits included (5-6 per run: the amortised cost), 27x. Bearing
    (BEARING-BA): the CAL-SMA update, plus the new steps' resection (O(k M)), plus every
    ``bundle_every`` updates a joint round over all steps (O(N M) for the normal blocks and
    O(N F^2 + F^3) for the Schur system, F the free objects: about 70 ms at N = 2,000, a seventh
    of a rebuild), plus a full BEARING-BA fit at each CAL-SMA refit: median about 4-5 ms,
    110-125x cheaper than rebuilding the BEARING-BA map (about 0.5-0.6 s), mean 34x; its map is
    within 1 % of the offline BEARING-BA map's MPE on average (2 degrees of bearing noise), and
    as exact (~5e-10 m) on perfect bearings. Masked visibility through a 90-degree view
    (VIEW-BA, ``--env fov_deg=90``): median 8 ms, mean 45 ms, 25x cheaper than a rebuild
    (1.15 s, a loaded machine), the refits (about 7 per run, 0.5-1.1 s each) most of it. See
    ``docs/online-and-exploration.md`` for what each change bought.
    """

    def __init__(self, anchor_ids, anchor_positions, *, sensor: str | None = None,
                 method: str | None = None, refit_growth: float | None = None,
                 warm_rounds: int = 1,
                 warm_tol: float = 1e-4, fold_check_every: int = 5, bundle_every: int = 5,
                 bundle_rounds: int = 1, random_state: int | None = 0, **params: Any) -> None:
        pos = np.asarray(anchor_positions, dtype=float)
        ids = check_anchor_ids(anchor_ids, np.iinfo(np.int64).max)
        check_anchors(ids, pos, int(ids.max()) + 1)  # shapes, finiteness, collinearity
        if refit_growth is not None and (isinstance(refit_growth, bool)
                                         or not isinstance(refit_growth, Real)
                                         or not refit_growth > 1):
            raise ValueError(f"refit_growth must be a number > 1 or None, got {refit_growth!r}")
        if isinstance(warm_rounds, bool) or not isinstance(warm_rounds, Integral) or warm_rounds < 1:
            raise ValueError(f"warm_rounds must be an integer >= 1, got {warm_rounds!r}")
        if isinstance(warm_tol, bool) or not isinstance(warm_tol, Real) or not 0 <= warm_tol < 1:
            raise ValueError(f"warm_tol must be a number in [0, 1), got {warm_tol!r}")
        if (isinstance(fold_check_every, bool) or not isinstance(fold_check_every, Integral)
                or fold_check_every < 1):
            raise ValueError(f"fold_check_every must be an integer >= 1, got {fold_check_every!r}")
        for name, value in (("bundle_every", bundle_every), ("bundle_rounds", bundle_rounds)):
            if isinstance(value, bool) or not isinstance(value, Integral) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        self.anchor_ids, self.anchor_positions = ids, pos
        self.sensor = check_sensor(sensor, allow_none=True)
        self.method, self.params = method, dict(params)
        self._refit_growth = refit_growth  # None: the method's (set when it is resolved)
        self.refit_growth = _REFIT_GROWTH if refit_growth is None else float(refit_growth)
        self.warm_rounds = int(warm_rounds)
        self.warm_tol, self.fold_check_every = float(warm_tol), int(fold_check_every)
        self.bundle_every, self.bundle_rounds = int(bundle_every), int(bundle_rounds)
        self.random_state = random_state
        self.n_steps, self.n_full_fits, self.map = 0, 0, None
        self._m: int | None = None
        self._masked: bool | None = None
        self._spec = None
        self._gram: np.ndarray | None = None
        self._n_columns = 0
        self._blocks: list[tuple[np.ndarray, np.ndarray | None]] = []
        self._last_full = 0  # steps at the last full fit
        self._last_scheduled = 0  # ... at the last one of the schedule (not a fold check's)
        self._first_map: int | None = None  # steps of the first map
        self._fit_notes: tuple[str, ...] = ()
        self._Y: np.ndarray | None = None  # last embedding (M, 2), NaN rows for unmapped
        self._retry_at = 0  # steps at which a first map that failed is tried again
        self._warm_est: _OnlineCalSMA | None = None  # keeps the last Guttman pseudo-inverse
        self._since_check, self._m_checked = 0, 0  # warm updates since the last fold check
        self.n_fold_refits = 0
        self._bundle: OnlineBundle | None = None  # BEARING-BA's state (complete bearing)
        self._view: OnlineView | None = None  # VIEW-BA's state (masked visibility)
        self._cal: dict = {}  # CAL-SMA's parameters (the method's, or BEARING-BA's start's)

    # ------------------------------------------------------------------ inputs
    def _check_batch(self, columns, mask):
        try:
            C = np.array(columns, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"columns must be a numeric (M, k) array: {exc}") from exc
        if C.ndim != 2 or C.shape[1] < 1:
            raise ValueError(f"columns must be a 2-D (objects x new columns) array with at least "
                             f"one column, got shape {C.shape}")
        if self._m is None:
            if C.shape[0] < 3:
                raise ValueError(f"columns need at least 3 objects (rows), got {C.shape[0]}")
            check_anchor_ids(self.anchor_ids, C.shape[0])
        elif C.shape[0] != self._m:
            raise ValueError(f"columns must have {self._m} rows (one per object, as in the first "
                             f"update), got {C.shape[0]}")
        if mask is not None:
            mask = np.asarray(mask)
            if mask.dtype != bool or mask.shape != C.shape:
                raise ValueError(f"mask must be a boolean array of the columns' shape {C.shape}, "
                                 f"got {mask.dtype} {mask.shape}")
        if not np.all(np.isfinite(C if mask is None else C[mask])):
            raise ValueError("columns contain NaN or inf (in observed entries)")
        if mask is not None:
            C = np.where(mask, C, 0.0)
        if self.sensor is not None and C.shape[1] % COLUMNS_PER_STEP[self.sensor]:
            raise ValueError(f"{self.sensor} columns come in groups of "
                             f"{COLUMNS_PER_STEP[self.sensor]} per step, got {C.shape[1]} columns")
        return C, mask

    def _kind(self, mask) -> bool:
        """Fix the kind of history at the first update; later masks must agree."""
        masked = mask is not None and not mask.all()
        if self._masked is None:
            self._masked = mask is not None
        elif masked and not self._masked:
            raise ValueError("mask given after a first update without one: the kind of history "
                             "(complete or masked) is fixed by the first update; pass a mask "
                             "(all True where complete) from the first update on")
        return self._masked

    def _resolve(self) -> None:
        """Choose the method once the sensor is known; replay the batches held until then."""
        spec = resolve_method(self.method, self.sensor, masked=self._masked)
        self._merged = spec.resolved_params(self.params)
        if "random_state" in spec.parameters and "random_state" not in self.params:
            self._merged["random_state"] = self.random_state
        self._spec = spec
        self._cal = self._merged
        start = self._merged.get("start")
        if (spec.label == _BUNDLE and self.sensor == "bearing" and not self._masked
                and (start is None or start.strip().upper() == _INCREMENTAL)):
            cal = resolve_method(_INCREMENTAL, self.sensor)
            self._cal = cal.resolved_params({})
            if "random_state" in cal.parameters:
                self._cal["random_state"] = self._merged.get("random_state", self.random_state)
            self._bundle = OnlineBundle(self._merged, self.anchor_ids, self.anchor_positions,
                                        every=self.bundle_every, rounds=self.bundle_rounds)
        if spec.label == _VIEW and self._masked:
            self._view = OnlineView(every=self.bundle_every, rounds=self.bundle_rounds)
            if self._refit_growth is None:
                self.refit_growth = _VIEW_REFIT_GROWTH
        blocks, self._blocks = self._blocks, []
        self.n_steps = 0
        for C, mask in blocks:
            if C.shape[1] % COLUMNS_PER_STEP[self.sensor]:
                raise ValueError(f"{self.sensor} columns come in groups of "
                                 f"{COLUMNS_PER_STEP[self.sensor]} per step, got {C.shape[1]}")
            self._add(C, mask)

    @property
    def incremental(self) -> bool:
        """Whether updates are incremental (CAL-SMA on complete histories, BEARING-BA from it on
        complete bearing ones, VIEW-BA between its refits on masked visibility ones) rather
        than refits."""
        return self._gram_path or self._view is not None

    @property
    def _gram_path(self) -> bool:
        """CAL-SMA's statistics kept as a Gram matrix (complete histories)."""
        return self._spec is not None and not self._masked and (
            (self._spec.label == _INCREMENTAL and not self._spec.is_scalable(self._merged))
            or self._bundle is not None)

    def _add(self, C, mask) -> None:
        if self._view is not None:  # new viewpoints placed against the current objects
            self._view.add(C, np.ones(C.shape, dtype=bool) if mask is None else mask)
        if self._gram_path:
            if self._bundle is not None:  # checked before anything is kept
                theta, seen = self._bundle.angles(C)
                self._bundle.add(C, theta, seen)
            G = C @ C.T
            self._gram = G if self._gram is None else self._gram + G
            self._n_columns += C.shape[1]
        else:
            self._blocks.append((C, mask))
        self.n_steps += C.shape[1] // COLUMNS_PER_STEP[self.sensor]

    # ------------------------------------------------------------------ API
    def update(self, columns, mask=None) -> Map:
        """Add the new steps' columns (M, k) (and their (M, k) bool mask, True = observed) and
        return the current map.

        ``k`` is a whole number of steps (``COLUMNS_PER_STEP[sensor]`` columns each), in step
        order, as in a history's matrix. Until three anchors and three objects have been sensed
        (or the method finds nothing to map yet) the map has every object unmapped, with a note
        in ``warnings``.
        """
        C, mask = self._check_batch(columns, mask)
        self._kind(mask)
        self._m = C.shape[0]
        if self._spec is None:
            if self.sensor is None and np.any(C != 0):
                self.sensor = infer_sensor(C, mask)
            if self.sensor is None:  # nothing sensed yet: hold the batch until the sensor is known
                self._blocks.append((C, mask))
                self.map = self._empty("nothing sensed yet")
                return self.map
            self._blocks.append((C, mask))
            self._resolve()
        else:
            self._add(C, mask)
        full = (self.n_steps >= self._retry_at if self._Y is None
                else self.n_steps >= self.refit_growth * self._last_scheduled)
        fits = self.n_full_fits
        self.map = self._update_incremental(full) if self._gram_path else self._update_refit(full)
        if self._bundle is not None:
            self.map = self._update_bundle(self.map, self.n_full_fits > fits)
        return self.map

    def _empty(self, why: str) -> Map:
        m = self._m
        label = self._spec.label if self._spec is not None else str(self.method)
        return Map(positions=np.full((m, 2), np.nan), unmapped=tuple(range(m)),
                   embedding=np.full((m, 2), np.nan), method=label,
                   params=dict(getattr(self, "_merged", self.params)),
                   sensor=self.sensor or "unknown",
                   warnings=(f"online map after {self.n_steps} steps: {why}",))

    # ------------------------------------------------------------------ updates
    def _usable(self, has_data: np.ndarray):
        """Mapped rows and the anchors among them, or the reason there is no map yet."""
        mapped = np.flatnonzero(has_data)
        ok = has_data[self.anchor_ids]
        if ok.sum() < 3 or mapped.size < 3:
            return None, f"{int(ok.sum())} anchors and {mapped.size} objects sensed so far"
        return mapped, None

    def _estimator(self, k: int, *, warm: bool) -> _OnlineCalSMA:
        """CAL-SMA with the method's parameters: a full fit (no random restarts: a map that
        still looks folded is refitted later, with more steps; at most ``_FULL_FIT_MAX_ITER``
        Guttman updates per round), or ``warm_rounds`` rounds whose Guttman updates stop at
        ``warm_tol``."""
        kw = dense_keywords(self._cal)
        kw.pop("n_neighbors", None)
        if warm:
            kw.update(n_rounds=self.warm_rounds, tol=self.warm_tol)
        else:
            kw["max_iter"] = _FULL_FIT_MAX_ITER  # (not one of CAL-SMA's registry parameters)
        return _OnlineCalSMA(dissimilarity="precomputed", n_neighbors=k, n_init=0, **kw)

    def _start(self, mapped: np.ndarray, D: np.ndarray) -> np.ndarray:
        """The last map for objects it had; a new object at the mean of its three most similar
        mapped objects (a small offset keeps two newcomers apart)."""
        S = self._Y[mapped].copy()
        old = np.isfinite(S[:, 0])
        for r in np.flatnonzero(~old):
            near = np.flatnonzero(old)[np.argsort(D[r, old], kind="stable")[:3]]
            S[r] = S[near].mean(axis=0) + 1e-3 * (r + 1) * np.array([1.0, -1.0])
        return S

    def _update_incremental(self, full: bool) -> Map:
        G = self._gram
        mapped, why = self._usable(np.diag(G) > 0)
        if mapped is None:
            return self._empty(why)
        m = mapped.size
        kind = "cosine" if self.sensor == "visibility" and self._n_columns >= 2 else "euclidean"
        D = gram_dissimilarity(G[np.ix_(mapped, mapped)], self._n_columns, kind)
        valid = informative_pairs(D)
        if not valid.any():  # CAL-SMA's own condition: nothing to calibrate
            return self._empty("no two objects sensed together yet")
        if not full and np.isnan(self._Y[mapped]).all():
            full = True
        scheduled = full
        is_anchor = np.isin(self.anchor_ids, mapped)
        local = np.searchsorted(mapped, self.anchor_ids[is_anchor])
        pos = self.anchor_positions[is_anchor]
        k = self._cal.get("n_neighbors")
        k = (12 if kind == "cosine" else 10) if k is None else k
        notes = []
        with _thread_limit(m):
            if not full:
                Y, score = self._warm(D, valid, mapped, local, pos, kind, min(k, m - 1))
                if score is not None:  # the warm map looks folded
                    next_fit = min(_FOLD_REFIT_GROWTH, self.refit_growth) * self._last_full
                    if self.n_steps >= next_fit:  # refit from CAL-SMA's deterministic starts
                        full, self.n_fold_refits = True, self.n_fold_refits + 1
                    else:
                        notes.append(f"online map looks folded (fold score {score:.3f}); refit "
                                     f"from scratch at {int(np.ceil(next_fit))} steps")
            if full:
                est = self._estimator(min(k, m - 1), warm=False)
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    Y = est.fit_transform(D, anchor_ids=local, anchor_positions=pos)
                notes = list(dict.fromkeys(f"{_INCREMENTAL}: {w.category.__name__}: {w.message}"
                                           for w in caught))
                self._last_full, self.n_full_fits = self.n_steps, self.n_full_fits + 1
                if scheduled:  # a fold check's refit leaves the schedule where it was
                    self._last_scheduled = self.n_steps
                    if self._first_map is None:
                        self._first_map = self.n_steps
                self._since_check, self._m_checked = 0, m
        if k > m - 1:
            notes.append(f"n_neighbors {k} > {m - 1} objects mapped so far: used {m - 1}")
        self._Y = np.full((self._m, 2), np.nan)
        self._Y[mapped] = Y
        return self._map(Y, mapped, local, pos, {**self._cal, "n_neighbors": k}, notes)

    def _update_bundle(self, start: Map, refitted: bool) -> Map:
        """BEARING-BA from the CAL-SMA map ``start``: a full fit when CAL-SMA was refitted (or
        objects joined its map), else the new steps' poses (resected in :meth:`_add`) and, when
        due, a warm joint round; the CAL-SMA map, with the refit's warning, where the refinement
        was not kept."""
        bundle = self._bundle
        placed = np.isfinite(start.positions[:, 0])
        if not placed.any():
            return start
        cal_notes = [f"start map ({_INCREMENTAL}): {w}" for w in start.warnings]
        joined = bundle.start_placed is None or np.any(placed & ~bundle.start_placed)
        with _thread_limit(self._m):
            if refitted or joined:
                bundle.refit(start.positions)
            elif bundle.due():
                bundle.joint_round()
        if bundle.state is None:  # the refinement was not kept: the CAL-SMA map
            return dataclasses.replace(start, method=self._spec.label, params=dict(self._merged),
                                       warnings=(*cal_notes, *bundle.notes))
        return self._adjusted_map(bundle.positions(), np.flatnonzero(placed),
                                  [*cal_notes, *bundle.notes])

    def _adjusted_map(self, positions: np.ndarray, mapped: np.ndarray, notes: list) -> Map:
        """The Map of a viewpoint adjustment's objects ``positions`` (M, 2) on the rows
        ``mapped`` (the anchors held at their positions)."""
        is_anchor = np.isin(self.anchor_ids, mapped)
        local = np.searchsorted(mapped, self.anchor_ids[is_anchor])
        return self._map(positions[mapped], mapped, local, self.anchor_positions[is_anchor],
                         dict(self._merged), notes)

    def _warm(self, D, valid, mapped, local, pos, kind, k) -> tuple[np.ndarray, float | None]:
        """``warm_rounds`` CAL-SMA rounds from the last map, and its fold score if CAL-SMA's
        fold check (run on every warm update of a young map, then every ``fold_check_every``,
        and whenever objects joined the map) finds it folded, else None."""
        if self._warm_est is None:
            self._warm_est = self._estimator(k, warm=True)
        est, m = self._warm_est, len(D)
        loc = knn_mask(D, valid, k)
        S = self._start(mapped, D)
        S[local] = pos
        Y, _, _, _, Dh = est._refine(D, S, loc, local)
        self._since_check += 1
        # a young map (before the second scheduled refit) is checked at every update: early maps
        # are the ones that fold
        young = self.n_steps < self.refit_growth**2 * self._first_map
        if self._since_check < self.fold_check_every and m == self._m_checked and not young:
            return Y, None
        self._since_check, self._m_checked = 0, m
        # as CAL-SMA's fit: never through a smaller neighbourhood than the default one
        k_check = min(max(k, 12 if kind == "cosine" else 10), m - 1)
        if k_check != k:
            loc_check = knn_mask(D, valid, k_check)
            Dh, _ = est._calibrate(D, Y, loc_check, log_floor(D[loc_check]))
        score = fold_score(Y, D, k_check, Dh)
        return Y, (score if score > est.fold_threshold else None)

    def _map(self, Y, mapped, local, pos, params, notes) -> Map:
        # CAL-SMA held the anchors fixed: the least-squares affine fit (the identity, to
        # rounding) needs no collinearity check, the anchors' known positions passed one
        T = np.linalg.lstsq(np.column_stack([Y[local], np.ones(len(local))]), pos, rcond=None)[0]
        positions = np.full((self._m, 2), np.nan)
        embedding = np.full((self._m, 2), np.nan)
        embedding[mapped] = Y
        positions[mapped] = apply_affine(Y, T)
        is_mapped = np.zeros(self._m, dtype=bool)
        is_mapped[mapped] = True
        unmapped = tuple(int(i) for i in np.flatnonzero(~is_mapped))
        lost = self.anchor_ids[~is_mapped[self.anchor_ids]]
        if lost.size:
            notes.append(f"anchors {lost.tolist()} have empty histories and were not used for the fit")
        return Map(positions=positions, unmapped=unmapped, embedding=embedding,
                   method=self._spec.label, params=params, sensor=self.sensor,
                   warnings=tuple(notes), affine=T,
                   anchor_ids=tuple(int(i) for i in self.anchor_ids[np.isin(self.anchor_ids, mapped)]))

    def _update_refit(self, full: bool) -> Map:
        scheduled, view = full, self._view
        if not full and view is not None and view.state is not None:
            if not view.joined():  # VIEW-BA's state carried on: the new steps are placed
                return self._update_view()
            full = True  # an object seen for the first time has no place: refit
        if not full and self._Y is None:  # the first map failed: tried again at _retry_at
            return self.map
        if not full:
            stale = f"online map of the first {self._last_full} of {self.n_steps} steps " \
                    f"(next refit at {int(np.ceil(self.refit_growth * self._last_scheduled))})"
            return dataclasses.replace(self.map, warnings=(*self._fit_notes, stale))
        X, mask = self._history()
        seen = np.any((X != 0) if mask is None else (mask & (X != 0)), axis=1)
        mapped, why = self._usable(seen)
        k = self._merged.get("n_neighbors")
        if mapped is None or (isinstance(k, Integral) and k >= mapped.size):
            return self._empty(why or f"n_neighbors {k} needs more than {mapped.size} objects")
        try:
            if view is None:
                result = build_map(X, self.anchor_ids, self.anchor_positions, self._spec.label,
                                   sensor=self.sensor, mask=mask, **self._merged)
            else:  # build_map's own fit, whose estimator holds VIEW-BA's state
                params = dict(self._merged)
                seed = params.pop("random_state", self.random_state)
                with _thread_limit(self._m):
                    result, est, rows = _fit_map(X, self.anchor_ids, self.anchor_positions,
                                                 self._spec.label, self.sensor, mask, None, None,
                                                 seed, params)
                    view.start(est, X, np.ones(X.shape, bool) if mask is None else mask, rows,
                               np.asarray(result.anchor_ids))
        except MappingError as exc:
            if view is not None:  # no refit, no state: the last map until the next refit
                view.state = None
            if self.map is None or not np.isfinite(self.map.positions).any():
                # tried again once the steps have grown a little (a try may cost as much as a fit)
                self._retry_at = int(np.ceil(_RETRY_GROWTH * self.n_steps))
                return self._empty(f"the method found nothing to map yet ({exc}); tried again "
                                   f"at {self._retry_at} steps")
            return dataclasses.replace(self.map, warnings=(
                *self.map.warnings, f"refit at {self.n_steps} steps failed, map kept: {exc}"))
        self._last_full = self.n_steps
        if scheduled:  # a refit for objects that joined leaves the schedule where it was
            self._last_scheduled = self.n_steps
        self.n_full_fits += 1
        self._Y = result.embedding
        self._fit_notes = result.warnings
        return result

    def _history(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The whole history kept so far, ``(X, mask)`` (mask None: complete), as one block (the
        next refit concatenates less)."""
        X = np.concatenate([C for C, _ in self._blocks], axis=1)
        if len(self._blocks) > 1:
            mask = None
            if self._masked:  # a batch given without a mask observed everything
                mask = np.concatenate([np.ones(C.shape, bool) if mk is None else mk
                                       for C, mk in self._blocks], axis=1)
            self._blocks = [(X, mask)]
        return self._blocks[0]

    def _update_view(self) -> Map:
        """VIEW-BA's map carried on from its last refit: a warm joint round when due."""
        view = self._view
        note = None
        if view.refine_due():
            X, mask = self._history()
            with _thread_limit(self._m):
                self._fit_notes = view.refine(X, mask, self.anchor_ids, self.anchor_positions)
        elif view.due():
            with _thread_limit(self._m):
                note = view.joint_round()
        if note is not None:
            self._fit_notes = (*self._fit_notes, note)
        if view.state is None:
            return self._update_refit(False)
        P = view.positions(self._m)
        return self._adjusted_map(P, np.flatnonzero(np.isfinite(P[:, 0])), list(self._fit_notes))
