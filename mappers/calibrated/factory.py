"""The factory of the label ``"CAL-SMA"``: one method, dense or on sparse pairs.

``sparse=False`` is :class:`~mappers.calibrated.cal_sma.CalibratedSMACOF` (all pairs, fold
guard; up to :data:`mappers.defaults.DENSE_MAX_OBJECTS` objects); ``sparse=True`` is
:class:`~mappers.calibrated.cal_sma_sparse.SparseCalibratedSMACOF`, the same model on sparse
pairs, which takes ``scipy.sparse`` histories and thousands of objects (the ``large`` default of
:mod:`mappers.defaults`). An option of one algorithm is a parameter, as scikit-learn has it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from mappers.calibrated.cal_sma import CalibratedSMACOF
from mappers.calibrated.cal_sma_sparse import SparseCalibratedSMACOF

__all__ = ["dense_keywords"]

_N_ROUNDS = {False: 20, True: 10}
# The defaults (K = 12 for visibility, 10 for bearing/range, via n_neighbors=None) were tuned on
# seeds of our own, never on the protocol's; the grid lets the protocol sweep K like the others.
_FOLD_THRESHOLD = 0.05


def dense_keywords(params: Mapping[str, Any]) -> dict[str, Any]:
    """CAL-SMA's parameters as the label takes them (``spec.resolved_params()``) as keywords of
    the dense estimator, :class:`~mappers.calibrated.cal_sma.CalibratedSMACOF`: the None defaults
    filled in, ``sparse`` dropped (True: ValueError, the sparse form is another estimator)."""
    kw = dict(params)
    if kw.pop("sparse", False):
        raise ValueError("sparse=True is CAL-SMA's sparse form, not the dense estimator")
    if kw.get("n_rounds") is None:
        kw["n_rounds"] = _N_ROUNDS[False]
    if kw.get("fold_threshold") is None:
        kw["fold_threshold"] = _FOLD_THRESHOLD
    return kw


def _cal_sma(
    sparse: bool = False,
    n_neighbors: int | None = None,
    n_rounds: int | None = None,
    position_degree: int = 2,
    fold_threshold: float | None = None,
    random_state=None,
) -> CalibratedSMACOF | SparseCalibratedSMACOF:
    """CAL-SMA's estimator. ``n_rounds`` None: 20 calibrate/re-embed rounds dense, 10 sparse;
    ``fold_threshold`` (None: 0.05) is the dense form's fold guard, which the sparse form has
    not (it needs all pairs): given with ``sparse=True`` it is a ValueError."""
    if not isinstance(sparse, bool):
        raise ValueError(f"sparse must be True or False, got {sparse!r}")
    rounds = _N_ROUNDS[sparse] if n_rounds is None else n_rounds
    if sparse:
        if fold_threshold is not None:
            raise ValueError("fold_threshold is the dense CAL-SMA's fold guard; the sparse form "
                             "(sparse=True) has none")
        return SparseCalibratedSMACOF(n_neighbors=n_neighbors, n_rounds=rounds,
                                      position_degree=position_degree, random_state=random_state)
    return CalibratedSMACOF(
        n_neighbors=n_neighbors,
        n_rounds=rounds,
        position_degree=position_degree,
        fold_threshold=_FOLD_THRESHOLD if fold_threshold is None else fold_threshold,
        random_state=random_state,
    )
