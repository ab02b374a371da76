"""CAL-SMA for the online mapper: its statistics from a Gram matrix, its rounds in fewer passes.

CAL-SMA (:class:`~mappers.calibrated.cal_sma.CalibratedSMACOF`, Yairi 2007's SMA with the
distances calibrated) needs only the dissimilarities of the L2-normalised history rows (paper
eq. 7), and both its cosine (visibility) and RMS Euclidean (bearing) dissimilarities are
functions of the Gram matrix ``G = X X^T`` and the column count: :func:`gram_dissimilarity`.
:class:`~mappers.online.mapper.OnlineMapper` accumulates ``G`` as ``C C^T`` over each batch of
new columns ``C`` (O(M^2 k) for k new columns, no column kept).

:class:`_OnlineCalSMA` runs the estimator's rounds in fewer array passes: the anchored Guttman
system (de Leeuw 1977; Borg & Groenen, *Modern Multidimensional Scaling*, 2005, ch. 8) solved
once per neighbour graph (:class:`_AnchoredGuttman`) and the calibration summed term by term.
Its maps equal the offline estimator's to rounding; ``build_map`` and the offline estimator do
not use it.
"""

from __future__ import annotations

import numpy as np

from mappers.calibrated import CalibratedSMACOF, fit_calibration
from mappers.smacof import squared_distance_matrix

__all__ = ["gram_dissimilarity"]


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
    results equal ``weighted_smacof``'s to rounding (not bit for bit), which is why it does not
    replace :class:`~mappers.smacof.weighted.GuttmanTransform` (the offline maps stay on that)
    nor call it (the pseudo-inverse and the explicit B(X) are the passes it saves).
    """

    def __init__(self, W: np.ndarray, fixed: np.ndarray) -> None:
        self.W = W
        self.free = np.ones(len(W), dtype=bool)
        self.free[fixed] = False
        V = np.diag(W.sum(axis=1)) - W
        self.V_ff_inv = np.linalg.inv(V[np.ix_(self.free, self.free)])
        self.V_fa = V[np.ix_(self.free, ~self.free)]

    def run(self, delta: np.ndarray, X: np.ndarray, max_iter: int, tol: float):
        """(X, raw stress, updates) from start ``X`` (its fixed rows kept), as weighted_smacof."""
        W, free, V_ff_inv = self.W, self.free, self.V_ff_inv
        X = np.array(X, dtype=float)
        rhs_fixed = self.V_fa @ X[~free]
        wd = W * delta
        base = float(np.vdot(W, delta * delta))
        D2 = squared_distance_matrix(X)
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
            D2 = squared_distance_matrix(X_new)
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

    Used by :class:`~mappers.online.mapper.OnlineMapper` for its full fits and warm updates: the
    Guttman system is solved once per neighbour graph (:class:`_AnchoredGuttman`, the last one
    kept in ``solver_``, so warm updates whose graph did not change reuse it), and the
    calibration sums its terms instead of building an (M, M, features) array. The offline estimator is untouched.
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
