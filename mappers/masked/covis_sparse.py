"""Co-observation maps of masked histories at scale (label ``"COVIS-SPARSE"``).

The masked bearing start (``COVIS-AUTO`` of :mod:`mappers.masked.covis_auto`) compares every
pair of objects through (M, M) matrices and dense (M, N) step tables. With a limited range the
history is mostly unobserved and most pairs are never sensed together, so almost all of that
work is on zeros. Here the same statistics come from sparse products over the observed entries:

- ``S`` (M, N): 1 where object i was sensed in step t; ``C = S S^T`` counts the steps that
  sensed both objects of a pair (non-zero only for pairs sensed together);
- bearing: ``U, V`` (M, N) hold ``cos`` and ``sin`` of each sensed bearing, and
  ``G = U U^T + V V^T`` sums ``cos(b_i - b_j)`` over those steps (visibility: ``G = C``);
- the (angle-weighted) Ochiai coefficient ``och_ij = max(G_ij, 0) / sqrt(n_i n_j)`` with
  ``n_i = C_ii``, and ``delta_ij = -log och_ij``: exactly
  :func:`mappers.masked.coobservation.angle_covisibility_dissimilarity` (tested), on the pairs only.

Pairs sensed together in at least ``min_co`` steps (with ``och > 1e-6``) are the candidate
pairs of CAL-SMA's sparse form (``sparse=True``,
:class:`mappers.calibrated.cal_sma_sparse.SparseCalibratedSMACOF`): a calibration of
``delta`` into metres on each object's nearest pairs, alternated with anchored sparse stress;
pairs never sensed together are only "far" (the lower bound on pairs near in the map). This is
``covis-cal``'s model (CAL-SMA on ``-log och``, its ``"log"`` link) on a sparse graph. Memory
and time grow with the observed entries and the co-observed pairs, not with M^2 or M N.

*Assumes*: what ``covis-cal`` assumes (a smooth, monotone link from the co-observation rate to
distance), over the pairs that were sensed together; and, as CAL-SMA's sparse form, anchors spread
over the arena (the global layout rests on them).
"""

from __future__ import annotations

from numbers import Integral

import numpy as np
import scipy.sparse as sp
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval

from mappers.calibrated import SparseCalibratedSMACOF
from mappers.core.estimator_params import store_params
from mappers.core.sensors import COLUMNS_PER_STEP
from mappers.core.validation import check_fit

__all__ = ["SparseCovis", "sparse_co_observation"]

_SENSORS = ("visibility", "bearing")
_FLOOR = 1e-6  # as the dense coefficient: och below this is "never seen together"


