"""The random walk's compiled choice of a draw: the first safe turn, else the first free one.

:class:`~lfmdr_gym.exploration.random_walk.RandomWalkPolicy` runs this once per env step;
usually the first draw settles it. As a plain-Python loop or a dozen numpy calls its fixed
costs outweigh its arithmetic many times over, so it is compiled with numba on first use and
cached on disk (``cache=True``); numba itself is imported on first use
(:func:`mappers.core.jit.compiled_on_first_use`).
It makes the same decisions, with the same formulas in the same order, as the vectorised
reference :meth:`lfmdr_gym.exploration.random_walk.RandomWalkPolicy._plan`
(``tests/gym/exploration/test_policies.py``), and every walk recorded before is recorded again bit for bit
(``tests/gym/histories/test_trajectory_identity.py``).
"""

from __future__ import annotations

import math

import numpy as np

from mappers.core.jit import compiled_on_first_use

__all__ = ["first_choice"]  # noqa: F822 - bound by __getattr__


# Compiled at first use and bound under its public name (``_room`` first: the compiled
# ``first_choice`` calls it as a global). numba is imported then and not at the top: code that
# only reads histories or maps should not pay for it.
__getattr__ = compiled_on_first_use(globals(), __all__, helpers=("_room",))


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

    The random walk's decision (:meth:`lfmdr_gym.exploration.random_walk.RandomWalkPolicy._plan` is
    the vectorised reference): each proximity reading p on ray k is modelled as an obstacle centred
    at ``(p + obstacle_radius) * ray_k``; a draw is free when the disc can advance ``step + margin``
    after the turn, and safe when it is free and, from where the move ends, some probe heading
    (``probe_c``, ``probe_s``: the cosine and sine of each probe turn) is free too, or there is room
    for two steps straight on. Only readings nearer than ``need + step + robot_radius`` can change
    either answer, so the others are left out.
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
