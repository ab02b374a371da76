"""One map of one history, and its scores against the ground truth (paper §4.3.2: MPE, MOE).

This is where the world's histories meet the mappers: a map is built from the history and its
anchors only; the true positions that travel with the history score it afterwards.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from lfmdr_gym.histories.history import History

__all__ = ["evaluate", "map_history", "mpe_nonanchor", "score_map"]


def _scores_for(positions: np.ndarray) -> tuple[Any, Any, int]:
    """The position score, the orientation score and the fewest objects it needs, for a map of
    ``positions``' dimension: the paper's MPE and MOE (triangles) in the plane, their 3-D forms
    (:mod:`mappers.core.scores_3d`: tetrahedra) in space."""
    if np.asarray(positions).ndim == 2 and np.asarray(positions).shape[1] == 3:
        from mappers import mean_position_error_3d, tetrahedron_orientation_error

        return mean_position_error_3d, tetrahedron_orientation_error, 4
    from mappers import mean_orientation_error, mean_position_error

    return mean_position_error, mean_orientation_error, 3


def score_map(positions: np.ndarray, unmapped: Sequence[int], history: History) -> dict[str, float]:
    """MPE (mapped objects), MOE and MPE over mapped non-anchor objects of a map of ``history``;
    for a 3-D map, ``moe`` is the tetrahedron orientation error
    (:func:`mappers.tetrahedron_orientation_error`)."""
    mpe, moe, fewest = _scores_for(positions)
    truth = history.object_positions
    unmapped = [int(i) for i in unmapped]
    nan = float("nan")
    mapped = history.n_objects - len(unmapped)
    return {
        "mpe": mpe(positions, truth, exclude=unmapped) if mapped else nan,
        "moe": moe(positions, truth, exclude=unmapped) if mapped >= fewest else nan,
        "mpe_nonanchor": mpe_nonanchor(positions, unmapped, history),
        "unmapped": len(unmapped),
    }


def mpe_nonanchor(positions: np.ndarray, unmapped: Sequence[int], history: History) -> float:
    """MPE [m] over the mapped non-anchor objects of a map of ``history`` (the figure the
    benchmarks report); NaN when none is mapped (the first steps through a limited view)."""
    non_anchor = sorted({int(i) for i in unmapped} | {int(i) for i in history.anchor_ids})
    if history.n_objects <= len(non_anchor):
        return float("nan")
    return _scores_for(positions)[0](positions, history.object_positions, exclude=non_anchor)


def map_history(history: History, method: str | None, params: Mapping[str, Any] | None = None,
                *, uncertainty: bool | str = False) -> Any:
    """``method``'s map of ``history`` (a ``mappers.Map``) from the history and its anchors; None =
    the default for the history's sensor and kind (complete or masked). ``uncertainty``: as
    ``build_map``'s (``Map.covariances``; docs/guide/uncertainty.md)."""
    from mappers import build_map

    return build_map(history, history.anchor_ids, history.anchor_positions, method,
                     uncertainty=uncertainty, **dict(params or {}))


def evaluate(history: History, method: str, params: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Map and score one unit; a mapper failure becomes NaN scores and an ``error`` message."""
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # sklearn/cvxpy chatter would break the progress bar
            result = map_history(history, method, params)
        scores = score_map(result.positions, result.unmapped, history)
        error = ""
    except (ValueError, ArithmeticError) as exc:
        # A method that fails on some data (the paper's HLLE "often failed to run"; the mappers
        # raise MappingError, a ValueError) is a deterministic result to record, not a reason to
        # stop the protocol. Anything else (a bug, MemoryError) stops the run unrecorded, so a
        # rerun retries it.
        nan = float("nan")
        scores = {"mpe": nan, "moe": nan, "mpe_nonanchor": nan, "unmapped": 0}
        error = f"{type(exc).__name__}: {exc}"[:300]
        result = None
    return {**scores, "seconds": time.perf_counter() - t0, "error": error, "map": result}
