"""Calibrated anchored SMACOF (CAL-SMA): a mapper designed for observation histories.

The idea in a few sentences. A history dissimilarity ``delta_ij`` grows with the true distance
``d_ij`` of two objects, but not linearly and not in the same way everywhere in the arena (near
walls an object is seen from fewer places). So instead of embedding ``delta`` as if it were a
distance, CAL-SMA alternates two steps: (1) fit, on neighbour pairs only, a smooth calibration
``log d = a_1 log delta + a_2 (log delta)^2 + c . phi(midpoint)`` from the current map, with
``phi`` a quadratic in position; (2) re-embed the calibrated distances by weighted SMACOF with the
anchors held at their known positions (a constrained Guttman update), so the map is in metres
with no affine fit afterwards. Pairs that are not neighbours in the histories only get a weak
lower bound ("farther apart than the neighbourhood radius"), which is what stops a map from
folding onto itself.

Reasons for each choice:

- ``1 - cos`` of the visibility rows rather than the paper's ``sqrt(2 - 2 cos)``: it grows
  about linearly with distance at short range, while the square root bends it.
  Bearing and range rows use the RMS Euclidean distance between rows.
- Only neighbour pairs (symmetric kNN in ``delta``, never-co-sensed pairs excluded) carry
  distance targets: far pairs' ``delta`` saturates (visibility: 1 for every pair never seen
  together) and says only "far".
- The calibration is log-linear with few parameters (2 for ``delta``, 6 for position), fitted
  by least squares over ~10 M pairs, so it cannot absorb a fold or the map's noise, only the
  smooth, position-dependent bias of the sensor.
- Anchors held fixed inside the stress fix scale, rotation and reflection of the whole map and
  let the calibration be in metres (with anchors only aligned afterwards the calibration has no
  scale to hold on to).
- Defaults (K = 12 / 10, 20 rounds, quadratic position term, far weight 0.02) were tuned on
  seeds of our own, never on the protocol's or on the fresh evaluation seeds.
- Folds: two deterministic starts (unweighted SMACOF, which is globally rigid and does not
  fold, and an Isomap-like geodesic CMDS), both affinely placed on the anchors and refined by
  the same loop; the result is chosen by a data-only criterion, :func:`fold_score`, then by
  stress. The score counts intrusions (pairs far apart in the histories but close in the map:
  overlap, collapse) and strained objects (neighbour distances off their calibrated targets by
  more than 20 %: the crease of a fold that does not overlap): about 0 on an unfolded map and
  well above the threshold on planted folds (``tests/mappers/calibrated/test_cal_sma.py``). It always looks through at least the default
  neighbourhood, so a small ``n_neighbors`` cannot hide a floppy map. If every start looks
  folded, random anchored starts are tried; if the kept map still looks folded, a
  :class:`FoldWarning` is raised (``build_map`` lists it in ``Map.warnings``) and
  ``fold_score_`` / ``folded_`` say so.

References: Yairi (2007) for the history rows and SMA, which this extends; de Leeuw (1977) and
Borg & Groenen, *Modern Multidimensional Scaling* (2005), for weighted SMACOF and its
majorisation with fixed points; Tenenbaum et al. (2000) for the geodesic start. Its accuracy
against the paper's methods is measured by ``benchmarks/bench_calibrated.py`` (figures in the
README, "CAL-SMA").
"""

from __future__ import annotations

import warnings
from numbers import Integral, Real
from typing import NamedTuple

import numpy as np
from scipy.sparse.csgraph import shortest_path
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import validate_data

from mappers.core.align import apply_affine, check_anchors, fit_affine
from mappers.core.estimator_params import store_params
from mappers.core.graph import informative_pairs, knn_mask
from mappers.core.iteration_params import ITERATION_CONSTRAINTS
from mappers.smacof import classical_mds, euclidean_distance_matrix, weighted_smacof

__all__ = [
    "CalibratedSMACOF",
    "CalibrationFit",
    "FoldWarning",
    "fit_calibration",
    "fold_score",
    "history_dissimilarity",
    "log_floor",
]


