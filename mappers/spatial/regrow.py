"""Growing a rays-only map between adjustments: drop the steps the adjusted map disowns,
intersect the objects left out robustly, resect the steps again.

Rays alone, the resection-and-intersection start (:func:`mappers.spatial.registration.register_rays`)
stalls where a wrongly resected step (three objects, a pose at the wrong minimum) sends every
least-squares intersection through it thousands of metres off: on ``LFMDR-Camera3D-v0`` it
placed 38 of 50 tags while the 12 others were seen 200-400 times each. Between adjustments
(:func:`mappers.spatial.adjustment.adjust_viewpoints`) the map is good enough to tell such steps
(their rays miss the adjusted objects by a median angle above a threshold: they are unposed and
resected again) and to intersect an object from a consensus of its rays (a RANSAC over pairs of
rays, Fischler & Bolles 1981: the pair whose intersection most rays pass within the angle,
then the least-squares intersection of those rays). Written here rather than with a library
because the hypotheses are pairs of 3-D lines and the inlier test is an angle per ray, which
neither scikit-learn's ``RANSACRegressor`` nor OpenCV's solvers take.
"""

from __future__ import annotations

import numpy as np

from mappers.spatial.rays import RayObservations
from mappers.spatial.registration import MIN_RAY_ANGLE, triangulate

__all__ = ["intersect_by_consensus", "step_ray_errors"]


def step_ray_errors(obs: RayObservations, P: np.ndarray, R: np.ndarray,
                    C: np.ndarray) -> np.ndarray:
    """(N,) the median angle [rad] between each posed step's rays and the directions to the
    placed objects it saw (NaN: the step is not posed or saw no placed object)."""
    use = np.all(np.isfinite(P[obs.obj]), axis=1) & np.isfinite(C[obs.step, 0])
    v = np.einsum("kji,kj->ki", R[obs.step[use]], P[obs.obj[use]] - C[obs.step[use]])
    cos = np.einsum("kj,kj->k", v, obs.ray[use]) / np.maximum(np.linalg.norm(v, axis=1), 1e-12)
    angle = np.arccos(np.clip(cos, -1.0, 1.0))
    out = np.full(len(C), np.nan)
    if not use.any():
        return out
    order = np.argsort(obs.step[use], kind="stable")
    steps, angle = obs.step[use][order], angle[order]
    first = np.flatnonzero(np.r_[True, steps[1:] != steps[:-1]])
    for t, part in zip(steps[first], np.split(angle, first[1:]), strict=True):
        out[t] = np.median(part)
    return out


def intersect_by_consensus(obs: RayObservations, P: np.ndarray, R: np.ndarray, C: np.ndarray,
                           max_angle: float, *, n_pairs: int = 300,
                           seed: int = 0) -> np.ndarray:
    """``P`` with the unplaced objects seen from three or more posed steps intersected by
    consensus (see the module's docstring): ``n_pairs`` random pairs of rays diverging by at
    least 10 degrees, the pair whose intersection the most rays pass within ``max_angle`` [rad]
    of, kept when those are at least half the rays (and three), whose least-squares
    intersection is the object's place. Deterministic for a ``seed``."""
    if not max_angle > 0 or n_pairs < 1:
        raise ValueError(f"max_angle must be > 0 and n_pairs >= 1, got {max_angle}, {n_pairs}")
    P = P.copy()
    rng = np.random.default_rng(seed)
    posed = np.isfinite(C[:, 0])
    for i in np.flatnonzero(~np.all(np.isfinite(P), axis=1)):
        k = np.flatnonzero((obs.obj == i) & posed[obs.step])
        if k.size < 3:
            continue
        c = C[obs.step[k]]
        d = np.einsum("kij,kj->ki", R[obs.step[k]], obs.ray[k])  # the rays in the world
        a, b = rng.integers(0, k.size, (2, n_pairs))
        dab = np.einsum("kj,kj->k", d[a], d[b])
        use = (a != b) & (dab < np.cos(MIN_RAY_ANGLE))
        if not use.any():
            continue
        a, b, dab = a[use], b[use], dab[use]
        # the midpoint of the closest points of the lines c_a + s d_a and c_b + t d_b
        w = c[a] - c[b]
        wa, wb = np.einsum("kj,kj->k", d[a], w), np.einsum("kj,kj->k", d[b], w)
        den = 1.0 - dab**2
        s, t = (dab * wb - wa) / den, (wb - dab * wa) / den
        cand = 0.5 * (c[a] + s[:, None] * d[a] + c[b] + t[:, None] * d[b])
        v = cand[:, None, :] - c[None]
        cos = np.einsum("qkj,kj->qk", v, d) / np.maximum(np.linalg.norm(v, axis=2), 1e-12)
        inliers = cos > np.cos(max_angle)
        good = inliers[np.argmax(inliers.sum(axis=1))]
        if good.sum() < max(3, 0.5 * k.size):
            continue
        p, ok = triangulate(c[good], d[good])
        if ok:
            P[i] = p
    return P
