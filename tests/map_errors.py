"""The errors of a map against the truth that several test files score their maps by."""

from __future__ import annotations

import numpy as np

from mappers import mean_position_error


def non_anchor_error(Y: np.ndarray, P: np.ndarray, anchor_ids) -> float:
    """Mean distance [m] between the map ``Y`` and the true positions ``P`` over the objects
    that are not anchors (NaN when such a row of ``Y`` is NaN)."""
    keep = np.setdiff1d(np.arange(len(P)), anchor_ids)
    return float(np.mean(np.linalg.norm(Y[keep] - P[keep], axis=1)))


def map_error(m, h) -> float:
    """MPE of the :class:`~mappers.Map` ``m`` of the history ``h`` over its placed non-anchor
    objects."""
    keep = np.setdiff1d(np.arange(h.n_objects), [*h.anchor_ids, *m.unmapped])
    return mean_position_error(m.positions[keep], h.object_positions[keep])