class CalibrationFit(NamedTuple):
    """CAL-SMA's calibration: ``coef`` of the least-squares fit, the design matrix ``F`` of the
    fitted pairs, the map's ``centre`` and ``half`` extent the position features use, and the
    ``target`` log map distances of the pairs."""

    coef: np.ndarray
    F: np.ndarray
    centre: np.ndarray
    half: float
    target: np.ndarray


def fit_calibration(ld: np.ndarray, X: np.ndarray, i: np.ndarray, j: np.ndarray,
                    dissimilarity_degree: int, position_degree: int) -> CalibrationFit:
    """Least-squares fit of the log map distance of pairs ``(i, j)`` of the map ``X`` on powers
    of their log dissimilarity ``ld`` and polynomial features of their midpoint (CAL-SMA's
    calibration; shared by the dense and the sparse estimator)."""
    centre = 0.5 * (X.min(axis=0) + X.max(axis=0))
    half = max(0.5 * float(np.max(X.max(axis=0) - X.min(axis=0))), 1e-12)
    F = np.column_stack(
        [ld**p for p in range(1, dissimilarity_degree + 1)]
        + [np.ones_like(ld), _features(0.5 * (X[i] + X[j]), centre, half, position_degree)]
    )
    dx = np.hypot(*(X[i] - X[j]).T)
    target = np.log(np.maximum(dx, 1e-6 * half))
    coef, *_ = np.linalg.lstsq(F, target, rcond=None)
    return CalibrationFit(coef, F, centre, half, target)


class FoldWarning(UserWarning):
    """The returned map looks folded or collapsed (see ``CalibratedSMACOF.fold_score_``)."""


def _is_scaled_binary(X: np.ndarray) -> bool:
    """True when every row is 0/1 up to a positive factor (raw or L2-normalised visibility)."""
    if X.shape[1] < 2 or np.any(X < 0):
        return False
    nz = X > 0
    row_max = X.max(axis=1, keepdims=True)
    return bool(np.all(np.isclose(X[nz], np.broadcast_to(row_max, X.shape)[nz], rtol=1e-9)))


def history_dissimilarity(X: np.ndarray, kind: str = "auto") -> tuple[np.ndarray, str]:
    """Dissimilarity of history rows and the kind used.

    ``"cosine"``: ``1 - cos`` of the rows (visibility; invariant to the row normalisation).
    ``"euclidean"``: RMS difference ``||x_i - x_j|| / sqrt(D)`` (bearing, range).
    ``"auto"``: cosine when the rows are 0/1 up to a factor per row, else euclidean.
    """
    X = np.asarray(X, dtype=float)
    if kind == "auto":
        kind = "cosine" if _is_scaled_binary(X) else "euclidean"
    if kind == "cosine":
        norms = np.linalg.norm(X, axis=1, keepdims=True)
        Y = X / norms
        delta = 1.0 - np.clip(Y @ Y.T, -1.0, 1.0)
    elif kind == "euclidean":
        delta = euclidean_distance_matrix(X) / np.sqrt(X.shape[1])
    else:
        raise ValueError(f"unknown dissimilarity kind {kind!r}")
    delta = 0.5 * (delta + delta.T)
    np.fill_diagonal(delta, 0.0)
    return np.maximum(delta, 0.0), kind


