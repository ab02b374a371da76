"""The information of the image pairs the 6-DoF adjustment leaves out, for the directions it
leaves free: a finite, honest covariance for an object the adjustment fixes only up to a turn.

SPATIAL-BA (:mod:`mappers.spatial.spatial_ba`) estimates a step's pose only where the step sees
three placed objects (a pose from two points turns freely about their line), so a step that
sees two objects is left out of the adjustment. Its reading still holds one pose-free number:
with rays ``u_a, u_b`` and ranges ``r_a, r_b`` the two objects' distance
``|r_a u_a - r_b u_b|``, whatever the pose (the law of cosines). The start
(:func:`mappers.spatial.registration.register_points`) uses those distances to place objects
the posed steps do not fix; the adjustment then moves the objects only along the directions its
own readings fix. An object the posed steps fix only up to a turn (on STAR-loc's eight_s3, tag
30 is seen by one posed step together with tags 44 and 53: any turn about their line fits) thus
keeps the start's place along that turn, and its marginal from the adjustment's normal
equations alone (:mod:`mappers.spatial.marginals`) is unbounded although the estimate is not.

The rule (:func:`complete_free_directions`): where the objects' reduced information ``S`` of
the adjustment is singular, the directions it leaves free (its null space ``N``, the directions
:func:`mappers.core.uncertainty.block_marginals` calls unbounded) get the information ``D`` of
the left-out pairs' distances (:func:`pair_distance_information`), the others keep exactly
the adjustment's. That is the covariance of the estimate as it is made: the free coordinates
``n = Nᵀ x`` are what the distances give with the rest of the map held at the adjustment's
values ``c`` (``V`` the range of ``S``, ``Λ`` its eigenvalues): linearised,
``e_n = A⁻¹ Nᵀ Jᵀ W ε - A⁻¹ Nᵀ D V e_c`` with ``A = Nᵀ D N``, so the rest's own error
(covariance ``Λ⁻¹``) is carried into them, and the distances' noise ``ε`` is independent of the
adjustment's readings (other image pairs). An object with no component along ``N`` keeps its
covariance; an object whose free direction no distance fixes stays unbounded. Distances of two
objects the adjustment already fixes are not added: the estimate does not use them, so they
would claim a precision it does not have. Only steps left out with exactly two placed, ranged
objects give a distance (a left-out step of three or more was left out for disagreeing with
the map). Each distance's variance is the sensor model's, propagated (first order) from the
two ranges (``range_noise + range_growth r²``) and the four ray angles (``bearing_noise``
each), and it is weighted by the adjustment's robust loss at its residual on the final map, as
a reading of the adjustment would be (Triggs et al., *Bundle Adjustment — A Modern Synthesis*,
2000, §9 on gauge and null directions; Hartley & Zisserman, *Multiple View Geometry*, 2nd ed.,
§5.2 on propagating covariance through a least-squares estimate).
"""

from __future__ import annotations

import numpy as np

from mappers.viewpoints import robust_weights

__all__ = ["complete_free_directions", "left_out_pairs", "pair_distance_information"]

NULL_TOL = 1e-12
"""An eigenvalue of the reduced information at most this share of its largest is a free
direction: the threshold :func:`mappers.core.uncertainty.block_marginals` calls unbounded."""


def left_out_pairs(obs, placed: np.ndarray, posed: np.ndarray) -> np.ndarray:
    """(L, 2) rows of ``obs`` (:class:`~mappers.spatial.rays.RayObservations`): the two
    sightings of each step that is not ``posed`` ((N,) bool) and sees exactly two ``placed``
    ((M,) bool) objects with a range each (module docstring)."""
    use = ~posed[obs.step] & placed[obs.obj] & np.isfinite(obs.range) & (obs.range > 0)
    rows = np.flatnonzero(use)
    count = np.bincount(obs.step[rows], minlength=obs.n_steps)
    rows = rows[count[obs.step[rows]] == 2]
    rows = rows[np.argsort(obs.step[rows], kind="stable")]
    return rows.reshape(-1, 2)


