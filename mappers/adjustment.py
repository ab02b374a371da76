"""What the viewpoint adjustments share: the start map they refine, and the no-gain guard.

BEARING-BA (:mod:`mappers.bearing_adjustment`), VIS-BA (:mod:`mappers.visibility_adjustment`)
and the range-bearing adjustment (:mod:`mappers.range_bearing_adjustment`) each refine a start
map with the anchors held at their known positions (they fix the gauge), and each returns that
start, with a warning, when the refinement explains the readings no better.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numpy as np

from mappers.align import check_anchors

__all__ = ["anchored_start", "keep_if_better"]


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