def fold_score(
    X: np.ndarray,
    delta: np.ndarray,
    n_neighbors: int,
    targets: np.ndarray | None = None,
    *,
    strain: float = 0.2,
) -> float:
    """Data-only fold/collapse score of a map ``X`` (M, 2) for dissimilarities ``delta``.

    Two symptoms of a fold, counted per object:

    - intrusions: pairs that are not among each other's ``2 n_neighbors`` nearest in ``delta``
      but lie closer in the map than half the median map distance to their endpoints'
      ``n_neighbors`` nearest (a region mirrored onto another, or a collapse);
    - strained objects (only when ``targets``, the (M, M) calibrated neighbour distances, are
      given): objects whose map distances to their neighbours miss the targets by more than
      ``strain`` (relative RMS). A fold that does not overlap still has a crease, where
      neighbours are torn apart or squeezed.

    Returns (intrusions + strained objects) / M: about 0 on an unfolded map, well above
    0.05 on a folded or collapsed one.
    """
    X = np.asarray(X, dtype=float)
    delta = np.asarray(delta, dtype=float)
    m = len(delta)
    valid = informative_pairs(delta)
    loc = knn_mask(delta, valid, n_neighbors)
    ext = knn_mask(delta, valid, 2 * n_neighbors)
    Dx = euclidean_distance_matrix(X)
    if not np.all(np.isfinite(Dx)):
        return float(m)
    med = _row_medians(Dx, loc)
    scale = np.median(med[med > 0]) if np.any(med > 0) else 0.0
    if scale <= 0:
        return float(m)  # everything on one point: a collapse
    # a neighbourhood squeezed to under a tenth of the typical one is a local collapse
    med = np.maximum(med, 0.1 * scale)
    radius = 0.5 * np.minimum(med[:, None], med[None, :])
    intrusions = ~ext & (Dx < radius)
    np.fill_diagonal(intrusions, False)
    count = intrusions.sum() / 2
    if targets is not None:
        T = np.asarray(targets, dtype=float)
        res = np.where(loc, (Dx - T) ** 2, 0.0).sum(axis=1)
        ref = np.where(loc, T**2, 0.0).sum(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.sqrt(np.where(ref > 0, res / ref, 0.0))
        count += int(np.sum(rel > strain))
    return float(count / m)


def _row_medians(A: np.ndarray, sel: np.ndarray) -> np.ndarray:
    """``np.median(A[i, sel[i]])`` for every row at once (0 for a row with nothing selected):
    sorted rows with the unselected entries last, then the middle one or two."""
    count = sel.sum(axis=1)
    S = np.sort(np.where(sel, A, np.inf), axis=1)
    rows = np.arange(len(A))
    lo = S[rows, np.maximum(count - 1, 0) // 2]
    hi = S[rows, count // 2]
    return np.where(count > 0, 0.5 * (lo + hi), 0.0)


def log_floor(delta: np.ndarray) -> float:
    """Floor of log(delta) in the calibration: the smallest positive dissimilarity of the fitted
    pairs, at least 1e-12 (identical rows give delta = 0). One rule for every fit, so the
    targets of the fold check and of the refinement agree."""
    positive = delta[delta > 0]
    return max(float(positive.min()), 1e-12) if positive.size else 1e-12


def _features(P: np.ndarray, centre: np.ndarray, half: float, degree: int) -> np.ndarray:
    """Polynomial features (without constant) of positions, in a unit box around the map."""
    x = (P[..., 0] - centre[0]) / half
    y = (P[..., 1] - centre[1]) / half
    F = []
    if degree >= 1:
        F += [x, y]
    if degree >= 2:
        F += [x * x, y * y, x * y]
    if degree >= 3:
        F += [x**3, y**3, x * x * y, x * y * y]
    return np.stack(F, axis=-1) if F else np.zeros(P.shape[:-1] + (0,))


CALIBRATION_CONSTRAINTS: dict = {
    "n_neighbors": [Interval(Integral, 2, None, closed="left"), None],
    "n_rounds": [Interval(Integral, 1, None, closed="left")],
    "position_degree": [Interval(Integral, 0, 3, closed="both")],
    "dissimilarity_degree": [Interval(Integral, 1, 3, closed="both")],
    "far_weight": [Interval(Real, 0, None, closed="left")],
    "far_factor": [Interval(Real, 0, None, closed="left")],
    **ITERATION_CONSTRAINTS,
    "random_state": ["random_state"],
}
"""The ``_parameter_constraints`` CAL-SMA and its sparse variant share (calibration rounds,
neighbour targets, far-pair bound, Guttman updates, seed)."""


class CalibratedSMACOF(TransformerMixin, BaseEstimator):
    """Calibrated, anchored, fold-guarded SMACOF of observation histories (label ``"CAL-SMA"``).

    See the module docstring for the idea. Uses only the history rows and, when given, the
    anchors' ids and known positions (``fit(X, anchor_ids=..., anchor_positions=...)``); then
    ``embedding_`` is in world coordinates and meets the anchors exactly. Without anchors the
    embedding is in arbitrary units and needs an affine fit like the other methods.

    Parameters:
        n_neighbors: neighbour pairs per object (symmetric kNN in the dissimilarity) that get
            calibrated distance targets; None = 12 for cosine (visibility), 10 for euclidean.
        dissimilarity: ``"auto"``, ``"cosine"``, ``"euclidean"`` (see
            :func:`history_dissimilarity`) or ``"precomputed"`` (X is an (M, M) dissimilarity).
        n_rounds: calibrate/re-embed rounds.
        position_degree: degree of the polynomial in the pair's midpoint (0 = no position term).
        dissimilarity_degree: degree of the polynomial in ``log delta``.
        far_weight, far_factor: weight of the lower bound on non-neighbour pairs, and the bound
            as a fraction of the larger neighbourhood radius of the two objects.
        n_init: extra random anchored starts tried only when every deterministic start looks
            folded.
        fold_threshold: ``fold_score_`` above which the map is reported as folded.
        init: None (the deterministic starts) or an (M, 2) start tried first (rows of anchors
            are replaced by their known positions); if its map looks folded, the deterministic
            starts are tried too and the least folded map is kept.
        max_iter, tol: Guttman updates per round and their relative stress tolerance.
        random_state: seed of the random starts.

    Attributes:
        embedding_ (M, 2); dissimilarity_ (M, M) and dissimilarity_kind_; neighbors_ (M, M)
        bool; calibration_ (coefficients of the last calibration); stress_ (normalised stress of
        the neighbour targets: sum w (d - t)^2 / sum w t^2); fold_score_ (see
        :func:`fold_score`); folded_ (bool); starts_ (list of (start, stress, fold_score));
        anchored_ (bool); n_iter_ (Guttman updates of the kept start).
    """

    _parameter_constraints: dict = {
        **CALIBRATION_CONSTRAINTS,
        "dissimilarity": [StrOptions({"auto", "cosine", "euclidean", "precomputed"})],
        "n_init": [Interval(Integral, 0, None, closed="left")],
        "fold_threshold": [Interval(Real, 0, None, closed="left")],
        "init": ["array-like", None],
    }

    def __init__(
        self,
        *,
        n_neighbors: int | None = None,
        dissimilarity: str = "auto",
        n_rounds: int = 20,
        position_degree: int = 2,
        dissimilarity_degree: int = 2,
        far_weight: float = 0.02,
        far_factor: float = 0.7,
        n_init: int = 4,
        fold_threshold: float = 0.05,
        init: np.ndarray | None = None,
        max_iter: int = 100,
        tol: float = 1e-6,
        random_state=None,
    ) -> None:
        store_params(self, locals())

    # ------------------------------------------------------------------ inputs
    @staticmethod
    def _check_anchors(m: int, anchor_ids, anchor_positions):
        if anchor_ids is None and anchor_positions is None:
            return None, None
        if anchor_ids is None or anchor_positions is None:
            raise ValueError("anchor_ids and anchor_positions must be given together")
        return check_anchors(anchor_ids, anchor_positions, m)

    def _dissimilarity(self, X: np.ndarray) -> tuple[np.ndarray, str]:
        if self.dissimilarity == "precomputed":
            if X.shape[0] != X.shape[1]:
                raise ValueError(f"precomputed dissimilarity must be square, got {X.shape}")
            if not np.allclose(X, X.T) or np.any(X < 0):
                raise ValueError("precomputed dissimilarity must be symmetric and non-negative")
            D = 0.5 * (X + X.T)
            np.fill_diagonal(D, 0.0)
            return D, "precomputed"
        kind = self.dissimilarity
        if kind == "auto":
            kind = "cosine" if _is_scaled_binary(X) else "euclidean"
        empty = np.flatnonzero(~np.any(X != 0, axis=1))
        if kind == "cosine" and empty.size:
            raise ValueError(
                f"rows {empty.tolist()[:10]} of X are empty (objects never sensed): "
                "remove them before mapping (build_map reports them as unmapped)"
            )
        return history_dissimilarity(X, kind)

    # ------------------------------------------------------------------ pieces
    def _calibrate(self, D, X, pairs, lo_delta):
        """Least-squares fit of log map distance on log delta and midpoint position."""
        i, j = np.nonzero(np.triu(pairs, 1))
        ld = np.log(np.maximum(D[i, j], lo_delta))
        fit = fit_calibration(ld, X, i, j, self.dissimilarity_degree, self.position_degree)
        coef, centre, half, target = fit.coef, fit.centre, fit.half, fit.target
        L = np.log(np.maximum(D, lo_delta))
        mid = 0.5 * (X[:, None, :] + X[None, :, :])
        G = np.concatenate(
            [
                np.stack([L**p for p in range(1, self.dissimilarity_degree + 1)], axis=-1),
                np.ones(L.shape + (1,)),
                _features(mid, centre, half, self.position_degree),
            ],
            axis=-1,
        )
        # clip the exponent to the fitted range: a pair outside it gets the extreme value
        expo = np.clip(G @ coef, target.min() - 1.0, target.max() + 1.0)
        Dh = np.exp(expo)
        Dh = 0.5 * (Dh + Dh.T)
        np.fill_diagonal(Dh, 0.0)
        return Dh, coef

    def _weights(self, loc):
        """SMACOF weights: 1 on neighbour pairs, ``far_weight`` on the rest, 0 on the diagonal."""
        far = ~loc
        np.fill_diagonal(far, False)
        W = np.where(loc, 1.0, np.where(far, self.far_weight, 0.0))
        if self.far_weight == 0:
            # keep the Guttman system solvable when the neighbour graph falls apart
            W = np.where(far, 1e-6, W)
        np.fill_diagonal(W, 0.0)
        return W

    def _embed(self, T, X, loc, fixed):
        """One re-embedding of targets ``T`` from ``X``, anchors ``fixed`` held: (X, updates)."""
        X, _, it = weighted_smacof(T, self._weights(loc), X, fixed=fixed,
                                   max_iter=self.max_iter, tol=self.tol)
        return X, it

    def _refine(self, D, X, loc, fixed):
        """Alternate calibration and anchored weighted SMACOF (:meth:`_embed`) from start X."""
        lo_delta = log_floor(D[loc])
        far = ~loc
        np.fill_diagonal(far, False)
        n_iter = 0
        Dh = None
        for _ in range(self.n_rounds):
            Dh, coef = self._calibrate(D, X, loc, lo_delta)
            R = np.where(loc, Dh, 0.0).max(axis=1)
            bound = self.far_factor * np.maximum(R[:, None], R[None, :])
            Dx = euclidean_distance_matrix(X)
            # targets: calibrated distance for neighbours, max(current, bound) for the rest
            T = np.where(loc, Dh, np.where(far, np.maximum(Dx, bound), 0.0))
            X, it = self._embed(T, X, loc, fixed)
            n_iter += it
        Dx = euclidean_distance_matrix(X)
        w = loc.astype(float)
        stress = float(np.sum(w * (Dx - Dh) ** 2) / max(np.sum(w * Dh**2), 1e-300))
        return X, stress, n_iter, coef, Dh

    def _starts(self, D, loc, ids, pos):
        """Deterministic starts: unweighted SMACOF and geodesic CMDS, placed on the anchors."""
        m = len(D)
        cmds = classical_mds(D, 2)
        unweighted, _, _ = weighted_smacof(D, 1.0 - np.eye(m), cmds, max_iter=300, tol=1e-6)
        graph = np.where(loc, D, 0.0)
        geo = shortest_path(graph, method="D", directed=False)
        if np.isinf(geo).any():  # disconnected neighbour graph: fall back to the raw values
            geo = np.where(np.isinf(geo), D.max() * 2 + geo[np.isfinite(geo)].max(), geo)
        starts = [("unweighted", unweighted), ("geodesic", classical_mds(geo, 2))]
        return [(name, self._place(S, ids, pos)) for name, S in starts]

    @staticmethod
    def _place(S, ids, pos):
        if ids is None:
            return S
        try:
            S = apply_affine(S, fit_affine(S[ids], pos))
        except ValueError:  # anchors collinear in this start: keep it, fixing the anchors
            pass
        S = S.copy()
        S[ids] = pos
        return S

    # ------------------------------------------------------------------ API
    def fit(self, X, y=None, *, anchor_ids=None, anchor_positions=None):
        """Map the history rows ``X`` (M, D) (or an (M, M) dissimilarity when precomputed).

        ``anchor_ids`` (A,) and ``anchor_positions`` (A, 2), A >= 3, not collinear: objects
        with known positions, held fixed; the embedding is then in world coordinates.
        """
        self._validate_params()
        X = validate_data(self, X, ensure_min_samples=3, dtype=float)
        m = X.shape[0]
        ids, pos = self._check_anchors(m, anchor_ids, anchor_positions)
        D, kind = self._dissimilarity(X)
        k_default = 12 if kind == "cosine" else 10
        k = min(self.n_neighbors if self.n_neighbors is not None else k_default, m - 1)
        valid = informative_pairs(D)
        loc = knn_mask(D, valid, k)
        # the fold check never looks through a smaller neighbourhood than the default one: with
        # a small K a floppy map fits its own few pairs and would pass its own check
        k_check = min(max(k, k_default), m - 1)
        loc_check = loc if k_check == k else knn_mask(D, valid, k_check)
        if not loc.any():
            raise ValueError(
                "no two objects have informative histories (every pair is at the saturation "
                "value, e.g. no two objects were ever sensed together): nothing to calibrate"
            )
        rng = check_random_state(self.random_state)
        if self.init is not None:
            S = np.asarray(self.init, dtype=float)
            if S.shape != (m, 2) or not np.all(np.isfinite(S)):
                raise ValueError(f"init must be a finite ({m}, 2) array, got {S.shape}")
            starts = [("init", self._place(S, ids, pos) if ids is not None else S.copy())]
        else:
            starts = self._starts(D, loc, ids, pos)
        results = []

        def run(name, S):
            Y, stress, n_iter, coef, Dh = self._refine(D, S, loc, ids)
            if k_check != k:  # targets for the wider check: the calibration refitted on it
                Dh, _ = self._calibrate(D, Y, loc_check, log_floor(D[loc_check]))
            fs = fold_score(Y, D, k_check, Dh)
            results.append((name, Y, stress, fs, n_iter, coef))

        for name, S in starts:
            run(name, S)
        if self.init is not None and results[0][3] > self.fold_threshold:
            # the given start folded: recover from the deterministic starts
            for name, S in self._starts(D, loc, ids, pos):
                run(name, S)
        if min(r[3] for r in results) > self.fold_threshold:
            # every deterministic start folded: random anchored starts, spread like the best map
            best = min(results, key=lambda r: (r[3], r[2]))[1]
            spread = best.std(axis=0)
            for t in range(self.n_init):
                S = best.mean(axis=0) + rng.normal(size=(m, 2)) * spread
                run(f"random{t}", self._place(S, ids, pos))
        # keep the least folded map; among those about as unfolded, the lowest stress
        low = min(r[3] for r in results)
        name, Y, stress, fs, n_iter, coef = min(
            (r for r in results if r[3] <= low + 0.02), key=lambda r: r[2]
        )
        self.embedding_ = Y
        self.dissimilarity_ = D
        self.dissimilarity_kind_ = kind
        self.n_neighbors_ = k
        self.neighbors_ = loc
        self.calibration_ = coef
        self.stress_ = stress
        self.fold_score_ = fs
        self.folded_ = bool(fs > self.fold_threshold)
        self.starts_ = [(r[0], r[2], r[3]) for r in results]
        self.anchored_ = ids is not None
        self.n_iter_ = n_iter
        if self.folded_:
            warnings.warn(
                f"CAL-SMA map looks folded or collapsed (fold_score_={fs:.3f} > "
                f"{self.fold_threshold}) after {len(results)} start(s); treat it with caution",
                FoldWarning,
                stacklevel=2,
            )
        return self

    def fit_transform(self, X, y=None, *, anchor_ids=None, anchor_positions=None) -> np.ndarray:
        """Fit and return the (M, 2) embedding (world coordinates when anchors are given)."""
        return self.fit(X, anchor_ids=anchor_ids, anchor_positions=anchor_positions).embedding_

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.pairwise = self.dissimilarity == "precomputed"
        return tags