def pair_distance_information(obs, points: np.ndarray, posed: np.ndarray, index: np.ndarray,
                              n_unknown: int, *, bearing_noise: float, range_noise: float,
                              range_growth: float, loss: str | None,
                              loss_scale: float) -> np.ndarray:
    """(3F, 3F) the information (in noise units, as the adjustment's normal matrix) of the
    pose-free distances of the steps left out of the adjustment with two objects
    (:func:`left_out_pairs`) on the ``n_unknown`` objects whose row ``index`` ((M,), -1: held,
    as an anchor) gives; ``points`` (M, 3) the adjusted objects (NaN: not placed), ``posed``
    (N,) the steps the adjustment posed, ``obs`` its sightings (the ranges as it scaled them).

    A distance ``d = |r_a u_a - r_b u_b|`` of unit direction ``n`` (in the sensor's frame) has
    the variance ``sum_k (n·u_k)² σ_r(r_k)² + r_k² σ_b² (1 - (n·u_k)²)`` (first order: a range
    moves its point along its ray, an angle across it), ``σ_r(r) = range_noise + range_growth
    r²`` and ``σ_b = bearing_noise`` as :class:`mappers.spatial.adjustment.Problem` models a
    reading; its residual on the map, ``(|p_a - p_b| - d) / σ_d``, gets the weight of ``loss``
    at ``loss_scale`` (:func:`mappers.viewpoints.robust_weights`)."""
    D = np.zeros((3 * n_unknown, 3 * n_unknown))
    placed = np.all(np.isfinite(points), axis=1)
    pairs = left_out_pairs(obs, placed, posed)
    if not len(pairs) or not n_unknown:
        return D
    a, b = obs.obj[pairs[:, 0]], obs.obj[pairs[:, 1]]
    keep = (index[a] >= 0) | (index[b] >= 0)
    pairs, a, b = pairs[keep], a[keep], b[keep]
    u, r = obs.ray[pairs], obs.range[pairs]  # (L, 2, 3), (L, 2)
    u = u / np.linalg.norm(u, axis=2, keepdims=True)
    delta = r[:, 0, None] * u[:, 0] - r[:, 1, None] * u[:, 1]
    d = np.linalg.norm(delta, axis=1)
    ok = d > 0
    n = delta[ok] / d[ok, None]
    along = np.einsum("lj,lkj->lk", n, u[ok])  # (L, 2): cos of each ray to the pair's line
    sr = range_noise + range_growth * r[ok] ** 2
    var = np.sum(along**2 * sr**2 + r[ok] ** 2 * bearing_noise**2 * (1.0 - along**2), axis=1)
    a, b, d = a[ok], b[ok], d[ok]
    diff = points[a] - points[b]
    length = np.linalg.norm(diff, axis=1)
    m = diff / np.maximum(length, 1e-12)[:, None]
    e = (length - d) / np.sqrt(var)
    w = robust_weights(np.abs(e), loss_scale, loss) / var
    # J = [m, -m] on the two objects' coordinates: information w [m; -m][m; -m]ᵀ
    outer = w[:, None, None] * m[:, :, None] * m[:, None, :]
    for x, y, sign in ((a, a, 1.0), (b, b, 1.0), (a, b, -1.0), (b, a, -1.0)):
        both = (index[x] >= 0) & (index[y] >= 0)
        rows = 3 * index[x[both], None, None] + np.arange(3)[None, :, None]
        cols = 3 * index[y[both], None, None] + np.arange(3)[None, None, :]
        np.add.at(D, (np.broadcast_to(rows, (both.sum(), 3, 3)),
                      np.broadcast_to(cols, (both.sum(), 3, 3))), sign * outer[both])
    return D


def complete_free_directions(S: np.ndarray, D: np.ndarray) -> np.ndarray:
    """The reduced information ``S`` (dF, dF) with its free directions given the information
    ``D`` (dF, dF) of the readings the adjustment left out (module docstring): ``S`` itself
    when ``D`` is zero, ``S`` has no free direction (no eigenvalue at most :data:`NULL_TOL` of
    its largest) or ``D`` fixes none of them; else the information of the estimate whose fixed coordinates are the
    adjustment's and whose free ones ``D`` gives, the others' error carried into them. Its
    inverse keeps ``S``'s pseudo-inverse on the objects without a free component; the free
    directions ``D`` does not fix stay free (a null space of the result)."""
    if not S.shape[0] or not np.any(D):
        return S
    # (an eigen-decomposition, not a Cholesky factorisation's failure: a free direction's
    # eigenvalue is rounding noise, ~1e-16 of the largest, and may come out positive)
    ev, vec = np.linalg.eigh(0.5 * (S + S.T))
    tol = NULL_TOL * max(float(ev[-1]), 1e-300)
    null = ev <= tol
    if not null.any():
        return S
    N, V, lam = vec[:, null], vec[:, ~null], ev[~null]
    D = 0.5 * (D + D.T)
    a, Q = np.linalg.eigh(N.T @ D @ N)
    fixed = a > tol
    if not fixed.any():
        return S
    Nf, af = N @ Q[:, fixed], a[fixed]
    # the joint information of the fixed coordinates c (error ~ N(0, Λ⁻¹)) and the free ones n
    # (e_n + B e_c ~ N(0, A⁻¹), B = A⁻¹ Nfᵀ D V): [[Λ + Bᵀ A B, Bᵀ A], [A B, A]]
    AB = Nf.T @ D @ V
    top = np.diag(lam) + AB.T @ (AB / af[:, None])
    P = np.block([[top, AB.T], [AB, np.diag(af)]])
    E = np.hstack([V, Nf])
    out = E @ P @ E.T
    return 0.5 * (out + out.T)
