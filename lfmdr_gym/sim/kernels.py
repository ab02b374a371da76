"""Compiled per-step kernels of the world: the proximity ring and the occlusion test.

The environment runs these once per step on a handful of nearby objects and 32 rays. Written
with numpy, each is a dozen array calls whose fixed cost (about a microsecond each) outweighs
their arithmetic many times over; compiled with numba they are plain loops over a few dozen
numbers. numba is the well-kept way to do this from Python (no C extension to build); the
functions are compiled on first use and cached on disk (``cache=True``), so a process pays the
compilation once per installation. numba itself is imported on first use (see
:func:`mappers.core.jit.compiled_on_first_use`). The random walk's compiled choice is in
:mod:`lfmdr_gym.exploration.random_walk_kernel`.

Each kernel computes the same geometry as the vectorised numpy code it replaced, with the same
formulas in the same order; the two differ at most in the last bit of a value where numpy's
matrix product went through BLAS, which may fuse a multiply and an add (these loops round each
operation). Every history recorded before is recorded again bit for bit
(``tests/gym/histories/test_trajectory_identity.py``); the sensors are tested against brute-force geometry
(``tests/gym/sim/test_sensors.py``).
"""
from __future__ import annotations

import math

import numpy as np

from mappers.core.jit import compiled_on_first_use

__all__ = ["proximity_ring", "visible_targets"]  # noqa: F822 - bound by __getattr__

# The kernels are compiled at the first use of any of them and bound under their public names.
# numba is imported then and not at the top: code that only reads histories or maps
# (``lfmdr map FILE``, :class:`~lfmdr_gym.History`) should not pay for it.
__getattr__ = compiled_on_first_use(globals(), __all__)


def _proximity_ring(x, y, c, s, rc, q, arena_half, dirs, max_range):  # pragma: no cover - compiled
    """Distance along each ray to the first wall or object surface, capped at ``max_range``.

    ``(x, y)`` the robot's centre, ``(c, s)`` the cosine and sine of its heading, ``rc`` (K, 2)
    the offsets of (at least) every object within ``max_range + radius``, ``q`` (K,) their
    squared distances minus the squared radius, ``dirs`` (n, 2) the rays in the robot frame.
    Ray k (world direction u) meets circle j at ``t - sqrt(t^2 - q_j)``, ``t = u . rc_j``: a miss
    when the root's argument is negative, behind the robot when ``t <= 0`` (the centre is outside
    every object, so both roots then lie behind it). The wall ahead along axis i is at
    ``(+-a - p_i) / u_i`` with the sign of ``u_i``.
    """
    n = dirs.shape[0]
    hit = np.empty(n)
    a = arena_half
    near_wall = a - abs(x) < max_range or a - abs(y) < max_range
    for k in range(n):
        dx, dy = dirs[k, 0], dirs[k, 1]
        ux = dx * c - dy * s
        uy = dx * s + dy * c
        best = max_range
        if near_wall:
            wx = (math.copysign(a, ux) - x) / ux if ux != 0.0 else math.inf
            wy = (math.copysign(a, uy) - y) / uy if uy != 0.0 else math.inf
            w = wx if wx < wy else wy
            if w < best:
                best = w
        for j in range(rc.shape[0]):
            t = rc[j, 0] * ux + rc[j, 1] * uy
            if t > 0.0:
                disc = t * t - q[j]
                if disc >= 0.0:
                    e = t - math.sqrt(disc)
                    if e < best:
                        best = e
        hit[k] = best
    return hit


def _visible_targets(cand, rc, dc2, d_vis2, q, occlusion, out):  # pragma: no cover - compiled
    """Set ``out[cand[j]] = 1`` for every candidate j nearer than ``d_vis`` whose line of sight no
    other candidate blocks (``occlusion``), and return how many.

    For target j (line of sight ``rc_j``, squared length ``dc2_j``) and object k, ``p = rc_k .
    rc_j = t d_j``, t the position of k's foot along the line of sight; the perpendicular h from
    k's centre obeys ``h^2 d_j^2 = d_k^2 d_j^2 - p^2``. So k blocks j (0 <= t <= d_j and h < r)
    iff ``0 <= p <= d_j^2`` and ``p^2 > (d_k^2 - r^2) d_j^2``: no square roots needed.
    """
    count = 0
    K = rc.shape[0]
    for j in range(K):
        dt2 = dc2[j]
        if not dt2 < d_vis2:
            continue
        seen = True
        if occlusion:
            tx, ty = rc[j, 0], rc[j, 1]
            for k in range(K):
                if k == j:
                    continue
                p = rc[k, 0] * tx + rc[k, 1] * ty
                if p >= 0.0 and p <= dt2 and p * p > q[k] * dt2:
                    seen = False
                    break
        if seen:
            out[cand[j]] = 1
            count += 1
    return count
