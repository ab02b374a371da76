"""How far a move really went, from the proximity rings before and after it (drift correction).

Dead reckoning from turns and the proximity ring
(:class:`~lfmdr_gym.exploration.coverage.CoveragePolicy`,
:class:`~lfmdr_gym.exploration.agent_view.AgentView`) assumes a move advances the full step unless
the ring reports less room. The turn is always exact, but the advance is not: an object hidden
between two rays (a 48 mm cylinder more than 0.245 m away fits between rays 11.25 degrees apart), or
a wall between two ray hits, can stop the robot short, and every such move adds its shortfall to the
drift.

A stopped move leaves a signature: the robot ends in contact (the physics stops it 10 micro-m
short), so some ray reads about ``robot_radius``. :func:`contact` detects it, and
:func:`matched_advance` then finds the advance ``a`` that best lays the ring after the move,
shifted back by ``a`` along the heading, over the ring before it (the obstacles are static): a
one-dimensional scan match over candidate advances, each post-move hit point scored by its
distance to the nearest pre-move hit point, clipped so that the object that was hidden (seen
only after the move) or a point beyond the range does not dominate.
"""

from __future__ import annotations

import numpy as np

__all__ = ["contact", "hit_points", "matched_advance"]


def hit_points(proximity: np.ndarray, proximity_range: float, rotate: float = 0.0) -> np.ndarray:
    """The (k, 2) points where rays hit something (readings below the range), in the robot's
    frame turned by ``rotate`` [rad] (a point at angle phi appears at phi - rotate)."""
    prox = np.asarray(proximity, dtype=np.float64)
    n = prox.size
    angles = 2.0 * np.pi * np.arange(n) / n - rotate
    hit = prox < proximity_range * (1.0 - 1e-6)
    return np.column_stack([prox[hit] * np.cos(angles[hit]), prox[hit] * np.sin(angles[hit])])


def contact(proximity: np.ndarray, robot_radius: float, tolerance: float = 0.003) -> bool:
    """Whether the ring shows the robot touching an obstacle (a reading within ``tolerance`` of
    ``robot_radius``): the signature of a move the physics stopped short."""
    return bool(np.min(proximity) < robot_radius + tolerance)


def match_costs(before: np.ndarray, after: np.ndarray, turn: float, max_advance: float,
                proximity_range: float, *, resolution: float = 0.005,
                clip: float = 0.03) -> tuple[np.ndarray, np.ndarray] | None:
    """(candidate advances, their mismatch costs) for :func:`matched_advance`; None when either
    ring has fewer than 3 hits."""
    p = hit_points(before, proximity_range, rotate=turn)  # in the frame of the move
    q = hit_points(after, proximity_range)
    if len(p) < 3 or len(q) < 3:
        return None
    cands = np.linspace(0.0, max_advance, max(int(round(max_advance / resolution)), 1) + 1)
    shifted = q[None, :, :] + np.stack([cands, np.zeros_like(cands)], axis=1)[:, None, :]
    d2 = ((shifted[:, :, None, :] - p[None, None, :, :]) ** 2).sum(-1)  # (A, |q|, |p|)
    return cands, np.minimum(np.sqrt(d2.min(axis=2)), clip).sum(axis=1)


def matched_advance(before: np.ndarray, after: np.ndarray, turn: float, max_advance: float,
                    proximity_range: float, *, resolution: float = 0.005,
                    clip: float = 0.03) -> float | None:
    """The advance in [0, max_advance] that best matches the ring ``after`` a move to the ring
    ``before`` it (module docstring); None when either ring sees too little (fewer than 3 hits).

    ``turn`` is the heading change made before the move; ``resolution`` the spacing of the
    candidate advances [m]; ``clip`` the largest mismatch one point may add [m].
    """
    found = match_costs(before, after, turn, max_advance, proximity_range,
                        resolution=resolution, clip=clip)
    if found is None:
        return None
    cands, cost = found
    return float(cands[int(np.argmin(cost))])
