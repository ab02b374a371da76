"""Small geometric histories for the mappers' tests (no simulator): objects in a unit square
sensed from the viewpoints of a walk, by a visibility range threshold, bearings (cos, sin) or
ranges, through a 360-degree view or a limited one (then with the mask of what was observed)."""

from __future__ import annotations

import numpy as np

ANCHORS = np.arange(4)
"""The anchors: the first four objects, near the square's corners."""


def layout(n_objects: int = 24, seed: int = 0) -> np.ndarray:
    """(M, 2) objects in the unit square, at least 0.1 apart; the first four (the anchors) towards
    the corners."""
    rng = np.random.default_rng(seed)
    P = [(0.15, 0.15), (0.85, 0.15), (0.85, 0.85), (0.15, 0.85)]
    while len(P) < n_objects:
        p = rng.uniform(0.1, 0.9, 2)
        if min(np.hypot(*(p - q)) for q in P) >= 0.1:
            P.append(tuple(p))
    return np.array(P)


def walk(n_steps: int = 300, step: float = 0.06, seed: int = 0) -> np.ndarray:
    """(N, 3) poses ``(x, y, heading)`` of a walk in the unit square: steps of ``step`` in the
    heading, which turns a little at every step and turns back at the walls."""
    rng = np.random.default_rng(seed + 1)
    poses = np.empty((n_steps, 3))
    x, y, h = 0.5, 0.5, rng.uniform(-np.pi, np.pi)
    for t in range(n_steps):
        h += rng.normal(0.0, 0.5)
        nx, ny = x + step * np.cos(h), y + step * np.sin(h)
        if not (0.0 <= nx <= 1.0 and 0.0 <= ny <= 1.0):
            h += np.pi
            nx, ny = x + step * np.cos(h), y + step * np.sin(h)
        x, y = float(np.clip(nx, 0.0, 1.0)), float(np.clip(ny, 0.0, 1.0))
        poses[t] = x, y, h
    return poses


def sensed(P: np.ndarray, poses: np.ndarray, fov_deg: float = 360.0,
           max_range: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(distance, bearing, in_view)``, each (M, N): the distance and the bearing relative to
    the heading of each object from each pose, and whether it is within the view (``fov_deg``
    about the heading and ``max_range``; None: any range)."""
    d = P[:, None, :] - poses[None, :, :2]
    dist = np.hypot(d[..., 0], d[..., 1])
    bearing = np.angle(np.exp(1j * (np.arctan2(d[..., 1], d[..., 0]) - poses[None, :, 2])))
    in_view = np.abs(bearing) <= np.radians(fov_deg) / 2
    if max_range is not None:
        in_view &= dist <= max_range
    return dist, bearing, in_view


def history(P: np.ndarray, poses: np.ndarray, sensor: str, *, masked: bool = False,
            radius: float = 0.35, fov_deg: float = 120.0, max_range: float | None = 0.7):
    """``(X, mask)``: the ``sensor`` history of the objects ``P`` from ``poses``.

    Complete (``masked=False``): visibility is ``distance < radius``; every object's bearing and
    range at every step (mask None). Masked: the view is ``fov_deg`` wide (and, for bearing and
    range, ``max_range`` deep); the mask says which objects each step observed (repeated over a
    bearing's two columns), the unobserved entries are 0.
    """
    dist, bearing, in_view = sensed(P, poses, fov_deg if masked else 360.0,
                                    max_range if masked and sensor != "visibility" else None)
    if not masked:
        in_view = np.ones_like(in_view)
    if sensor == "visibility":
        X = (in_view & (dist < radius)).astype(float)
    elif sensor == "bearing":
        X = (np.stack([np.cos(bearing), np.sin(bearing)], -1) * in_view[..., None])
        X = X.reshape(len(P), -1)
        in_view = np.repeat(in_view, 2, axis=1)
    else:
        X = np.where(in_view, dist, 0.0)
    return X, (in_view if masked else None)