def _steps(X, mask, sensor: str) -> tuple[sp.csr_array, sp.csr_array | None, sp.csr_array | None]:
    """``(S, U, V)``: sensed flags (float 0/1) and, for bearing, cos and sin of each sensed
    bearing, all (M, N) sparse; the per-step view of :func:`mappers.core.sensors.step_observations`
    (a visibility 0 and a bearing pair (0, 0) are not sensed; a masked entry is not sensed)."""
    c = COLUMNS_PER_STEP[sensor]
    Xr = sp.csr_array(X, dtype=np.float64)
    Mr = None if mask is None else sp.csr_array(mask, dtype=bool)
    if (sensor == "bearing" and Xr.shape[1] % 2 == 0 and Xr.has_canonical_format
            and (Mr is None or (Mr.shape == Xr.shape and Mr.has_canonical_format))):
        return _bearing_steps(Xr, Mr)
    Xc = sp.coo_array(Xr)
    m, d = Xc.shape
    if d % c:
        raise ValueError(f"X must be (M, N*{c}) for {sensor!r}, got {Xc.shape}")
    n = d // c
    keep = np.isfinite(Xc.data) & (Xc.data != 0)
    if mask is not None:
        Mk = sp.csr_array(mask, dtype=bool)
        if Mk.shape != Xc.shape:
            raise ValueError(f"mask must have the shape of X {Xc.shape}, got {Mk.shape}")
        keep &= np.asarray(Mk[Xc.row, Xc.col]).ravel()
    row, col, val = Xc.row[keep].astype(np.int64), Xc.col[keep].astype(np.int64), Xc.data[keep]
    if sensor == "visibility":
        pos = val > 0
        S = sp.csr_array((np.ones(int(pos.sum())), (row[pos], col[pos])), shape=(m, n))
        return S, None, None
    # bearing: gather each step's (cos, sin) pair; a pair needs both columns observed
    step = col // 2
    cos = sp.csr_array((np.where(col % 2 == 0, val, 0.0), (row, step)), shape=(m, n))
    sin = sp.csr_array((np.where(col % 2 == 1, val, 0.0), (row, step)), shape=(m, n))
    sensed = sp.csr_array((np.ones(row.size), (row, step)), shape=(m, n))  # stored: either seen
    if mask is not None:  # both columns of the pair observed (collect masks them together)
        Mc = sp.coo_array(Mk)
        both = sp.csr_array((np.ones(Mc.nnz), (Mc.row, Mc.col // 2)), shape=(m, n))
        sensed = sensed.multiply(both >= 2)
    sensed = sp.csr_array(sensed > 0, dtype=np.float64)
    cos, sin = sp.csr_array(cos.multiply(sensed)), sp.csr_array(sin.multiply(sensed))
    # the angle as the dense path takes it (arctan2, then cos and sin), on the sensed entries
    sensed.sort_indices()
    cos = _on_pattern(cos, sensed)
    sin = _on_pattern(sin, sensed)
    angle = np.arctan2(sin, cos)
    U = sp.csr_array((np.cos(angle), sensed.indices, sensed.indptr), shape=(m, n))
    V = sp.csr_array((np.sin(angle), sensed.indices, sensed.indptr), shape=(m, n))
    return sensed, U, V


def _bearing_steps(X: sp.csr_array, mask: sp.csr_array | None):
    """:func:`_steps` of a bearing history whose CSR arrays (and the mask's) are canonical
    (sorted, no duplicates; as ``collect`` records them), read off the CSR arrays in row-major
    order: the same matrices, value for value, without scipy's element look-ups and COO-to-CSR
    conversions (most of the time of :func:`_steps` at M = 1,000, N = 20,000)."""
    m, n = X.shape[0], X.shape[1] // 2
    row = np.repeat(np.arange(m, dtype=np.int64), np.diff(X.indptr))
    col = X.indices.astype(np.int64)
    keep = np.isfinite(X.data) & (X.data != 0)
    if mask is not None:
        mrow = np.repeat(np.arange(m, dtype=np.int64), np.diff(mask.indptr))
        mcol = mask.indices.astype(np.int64)
        if np.array_equal(mask.indptr, X.indptr) and np.array_equal(mask.indices, X.indices):
            keep &= mask.data
        else:  # the mask's value at each reading (False where it stores none)
            mfull = mrow * (2 * n) + mcol
            keep &= _found(mfull, row * (2 * n) + col) & mask.data[
                np.minimum(np.searchsorted(mfull, row * (2 * n) + col), max(mfull.size - 1, 0))]
    row, col, val = row[keep], col[keep], X.data[keep]
    grp, keys, _ = _group(row * n + col // 2)  # (object, step), row-major: never falling
    cos, sin = np.zeros(keys.size), np.zeros(keys.size)
    even = col % 2 == 0
    cos[grp[even]], sin[grp[~even]] = val[even], val[~even]
    if mask is not None:  # both columns of the pair stored in the mask (collect masks them together)
        _, mkeys, count = _group(mrow * n + mcol // 2)
        both = _found(mkeys[count >= 2], keys)
        keys, cos, sin = keys[both], cos[both], sin[both]
    indptr = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(np.bincount(keys // n, minlength=m), out=indptr[1:])
    cols = keys % n
    angle = np.arctan2(sin, cos)
    S = sp.csr_array((np.ones(keys.size), cols, indptr), shape=(m, n))
    U = sp.csr_array((np.cos(angle), cols, indptr), shape=(m, n))
    V = sp.csr_array((np.sin(angle), cols, indptr), shape=(m, n))
    return S, U, V


def _group(key: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For a non-decreasing ``key``: each entry's group, the distinct keys and their counts."""
    first = np.ones(key.size, dtype=bool)
    first[1:] = key[1:] != key[:-1]
    starts = np.flatnonzero(first)
    return np.cumsum(first) - 1, key[starts], np.diff(np.append(starts, key.size))


def _found(sorted_keys: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Whether each of ``at`` is among the (sorted, distinct) ``sorted_keys``."""
    if not sorted_keys.size:
        return np.zeros(at.size, dtype=bool)
    idx = np.minimum(np.searchsorted(sorted_keys, at), sorted_keys.size - 1)
    return sorted_keys[idx] == at


def _on_pattern(A: sp.csr_array, P: sp.csr_array) -> np.ndarray:
    """The values of ``A`` at the stored entries of ``P`` (in P's order), 0 where A has none."""
    rows = np.repeat(np.arange(P.shape[0]), np.diff(P.indptr))
    return np.asarray(A[rows, P.indices]).ravel()


def sparse_co_observation(X, mask=None, *, sensor: str):
    """``(i, j, och, count, n)``: for every pair i < j sensed together at least once, the
    (angle-weighted, for bearing) Ochiai coefficient and the number of steps that sensed both;
    ``n`` (M,) the steps that sensed each object. Sparse products only (module docstring)."""
    if sensor not in _SENSORS:
        raise ValueError(f"sensor must be one of {list(_SENSORS)}, got {sensor!r}")
    S, U, V = _steps(X, mask, sensor)
    C = sp.csr_array(S @ S.T)
    n = C.diagonal()
    Cu = sp.coo_array(sp.triu(C, k=1))
    order = np.lexsort((Cu.col, Cu.row))  # pairs in row-major order
    i, j, count = Cu.row[order].astype(np.int64), Cu.col[order].astype(np.int64), Cu.data[order]
    if sensor == "bearing":
        G = sp.csr_array(U @ U.T + V @ V.T)
        g = np.asarray(G[i, j]).ravel()
    else:
        g = count
    och = np.maximum(g, 0.0) / np.sqrt(n[i] * n[j])
    return i, j, np.clip(och, 0.0, 1.0), count, n


class SparseCovis(TransformerMixin, BaseEstimator):
    """``"COVIS-SPARSE"``: CAL-SMA (``sparse=True``) on ``-log`` of the co-observation coefficient of the
    pairs sensed together in at least ``min_co`` steps (module docstring).

    Parameters:
        min_co: a pair needs this many steps that sensed both to be used.
        n_neighbors, n_rounds, position_degree, random_state: CAL-SMA-SPARSE's.

    ``fit(X, mask=None, *, sensor=None, anchor_ids=None, anchor_positions=None)`` takes a dense
    or scipy sparse visibility or bearing history and mask.

    Attributes:
        embedding_ (M, 2) (NaN rows: objects with no usable pair); cal_ the fitted
        :class:`~mappers.calibrated.cal_sma_sparse.SparseCalibratedSMACOF`; n_features_in_.
    """

    _parameter_constraints: dict = {
        "min_co": [Interval(Integral, 1, None, closed="left")],
        "n_neighbors": [Interval(Integral, 2, None, closed="left"), None],
        "n_rounds": [Interval(Integral, 1, None, closed="left")],
        "position_degree": [Interval(Integral, 0, 3, closed="both")],
        "random_state": ["random_state"],
    }

    def __init__(self, *, min_co: int = 3, n_neighbors: int | None = 12, n_rounds: int = 10,
                 position_degree: int = 2, random_state=0) -> None:
        store_params(self, locals())

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.sparse = True
        return tags

    def fit(self, X, y=None, *, mask=None, sensor: str | None = None, anchor_ids=None,
            anchor_positions=None):
        """Map the history ``X`` (M, D), dense or sparse (``mask`` True where observed)."""
        X, mask, sensor = check_fit(self, X, y, bools=("min_co",), mask=mask, sensor=sensor,
                                    sensors=_SENSORS, accept_sparse=True)
        m = X.shape[0]
        i, j, och, count, _ = sparse_co_observation(X, mask, sensor=sensor)
        use = (count >= self.min_co) & (och > _FLOOR)
        i, j, och = i[use], j[use], och[use]
        placed = np.zeros(m, dtype=bool)
        placed[i] = placed[j] = True
        out = np.full((m, 2), np.nan)
        ids = None if anchor_ids is None else np.asarray(anchor_ids)
        pos = None if anchor_positions is None else np.asarray(anchor_positions, dtype=np.float64)
        if ids is not None and not placed[ids].all():  # an anchor without usable pairs: unplaced
            keep_anchor = placed[ids]
            ids, pos = ids[keep_anchor], pos[keep_anchor]
        rows = np.flatnonzero(placed)
        local = np.full(m, -1)
        local[rows] = np.arange(rows.size)
        self.cal_ = SparseCalibratedSMACOF(n_neighbors=self.n_neighbors, n_rounds=self.n_rounds,
                                           position_degree=self.position_degree,
                                           random_state=self.random_state)
        self.cal_.fit_pairs(local[i], local[j], -np.log(och), rows.size,
                            anchor_ids=None if ids is None else local[ids],
                            anchor_positions=pos)
        out[rows] = self.cal_.embedding_
        self.embedding_ = out
        return self

    def fit_transform(self, X, y=None, *, mask=None, sensor: str | None = None, anchor_ids=None,
                      anchor_positions=None):
        """Fit and return the (M, 2) map (NaN rows: objects with no usable pair)."""
        return self.fit(X, mask=mask, sensor=sensor, anchor_ids=anchor_ids,
                        anchor_positions=anchor_positions).embedding_
