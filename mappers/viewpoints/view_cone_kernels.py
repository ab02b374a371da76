"""Compiled loops of the view-cone adjustment (:mod:`mappers.viewpoints.view_cone`).

Each Gauss-Newton round of VIEW-BA visits every (step, object) pair once (N x M, 100,000 at
N = 2000, M = 50) to sum the pair's terms into the blocks of the normal equations. As numpy
array expressions that is some thirty temporaries of N x M and a scatter-add per block, about
0.1 s a round; as a compiled loop it is a few milliseconds. numba is the well-kept way to write
such a loop in Python (as :mod:`lfmdr_gym.sim.kernels` does for the world); it is imported, and the
loops compiled (cached on disk), on first use (:mod:`mappers.core.jit`), so ``import mappers``
does not pay for it.

The model (one pair: viewpoint ``c`` with heading ``theta``, object ``p``, ``d = |p - c|``,
``alpha`` the object's angle off the heading; ``o`` whether the step observed the object, ``b``
its visibility bit):

- the view cone, every pair: ``P(o) = sigmoid(y (cos(alpha) - cos(h)) / s_c)``, ``y = +-1``;
- the visibility bit, observed pairs only: ``P(b) = (1 - eps - f) sigmoid((R - d) / s_r) + f``
  with ``f = 1e-3`` (a floor against log 0).

The loss is the negative log-likelihood. The blocks use each term's Fisher weight, except that a
cone term on the wrong side of its boundary (``z < 0``) takes the logistic's largest curvature,
1/4, instead of its vanishing one: the Gauss-Newton model then does not overshoot the pairs it
has to move most (Böhning's bound).
"""

from __future__ import annotations

import math

from mappers.core.jit import compiled_on_first_use

__all__ = ["cone_blocks", "cone_cost"]  # noqa: F822 - bound by __getattr__

FLOOR = 1e-3
"""The visibility bit's probability floor ``f``."""

__getattr__ = compiled_on_first_use(globals(), __all__)


def _cone_cost(P, C, obs, seen, cos_h, R, s_c, s_r, eps):  # pragma: no cover - compiled
    """The loss (module docstring) of the objects ``P`` (M, 2) and the viewpoints ``C`` (N, 3)
    given the observed sets ``obs`` and visible bits ``seen`` ((N, M) bool)."""
    n, m = obs.shape
    a = 1.0 - eps - FLOOR
    loss = 0.0
    for t in range(n):
        ux, uy = math.cos(C[t, 2]), math.sin(C[t, 2])
        for j in range(m):
            dx, dy = P[j, 0] - C[t, 0], P[j, 1] - C[t, 1]
            d = math.sqrt(dx * dx + dy * dy) + 1e-9
            ca = (dx * ux + dy * uy) / d
            y = 1.0 if obs[t, j] else -1.0
            z = y * (ca - cos_h) / s_c
            loss -= -math.log1p(math.exp(-z)) if z > 0 else z - math.log1p(math.exp(z))
            if obs[t, j]:
                r = (R - d) / s_r
                q = 1.0 / (1.0 + math.exp(-r)) if r > 0 else math.exp(r) / (1.0 + math.exp(r))
                p1 = a * q + FLOOR
                loss -= math.log(p1) if seen[t, j] else math.log(1.0 - p1)
    return loss


