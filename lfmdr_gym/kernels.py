"""Compiled per-step kernels: the proximity ring, the occlusion test and the random walk's choice.

The environment runs these once per step on a handful of nearby objects and 32 rays. Written
with numpy, each is a dozen array calls whose fixed cost (about a microsecond each) outweighs
their arithmetic many times over, and the random walk's choice is a plain-Python loop; compiled
with numba they are plain loops over a few dozen numbers. numba is the well-kept way to do this
from Python (no C extension to build); the functions are compiled on first use and cached on
disk (``cache=True``), so a process pays the compilation once per installation. numba itself
is imported on first use (:func:`mappers.core.jit.compiled_on_first_use`).

Each kernel computes the same geometry as the vectorised numpy code it replaced, with the same
formulas in the same order; the two differ at most in the last bit of a value where numpy's
matrix product went through BLAS, which may fuse a multiply and an add (these loops round each
operation). Every history recorded before is recorded again bit for bit
(``tests/test_trajectory_identity.py``); the sensors are tested against brute-force geometry
(``tests/test_sensors.py``) and the random walk's choice against its vectorised reference,
:meth:`lfmdr_gym.policies.RandomWalkPolicy._plan` (``tests/test_policies.py``).
"""

from __future__ import annotations

import math

import numpy as np

from mappers.core.jit import compiled_on_first_use

__all__ = ["first_choice", "proximity_ring", "visible_targets"]  # noqa: F822 - bound by __getattr__

# The kernels are compiled at the first use of any of them and bound under their public names
# (``_room`` first: the compiled ``first_choice`` calls it as a global). numba is imported then
# and not at the top: code that only reads histories or maps (``lfmdr map FILE``,
# :class:`~lfmdr_gym.History`) should not pay for it.
__getattr__ = compiled_on_first_use(globals(), __all__, helpers=("_room",))


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


def _room(px, py, n, c, s, rr2):  # pragma: no cover - compiled
    """How far the disc can advance along the frame's +x before touching an obstacle centre
    (inf if none is in the way): the points ``(px, py)[:n]`` seen from the frame turned by
    (c, s)."""
    room = math.inf
    for i in range(n):
        xm = px[i] * c + py[i] * s
        if xm > 0.0:
            y = py[i] * c - px[i] * s
            if y * y < rr2:
                v = xm - math.sqrt(rr2 - y * y)
                if v < room:
                    room = v
    return room


def _first_choice(proximity, turns, ray_x, ray_y, probe_c, probe_s, obstacle_radius,
                 robot_radius, step, margin, plan_ahead):  # pragma: no cover - compiled
    """Index of the first safe draw in ``turns``, else of the first free one, else -1.

    The random walk's decision (:meth:`lfmdr_gym.policies.RandomWalkPolicy._plan` is the
    vectorised reference): each proximity reading p on ray k is modelled as an obstacle centred
    at ``(p + obstacle_radius) * ray_k``; a draw is free when the disc can advance ``step +
    margin`` after the turn, and safe when it is free and, from where the move ends, some probe
    heading (``probe_c``, ``probe_s``: the cosine and sine of each probe turn) is free too, or
    there is room for two steps straight on. Only readings nearer than ``need + step +
    robot_radius`` can change either answer, so the others are left out.
    """
    need = step + margin
    rr2 = (robot_radius + obstacle_radius) ** 2
    reach = need + step + robot_radius
    n = proximity.shape[0]
    px = np.empty(n)
    py = np.empty(n)
    m = 0
    for k in range(n):
        p = proximity[k]
        if p < reach:
            d = p + obstacle_radius
            px[m] = d * ray_x[k]
            py[m] = d * ray_y[k]
            m += 1
    if m == 0:
        return 0
    first_free = -1
    for i in range(turns.shape[0]):
        c, s = math.cos(turns[i]), math.sin(turns[i])
        room = _room(px, py, m, c, s, rr2)
        if room < need:
            continue
        if first_free < 0:
            first_free = i
        if not plan_ahead or room >= need + step:
            return i
        # Is some probe heading clear from where this move ends? The moved points, in the
        # draw's frame: (x - step, y); a probe turned by (pc, ps) sees them rotated once more.
        qx = np.empty(m)
        qy = np.empty(m)
        for j in range(m):
            qx[j] = (px[j] * c + py[j] * s) - step
            qy[j] = py[j] * c - px[j] * s
        for b in range(probe_c.shape[0]):
            if _room(qx, qy, m, probe_c[b], probe_s[b], rr2) >= need:
                return i
    return first_free
