"""What the viewpoint adjustments share: the start map they refine, the objects they free, and
the no-gain guard.

BEARING-BA (:mod:`mappers.viewpoints.bearing`), VIS-BA-WALK (:mod:`mappers.viewpoints.visibility`)
and the range-bearing adjustment (:mod:`mappers.viewpoints.range_bearing`) each refine a start
map with the anchors held at their known positions (they fix the gauge), and each returns that
start, with a warning, when the refinement explains the readings no better.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numpy as np

from mappers.catalog import resolve_method
from mappers.core.align import check_anchors
from mappers.fitting import check_inputs, fit_checked

__all__ = ["anchored_start", "fit_start", "free_objects", "keep_if_better"]


def fit_start(label: str, X, ids, pos, *, sensor: str, mask=None, timeline=None,
              random_state=0, category: type[Warning] = UserWarning, params=None):
    """The start map's (M, 2) positions (NaN rows: not placed) drawn by the method ``label``
    (with ``params``, e.g. ``sparse=True`` for CAL-SMA) on the histories an adjustment was
    given, anchors fitted; each of the start map's notes is issued as a warning of
    ``category``, naming the start method. Returns ``(positions, label)`` with the label as the
    catalog spells it."""
    X, mask, sensor, timeline = check_inputs(X, sensor, mask, timeline)
    spec = resolve_method(label, sensor, masked=mask is not None, n_objects=X.shape[0])
    m = fit_checked(spec, X, ids, pos, sensor, mask, timeline, None, random_state,
                    dict(params or {}), [])[0]
    for note in m.warnings:
        warnings.warn(f"start map ({m.method}): {note}", category, stacklevel=4)
    return m.positions, m.method


def anchored_start(method: str, anchor_ids, anchor_positions, n_objects: int, start_positions,
                   draw: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None):
    """``(ids, pos, P0)``: the anchors checked, and the start map as a new (M, 2) float array
    with the anchors at their known positions (NaN rows: not placed). ``start_positions`` if
    given (its shape checked), else ``draw(ids, pos)``; a ValueError names what is missing."""
    if anchor_ids is None or anchor_positions is None:
        raise ValueError(f"{method} needs anchor_ids and anchor_positions (they fix the map's "
                         "frame)")
    ids, pos = check_anchors(anchor_ids, anchor_positions, n_objects)
    if start_positions is None:
        if draw is None:
            raise ValueError(f"{method} needs start_positions (the map it refines)")
        P0 = np.array(draw(ids, pos), dtype=float)
    else:
        P0 = np.array(start_positions, dtype=float)
        if P0.shape != (n_objects, 2):
            raise ValueError(f"start_positions must have shape ({n_objects}, 2), got {P0.shape}")
    P0[ids] = pos
    return ids, pos, P0


def keep_if_better(P: np.ndarray, P0: np.ndarray, placed: np.ndarray, cost: float,
                   start_cost: float, readings: str, category: type[Warning]):
    """``(refined, positions)``: the refined map ``P`` (unplaced rows NaN) if it is finite and
    its robust cost over ``readings`` is at most the start's, else the start ``P0`` and a
    warning of ``category``."""
    finite = bool(np.all(np.isfinite(P[placed])))
    if finite and cost <= start_cost:
        return True, np.where(placed[:, None], P, np.nan)
    warnings.warn(f"the refined map explains the {readings} no better than the start (robust "
                  f"cost {cost:.4g} against {start_cost:.4g}{'' if finite else ', not finite'}): "
                  "the start map is kept", category, stacklevel=4)
    return False, P0


def free_objects(placed: np.ndarray, ids: np.ndarray, method: str, dims: int, max_free: int,
                 instead: str) -> np.ndarray:
    """The objects an adjustment that solves a dense system of its free objects refines: the
    ``placed`` (M,) bool ones that are not anchors (``ids``), as a bool mask (M,).

    Parameters:
        placed: True for the objects the start map placed.
        ids: the anchors' indices (held at their known positions).
        method: the adjustment's name, for the errors (e.g. ``"VIEW-BA"``).
        dims: the coordinates of one object (its system is ``(dims F, dims F)``).
        max_free: the most free objects F it solves for.
        instead: the method the error advises above ``max_free``.

    Raises:
        ValueError: when no object is free, or more than ``max_free`` are.
    """
    free = placed.copy()
    free[ids] = False
    if not free.any():
        raise ValueError(f"{method} has nothing to refine: every placed object is an anchor")
    if free.sum() > max_free:
        raise ValueError(f"{method} solves a ({dims}F, {dims}F) system of its F free objects "
                         f"each round and F = {int(free.sum())} is above {max_free}: map this "
                         f"history with {instead}")
    return free