def _cone_blocks(P, C, obs, seen, free_index, cos_h, R, s_c, s_r, eps,
                 U, V, W, g, h):  # pragma: no cover - compiled
    """Add the Gauss-Newton blocks of the loss into ``U`` (N, 3, 3) pose blocks, ``V`` (F, 2, 2)
    free-object blocks, ``W`` (N, 3, 2F) pose-object blocks, ``g`` (N, 3) and ``h`` (F, 2)
    gradients (all zero on entry; ``free_index[j]`` is object j's row among the free objects or
    -1); return the loss and the gradient of the loss with respect to ``R``."""
    n, m = obs.shape
    a = 1.0 - eps - FLOOR
    loss, g_r = 0.0, 0.0
    for t in range(n):
        ux, uy = math.cos(C[t, 2]), math.sin(C[t, 2])
        for j in range(m):
            dx, dy = P[j, 0] - C[t, 0], P[j, 1] - C[t, 1]
            d = math.sqrt(dx * dx + dy * dy) + 1e-9
            ex, ey = dx / d, dy / d
            ca = ex * ux + ey * uy
            sa = ey * ux - ex * uy
            y = 1.0 if obs[t, j] else -1.0
            z = y * (ca - cos_h) / s_c
            if z > 0:  # sig_neg = sigmoid(-z), in the form that cannot overflow
                e = math.exp(-z)
                loss += math.log1p(e)
                sig_neg = e / (1.0 + e)
            else:
                loss += -z + math.log1p(math.exp(z))
                sig_neg = 1.0 / (1.0 + math.exp(z))
            lc = -y * sig_neg / s_c  # d loss / d cos(alpha)
            wc = (0.25 if z < 0 else sig_neg * (1.0 - sig_neg)) / (s_c * s_c)
            # d cos(alpha) / d p = (u - cos(alpha) e) / d; / d c = -that; / d theta = sin(alpha)
            bx, by = (ux - ca * ex) / d, (uy - ca * ey) / d
            lb, wb = 0.0, 0.0
            if obs[t, j]:
                r = (R - d) / s_r
                q = 1.0 / (1.0 + math.exp(-r)) if r > 0 else math.exp(r) / (1.0 + math.exp(r))
                p1 = a * q + FLOOR
                dp = -a * q * (1.0 - q) / s_r  # d p1 / d d
                if seen[t, j]:
                    loss -= math.log(p1)
                    lb = -dp / p1
                else:
                    loss -= math.log(1.0 - p1)
                    lb = dp / (1.0 - p1)
                wb = dp * dp / (p1 * (1.0 - p1))
                g_r -= lb  # d d / d R = -1 in the sigmoid's argument
            # the pose's Jacobians: cone (-bx, -by, sa), bit (-ex, -ey, 0)
            g[t, 0] -= lc * bx + lb * ex
            g[t, 1] -= lc * by + lb * ey
            g[t, 2] += lc * sa
            U[t, 0, 0] += wc * bx * bx + wb * ex * ex
            U[t, 0, 1] += wc * bx * by + wb * ex * ey
            U[t, 1, 1] += wc * by * by + wb * ey * ey
            U[t, 0, 2] -= wc * bx * sa
            U[t, 1, 2] -= wc * by * sa
            U[t, 2, 2] += wc * sa * sa
            f = free_index[j]
            if f >= 0:
                h[f, 0] += lc * bx + lb * ex
                h[f, 1] += lc * by + lb * ey
                V[f, 0, 0] += wc * bx * bx + wb * ex * ex
                V[f, 0, 1] += wc * bx * by + wb * ex * ey
                V[f, 1, 0] += wc * by * bx + wb * ey * ex
                V[f, 1, 1] += wc * by * by + wb * ey * ey
                W[t, 0, 2 * f] -= wc * bx * bx + wb * ex * ex
                W[t, 0, 2 * f + 1] -= wc * bx * by + wb * ex * ey
                W[t, 1, 2 * f] -= wc * by * bx + wb * ey * ex
                W[t, 1, 2 * f + 1] -= wc * by * by + wb * ey * ey
                W[t, 2, 2 * f] += wc * sa * bx
                W[t, 2, 2 * f + 1] += wc * sa * by
    for t in range(n):  # the pose blocks are symmetric: fill the lower triangle
        U[t, 1, 0], U[t, 2, 0], U[t, 2, 1] = U[t, 0, 1], U[t, 0, 2], U[t, 1, 2]
    return loss, g_r
