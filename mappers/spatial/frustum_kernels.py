"""Compiled loop of the frustum adjustment (:mod:`mappers.spatial.frustum`): its loss and gradient.

Each evaluation visits every (step, object) pair once (N x M, 100,000 at N = 2000, M = 50); as
numpy array expressions that is some forty temporaries of N x M per call and a scatter-add per
gradient block, and the quasi-Newton fit calls it hundreds of times. A compiled loop does one
call in about a millisecond; numba is the well-kept way to write it in Python (as
:mod:`mappers.viewpoints.view_cone_kernels` does for the planar view cone), compiled and cached
on first use (:mod:`mappers.core.jit`).

The model (one pair: a planar viewpoint ``(x, y, theta)`` whose camera sits at ``height`` above
the floor pitched up by ``pitch``, an object ``p`` in 3-D; ``(xc, yc, zc)`` the object in the
camera's frame, ``x`` right, ``y`` down, ``z`` forward, as :mod:`lfmdr_gym.sim.view3d`; ``d`` its
distance):

- five soft margins, each positive inside the view: ``(t_h zc -+ xc) / (d s)``,
  ``(t_v zc -+ yc) / (d s)`` (the image's four sides, ``t_h``, ``t_v`` the tangents of the half
  fields of view; divided by ``d`` they are angles to first order) and ``(R - d) / s_r`` (the
  range limit; left out when ``R`` is infinite);
- ``q``, the product of their logistic sigmoids: the probability that the object is in view;
- a sighting: ``P = (1 - eps) q`` (a sighting is never spurious: the loss is the margins'
  logistic losses, convex in each margin, whose gradient does not vanish however far outside
  the view the object is put);
- no sighting: ``P = 1 - (1 - eps) q`` (the miss rate ``eps`` absorbs occlusion and dropouts:
  an object in view and not seen costs at most ``-log eps``).

The loss is the negative log-likelihood summed over the pairs.
"""

from __future__ import annotations

import math

import numpy as np

from mappers.core.jit import compiled_on_first_use

__all__ = ["frustum_blocks", "frustum_loss"]  # noqa: F822 - bound by __getattr__

__getattr__ = compiled_on_first_use(
    globals(), __all__, helpers=("log_sigmoid", "camera_frame", "pair_margins", "pair_terms"))


def log_sigmoid(m):  # pragma: no cover - compiled
    """``log(1 / (1 + exp(-m)))`` in the form that cannot overflow."""
    return -math.log1p(math.exp(-m)) if m > 0 else m - math.log1p(math.exp(m))


def camera_frame(rx, ry, rz, ch, sh, cp, sp):  # pragma: no cover - compiled
    """The offset object - camera ``(rx, ry, rz)`` seen from a camera of heading cosine and sine
    ``ch``, ``sh`` and pitch cosine and sine ``cp``, ``sp``: ``(d, ah, xc, yc, zc)``, its
    distance ``d``, its offset ``ah`` along the heading on the floor and its coordinates in the
    camera's frame (module docstring)."""
    d = math.sqrt(rx * rx + ry * ry + rz * rz) + 1e-9
    ah = ch * rx + sh * ry
    xc = sh * rx - ch * ry
    zc = cp * ah + sp * rz
    yc = sp * ah - cp * rz
    return d, ah, xc, yc, zc


def pair_margins(rx, ry, rz, ch, sh, cp, sp, t_h, t_v, R, s_c, s_r, ranged,
                  mg, Jr, Jy):  # pragma: no cover - compiled
    """One pair's five margins into ``mg`` (5,), their derivatives with respect to the offset
    object - camera into ``Jr`` (5, 3) and to the heading into ``Jy`` (5,); returns ``d``."""
    d, ah, xc, yc, zc = camera_frame(rx, ry, rz, ch, sh, cp, sp)
    k = 1.0 / (d * s_c)
    mg[0] = (t_h * zc - xc) * k
    mg[1] = (t_h * zc + xc) * k
    mg[2] = (t_v * zc - yc) * k
    mg[3] = (t_v * zc + yc) * k
    mg[4] = (R - d) / s_r if ranged else 50.0
    # d margin / d (zc, xc, yc, d), then d (zc, xc, yc, d) / d rel and / d heading:
    # xc = (sh, -ch, 0) . rel, zc = (cp ch, cp sh, sp) . rel, yc = (sp ch, sp sh, -cp) . rel;
    # heading: xc' = ah, ah' = -xc
    for i in range(5):
        if i < 4:
            dz = (t_h if i < 2 else t_v) * k
            sgn = -k if i % 2 == 0 else k
            dx = sgn if i < 2 else 0.0
            dy = sgn if i >= 2 else 0.0
            dd = -mg[i] / d
        else:
            dz, dx, dy = 0.0, 0.0, 0.0
            dd = -1.0 / s_r if ranged else 0.0
        Jr[i, 0] = dz * cp * ch + dx * sh + dy * sp * ch + dd * rx / d
        Jr[i, 1] = dz * cp * sh - dx * ch + dy * sp * sh + dd * ry / d
        Jr[i, 2] = dz * sp - dy * cp + dd * rz / d
        Jy[i] = dx * ah - (dz * cp + dy * sp) * xc
    return d


def pair_terms(mg, seen, a, log_a, gm, Hm):  # pragma: no cover - compiled
    """One pair's loss; its gradient with respect to the margins into ``gm`` (5,) and a
    positive semi-definite curvature into ``Hm`` (5, 5): a sighting, the logistic's curvature
    of each margin, 1/4 on the wrong side of its boundary (Böhning's bound: the Gauss-Newton
    model does not overshoot the pairs it has to move most); no sighting, the Gauss-Newton
    term of ``-log(1 - a q)`` in ``log q`` (its negative part dropped)."""
    log_q = 0.0
    for i in range(5):
        log_q += log_sigmoid(mg[i])
    for i in range(5):
        for j in range(5):
            Hm[i, j] = 0.0
    if seen:
        for i in range(5):
            sn = 1.0 / (1.0 + math.exp(mg[i]))  # sigmoid(-m)
            gm[i] = -sn
            Hm[i, i] = 0.25 if mg[i] < 0 else sn * (1.0 - sn)
        return -(log_a + log_q)
    aq = a * math.exp(log_q)
    s = aq / (1.0 - aq)
    c = s * (1.0 + s)
    for i in range(5):
        gm[i] = s / (1.0 + math.exp(mg[i]))
    for i in range(5):
        vi = 1.0 / (1.0 + math.exp(mg[i]))
        for j in range(5):
            Hm[i, j] = c * vi / (1.0 + math.exp(mg[j]))
    return -math.log1p(-aq)


def _frustum_loss(P, C, seen, height, pitch, t_h, t_v, R, s_c, s_r,
                  eps):  # pragma: no cover - compiled
    """The loss (module docstring) of the objects ``P`` (M, 3) and the viewpoints ``C`` (N, 3:
    x, y, heading) given the sightings ``seen`` ((N, M) bool)."""
    n, m = seen.shape
    cp, sp = math.cos(pitch), math.sin(pitch)
    a = 1.0 - eps
    log_a = math.log(a)
    ranged = math.isfinite(R)
    loss = 0.0
    for t in range(n):
        ch, sh = math.cos(C[t, 2]), math.sin(C[t, 2])
        for j in range(m):
            d, _, xc, yc, zc = camera_frame(P[j, 0] - C[t, 0], P[j, 1] - C[t, 1],
                                            P[j, 2] - height, ch, sh, cp, sp)
            k = 1.0 / (d * s_c)
            log_q = (log_sigmoid((t_h * zc - xc) * k) + log_sigmoid((t_h * zc + xc) * k)
                     + log_sigmoid((t_v * zc - yc) * k) + log_sigmoid((t_v * zc + yc) * k))
            if ranged:
                log_q += log_sigmoid((R - d) / s_r)
            else:
                log_q += log_sigmoid(50.0)
            if seen[t, j]:
                loss -= log_a + log_q
            else:
                loss -= math.log1p(-a * math.exp(log_q))
    return loss


def _frustum_blocks(P, C, seen, free_index, height, pitch, t_h, t_v, R, s_c, s_r, eps,
                    U, V, W, g, h):  # pragma: no cover - compiled
    """Add the Gauss-Newton blocks of the loss into ``U`` (N, 3, 3) viewpoint blocks, ``V``
    (F, 3, 3) free-object blocks, ``W`` (N, 3, 3F) viewpoint-object blocks, ``g`` (N, 3) and
    ``h`` (F, 3) gradients (all zero on entry; ``free_index[j]`` is object j's row among the
    free objects or -1); return the loss."""
    n, m = seen.shape
    cp, sp = math.cos(pitch), math.sin(pitch)
    a = 1.0 - eps
    log_a = math.log(a)
    ranged = math.isfinite(R)
    mg, gm = np.empty(5), np.empty(5)
    Jr, Jy, Hm = np.empty((5, 3)), np.empty(5), np.empty((5, 5))
    Jc, Jp = np.empty((5, 3)), np.empty((5, 3))
    HJc, HJp = np.empty((5, 3)), np.empty((5, 3))
    loss = 0.0
    for t in range(n):
        ch, sh = math.cos(C[t, 2]), math.sin(C[t, 2])
        for j in range(m):
            pair_margins(P[j, 0] - C[t, 0], P[j, 1] - C[t, 1], P[j, 2] - height, ch, sh, cp, sp,
                          t_h, t_v, R, s_c, s_r, ranged, mg, Jr, Jy)
            loss += pair_terms(mg, seen[t, j], a, log_a, gm, Hm)
            for i in range(5):  # viewpoint (x, y, heading) and object (x, y, z) Jacobians
                Jc[i, 0], Jc[i, 1], Jc[i, 2] = -Jr[i, 0], -Jr[i, 1], Jy[i]
                Jp[i, 0], Jp[i, 1], Jp[i, 2] = Jr[i, 0], Jr[i, 1], Jr[i, 2]
            for i in range(5):
                for c in range(3):
                    HJc[i, c] = 0.0
                    HJp[i, c] = 0.0
                    for k in range(5):
                        HJc[i, c] += Hm[i, k] * Jc[k, c]
                        HJp[i, c] += Hm[i, k] * Jp[k, c]
            f = free_index[j]
            for r in range(3):
                for i in range(5):
                    g[t, r] += Jc[i, r] * gm[i]
                for c in range(3):
                    acc = 0.0
                    for i in range(5):
                        acc += Jc[i, r] * HJc[i, c]
                    U[t, r, c] += acc
            if f >= 0:
                for r in range(3):
                    for i in range(5):
                        h[f, r] += Jp[i, r] * gm[i]
                    for c in range(3):
                        accv, accw = 0.0, 0.0
                        for i in range(5):
                            accv += Jp[i, r] * HJp[i, c]
                            accw += Jc[i, r] * HJp[i, c]
                        V[f, r, c] += accv
                        W[t, r, 3 * f + c] += accw
    return loss
