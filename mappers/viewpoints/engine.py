"""The bundle-adjustment engine the viewpoint adjustments share.

Angles and their residuals, the robust loss (Huber or Cauchy weights and costs), the closed-form
and iterative resection of each step's pose from a map, the intersection of rays, and the
Levenberg-Marquardt step with the viewpoints eliminated by the Schur complement (each pose's
3x3 block is solved away, leaving the free objects' normal equations), as bundle adjusters do
(Triggs et al., *Bundle Adjustment — A Modern Synthesis*, 2000), dense or, for problems whose
dense pose-object coupling would not fit, sparse (:mod:`mappers.viewpoints.sparse_schur`), and
the one Levenberg-Marquardt driver (:func:`damped_step`) under each adjustment's damping rule
(:class:`Damping`). BEARING-BA (:mod:`mappers.viewpoints.bearing`), the view-cone and
range-bearing adjustments, the 6-DoF adjustment (:mod:`mappers.spatial.adjustment`) and the
online bundle use these pieces.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mappers.viewpoints import sparse_schur_kernels as kernels
from mappers.viewpoints.sparse_schur import (
    CG_RTOL,
    DENSE_COUPLING_MAX_BYTES,
    Coupling,
    sparse_schur_step,
    use_sparse_coupling,
)

__all__ = [
    "CG_RTOL",
    "DENSE_COUPLING_MAX_BYTES",
    "Coupling",
    "Damping",
    "bearing_angles",
    "bearing_observations",
    "bearing_residuals",
    "damped_step",
    "initial_poses",
    "intersect",
    "joint_step",
    "normal_blocks",
    "pose_jacobian",
    "ray_spread",
    "resect",
    "robust_cost",
    "robust_weights",
    "scatter_sum",
    "schur_step",
    "sparse_schur_step",
    "use_sparse_coupling",
    "wrap_angles",
]

_UNIT_TOL = 1e-3
"""How far an observed (cos, sin) pair's norm may be from 1 (float32 storage, rounding)."""

_MIN_RANGE = 0.05
"""Smallest range [m] in the angle weights of the alternating intersection (an object at the
viewpoint)."""


def wrap_angles(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def bearing_angles(X, mask=None) -> tuple[np.ndarray, np.ndarray]:
    """``(theta, seen)``, both (N, M): the bearing [rad] of each object at each step, relative to
    the heading, and whether it was observed (masked in, and not the (0, 0) of an object at the
    viewpoint). ValueError when ``X`` is not a history of unit (cos, sin) pairs."""
    X = np.asarray(X, dtype=float)
    if X.ndim != 2 or X.shape[1] % 2 or X.shape[1] == 0:
        raise ValueError(f"a bearing history has 2 columns (cos, sin) per step, got shape {X.shape}")
    c, s = X[:, 0::2].T, X[:, 1::2].T
    seen = (c != 0) | (s != 0)
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != X.shape:
            raise ValueError(f"mask must have the shape of the history {X.shape}, got {mask.shape}")
        seen &= mask[:, 0::2].T & mask[:, 1::2].T
    norm = np.hypot(c, s)[seen]
    if not np.all(np.isfinite(norm)) or np.any(np.abs(norm - 1.0) > _UNIT_TOL):
        bad = norm[np.abs(norm - 1.0) > _UNIT_TOL]
        raise ValueError(
            "a bearing history holds unit (cos, sin) pairs; found observed pairs of norm "
            f"{bad[:3].round(3).tolist()} (a visibility or range history, or normalised rows? "
            "pass normalize=False)"
        )
    return np.arctan2(s, c), seen


def bearing_observations(X, mask=None) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], int, int]:
    """``((t, i, theta), N, M)``: the step, object and bearing [rad] of each observation (as
    :func:`bearing_angles` sees them), ordered by step then object, from a dense history or a
    ``scipy.sparse`` one (with a sparse or dense mask; the (N, M) arrays of
    :func:`bearing_angles` are never built for it). ValueError as :func:`bearing_angles`."""
    if not sp.issparse(X):
        theta, seen = bearing_angles(X, mask)
        t, i = np.nonzero(seen)
        return (t, i, theta[t, i]), theta.shape[0], theta.shape[1]
    X = sp.csr_array(X, dtype=float)
    if X.ndim != 2 or X.shape[1] % 2 or X.shape[1] == 0:
        raise ValueError(f"a bearing history has 2 columns (cos, sin) per step, got shape {X.shape}")
    c, s = X[:, 0::2], X[:, 1::2]
    seen = sp.csr_array((c != 0) + (s != 0), dtype=bool)
    if mask is not None:
        mask = sp.csr_array(mask, dtype=bool)
        if mask.shape != X.shape:
            raise ValueError(f"mask must have the shape of the history {X.shape}, got {mask.shape}")
        seen = sp.csr_array(seen.multiply(mask[:, 0::2]).multiply(mask[:, 1::2]), dtype=bool)
    seen.eliminate_zeros()
    i, t = seen.nonzero()
    order = np.lexsort((i, t))
    t, i = t[order], i[order]
    cv, sv = np.asarray(c[i, t]).ravel(), np.asarray(s[i, t]).ravel()
    norm = np.hypot(cv, sv)
    if not np.all(np.isfinite(norm)) or np.any(np.abs(norm - 1.0) > _UNIT_TOL):
        raise ValueError("a bearing history holds unit (cos, sin) pairs; found observed pairs of "
                         f"norm {norm[np.abs(norm - 1.0) > _UNIT_TOL][:3].round(3).tolist()}")
    return (t, i, np.arctan2(sv, cv)), X.shape[1] // 2, X.shape[0]


def robust_weights(res: np.ndarray, scale: float, loss: str | None) -> np.ndarray:
    """IRLS weights of the residuals for the loss (1 inside the scale)."""
    if loss is None:
        return np.ones_like(res)
    u = np.abs(res) / scale
    if loss == "huber":
        return np.where(u <= 1.0, 1.0, 1.0 / np.maximum(u, 1e-300))
    return 1.0 / (1.0 + u * u)  # cauchy


def robust_cost(res: np.ndarray, scale: float, loss: str | None) -> np.ndarray:
    """The loss of each residual (least squares: ``res**2 / 2``)."""
    if loss is None:
        return 0.5 * res * res
    u = np.abs(res) / scale
    if loss == "huber":
        return scale * scale * np.where(u <= 1.0, 0.5 * u * u, u - 0.5)
    return 0.5 * scale * scale * np.log1p(u * u)


def scatter_sum(idx: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Per index, the sum of ``values`` (K,) or (K, ...) over the observations with that index."""
    if values.ndim == 1:
        return np.bincount(idx, weights=values, minlength=n)
    # the trailing size spelt out: reshape(0, -1) cannot infer it when there are no values
    flat = values.reshape(len(values), int(np.prod(values.shape[1:])))
    out = np.stack([np.bincount(idx, weights=flat[:, k], minlength=n) for k in range(flat.shape[1])],
                   axis=1)
    return out.reshape((n, *values.shape[1:]))


def bearing_residuals(P, C, phi, obs):
    """Angle residuals (K,) of the observations ``obs = (t, i, theta)`` and the offsets object -
    viewpoint (K, 2)."""
    t, i, th = obs
    d = P[i] - C[t]
    return wrap_angles(np.arctan2(d[:, 1], d[:, 0]) - phi[t] - th), d


def pose_jacobian(d):
    """d residual / d (x, y, heading) of the viewpoint, (K, 3); the object's is minus the first two."""
    r2 = np.maximum(np.einsum("kj,kj->k", d, d), 1e-12)
    return np.column_stack([d[:, 1] / r2, -d[:, 0] / r2, -np.ones_like(r2)])


def initial_poses(P, obs, n, compiled: bool = False):
    """Each step's pose from the start map in closed form. In the robot's frame an object is at
    ``e = R(phi)^T p - s`` with ``s = R(phi)^T c``, and its bearing ``v`` is parallel to ``e``:
    ``a (p x v) + b (p . v) - s1 v_y + s2 v_x = 0`` with ``(a, b) = (cos phi, sin phi)``, linear
    in ``(a, b, s1, s2)``; the least-squares solution is the normal matrix's eigenvector of the
    smallest eigenvalue, scaled to ``a^2 + b^2 = 1`` and signed so that the objects lie ahead
    along their rays. Returns the poses and which steps gave one. ``compiled``: the normal
    matrices summed by a compiled loop
    (:func:`mappers.viewpoints.sparse_schur_kernels.outer_sums`, the same sums in the same
    order), for large problems (it imports numba)."""
    t, i, th = obs
    vx, vy = np.cos(th), np.sin(th)
    px, py = P[i, 0], P[i, 1]
    rows = np.column_stack([px * vy - py * vx, py * vy + px * vx, -vy, vx])
    if compiled:
        A = np.zeros((n, 4, 4))
        kernels.outer_sums(rows, np.ascontiguousarray(t, dtype=np.int64), A)
    else:
        A = scatter_sum(t, rows[:, :, None] * rows[:, None, :], n)
    ev, vec = np.linalg.eigh(A)
    z = vec[:, :, 0]
    norm = np.hypot(z[:, 0], z[:, 1])
    ok = (norm > 1e-9) & (ev[:, 1] > 1e-12 * np.maximum(ev[:, -1], 1e-300))
    z = z / np.where(ok, norm, 1.0)[:, None]
    ahead = scatter_sum(t, (rows[:, 1] * z[t, 0] - rows[:, 0] * z[t, 1]  # e . v = (R^T p - s) . v
                     - z[t, 2] * vx - z[t, 3] * vy), n)
    z *= np.where(ahead < 0, -1.0, 1.0)[:, None]
    phi = np.arctan2(z[:, 1], z[:, 0])
    C = np.column_stack([z[:, 0] * z[:, 2] - z[:, 1] * z[:, 3], z[:, 1] * z[:, 2] + z[:, 0] * z[:, 3]])
    return C, phi, ok


def resect(P, C, phi, obs, w, iters: int, compiled: bool = False):
    """Gauss-Newton on each step's pose (batched 3 x 3 systems), the objects fixed; returns the
    poses and which steps have a well-conditioned system. ``compiled``: the systems summed by
    one compiled loop over the observations
    (:func:`mappers.viewpoints.sparse_schur_kernels.bearing_blocks` with no free object: the
    same sums in the same order), for large problems (it imports numba)."""
    n, t = len(C), obs[0]
    ok = np.ones(n, dtype=bool)
    for _ in range(iters):
        res, d = bearing_residuals(P, C, phi, obs)
        if compiled:
            # no free object: the poses' part of the normal equations alone
            H, _, _, g, _ = _sparse_normal_blocks(res, d, w, t, np.full(len(res), -1), n, 0)
        else:
            a = pose_jacobian(d)
            H = scatter_sum(t, w[:, None, None] * a[:, :, None] * a[:, None, :], n)
            g = scatter_sum(t, (w * res)[:, None] * a, n)
        ev = np.linalg.eigvalsh(H)
        ok = ev[:, 0] > 1e-8 * np.maximum(ev[:, -1], 1e-300)
        H[~ok] = np.eye(3)
        step = -np.linalg.solve(H, g[..., None])[..., 0]
        step[~ok] = 0.0
        step[:, 2] = np.clip(step[:, 2], -0.5, 0.5)
        C = C + step[:, :2]
        phi = wrap_angles(phi + step[:, 2])
    return C, phi, ok


def intersect(P, C, phi, obs, w):
    """Each object's least-squares point of its rays' lines, the perpendicular offsets divided by
    the current range (the angle residuals to first order); returns the points (M, 2)."""
    t, i, th = obs
    m = len(P)
    a = th + phi[t]
    nx, ny = -np.sin(a), np.cos(a)
    d = P[i] - C[t]
    w = w / np.maximum(np.einsum("kj,kj->k", d, d), _MIN_RANGE**2)
    rhs = nx * C[t, 0] + ny * C[t, 1]
    A11, A12, A22 = scatter_sum(i, w * nx * nx, m), scatter_sum(i, w * nx * ny, m), scatter_sum(i, w * ny * ny, m)
    b1, b2 = scatter_sum(i, w * nx * rhs, m), scatter_sum(i, w * ny * rhs, m)
    det = A11 * A22 - A12 * A12
    safe = np.where(det > 0, det, 1.0)
    Q = np.column_stack([(A22 * b1 - A12 * b2) / safe, (A11 * b2 - A12 * b1) / safe])
    return np.where((det > 0)[:, None], Q, P)


def ray_spread(phi, obs, used, m):
    """Per object, the smallest over the largest eigenvalue of its rays' (unweighted) normal
    matrix: 0 for parallel rays, 1 for rays in every direction."""
    t, i, th = obs
    a = th + phi[t]
    nx, ny = -np.sin(a) * used, np.cos(a) * used
    A11, A12, A22 = scatter_sum(i, nx * nx, m), scatter_sum(i, nx * ny, m), scatter_sum(i, ny * ny, m)
    tr, det = A11 + A22, A11 * A22 - A12 * A12
    disc = np.sqrt(np.maximum(tr * tr / 4 - det, 0.0))
    return np.where(tr > 0, (tr / 2 - disc) / np.maximum(tr / 2 + disc, 1e-300), 0.0)


def normal_blocks(P, C, phi, obs, w, free_index, n_free, sparse: bool = False, residuals=None):
    """The blocks of the Gauss-Newton normal equations of the joint problem (poses and free
    objects): ``U`` (N, 3, 3), ``V`` (F, 2, 2), ``Wf`` (N, 3, 2F), gradients ``g`` (N, 3) and
    ``h`` (F, 2), for weighted residuals ``w * res**2 / 2``. ``sparse``: the coupling ``Wf`` as a
    :class:`Coupling` (one block per observation) instead of the dense array. ``residuals``:
    :func:`bearing_residuals` of these poses and objects if the caller has them already."""
    t, i, _ = obs
    n = len(C)
    res, d = bearing_residuals(P, C, phi, obs) if residuals is None else residuals
    if sparse:  # one compiled pass over the observations (large problems only)
        return _sparse_normal_blocks(res, d, w, t, free_index[i], n, n_free)
    a = pose_jacobian(d)
    U = scatter_sum(t, w[:, None, None] * a[:, :, None] * a[:, None, :], n)
    g = scatter_sum(t, (w * res)[:, None] * a, n)
    f = free_index[i]
    k = np.flatnonzero(f >= 0)
    tf, ff, wf, af, bf = t[k], f[k], w[k], a[k], -a[k, :2]
    V = scatter_sum(ff, wf[:, None, None] * bf[:, :, None] * bf[:, None, :], n_free)
    h = scatter_sum(ff, (wf * res[k])[:, None] * bf, n_free)
    Wf = np.zeros((n, 3, n_free, 2))
    Wf[tf, :, ff, :] = wf[:, None, None] * af[:, :, None] * bf[:, None, :]
    return U, V, Wf.reshape(n, 3, 2 * n_free), g, h


def _sparse_normal_blocks(res, d, w, t, f, n, n_free):
    """:func:`normal_blocks` with the coupling sparse, by the compiled loop
    :func:`mappers.viewpoints.sparse_schur_kernels.bearing_blocks` (equal to rounding)."""
    kf = int(np.count_nonzero(f >= 0))
    U, g = np.zeros((n, 3, 3)), np.zeros((n, 3))
    V, h = np.zeros((n_free, 2, 2)), np.zeros((n_free, 2))
    blocks = np.empty((kf, 3, 2))
    bstep, bfree = np.empty(kf, dtype=np.int64), np.empty(kf, dtype=np.int64)
    kernels.bearing_blocks(np.ascontiguousarray(d, dtype=np.float64),
                           np.ascontiguousarray(res, dtype=np.float64),
                           np.ascontiguousarray(w, dtype=np.float64),
                           np.ascontiguousarray(t, dtype=np.int64),
                           np.ascontiguousarray(f, dtype=np.int64), U, g, V, h, blocks, bstep, bfree)
    return U, V, Coupling(blocks, bstep, bfree, n, n_free), g, h


def joint_step(U, V, Wf, g, h, lam, solver: str = "lu", rtol: float = CG_RTOL):
    """The damped Gauss-Newton step (Levenberg-Marquardt, ``diag *= 1 + lam``) of the poses and
    the free objects, the poses eliminated per step (Schur complement on the objects): the planar
    case of :func:`schur_step` (3 pose and 2 object parameters)."""
    return schur_step(U, V, Wf, g, h, lam, solver, rtol)


def schur_step(U, V, Wf, g, h, lam, solver: str = "lu", rtol: float = CG_RTOL):
    """The damped Gauss-Newton step (Levenberg-Marquardt, ``diag *= 1 + lam``) of the poses and
    the free objects, each pose's block eliminated (Schur complement on the objects), for any
    number of pose parameters ``p`` and object coordinates ``d``: ``U`` (N, p, p), ``V`` (F, d, d),
    ``Wf`` (N, p, d F), ``g`` (N, p), ``h`` (F, d). Returns the pose steps (N, p) and the object
    steps (F, d). The planar adjustments use p = 3, d = 2; the 3-D ones
    (:mod:`mappers.spatial`) p = 6, d = 3. ``Wf`` a :class:`Coupling`: the sparse step
    (:func:`sparse_schur_step`, with ``solver``), for problems whose dense coupling would not
    fit (:func:`use_sparse_coupling`; ``rtol`` its conjugate gradients' relative residual)."""
    if isinstance(Wf, Coupling):
        return sparse_schur_step(U, V, Wf, g, h, lam, solver, rtol)
    n, p = U.shape[:2]
    f, d = V.shape[:2]
    diag = np.arange(p)
    U = U.copy()
    U[:, diag, diag] *= 1.0 + lam
    U[:, diag, diag] += 1e-12
    Ui = np.linalg.inv(U)
    S = np.zeros((d * f, d * f))
    idx = np.arange(f)
    for r in range(d):
        for c in range(d):
            S[d * idx + r, d * idx + c] = V[:, r, c] * (1.0 + lam if r == c else 1.0)
    Y = Ui @ Wf  # (N, p, dF)
    S -= Wf.reshape(p * n, -1).T @ Y.reshape(p * n, -1)
    Uig = np.einsum("nij,nj->ni", Ui, g)
    rhs = -h.reshape(-1) + Wf.reshape(p * n, -1).T @ Uig.reshape(-1)
    dp = np.linalg.solve(S + 1e-12 * np.eye(d * f), rhs)
    dc = -Uig - Y @ dp
    return dc, dp.reshape(f, d)


@dataclass(frozen=True)
class Damping:
    """A Levenberg-Marquardt damping rule (Marquardt 1963; Nocedal & Wright, *Numerical
    Optimization*, 2006, section 10.3): a step that does not lower the cost is retried with the
    damping ``lam`` multiplied by ``up``, at most ``tries`` times (None: no limit) and while
    ``lam`` is below ``ceiling`` (None: no ceiling); an accepted step divides it by ``down``, no
    lower than ``floor``. ``accept_equal``: a step that leaves the cost equal is accepted (else
    it must fall). Each adjustment keeps the rule it was tuned with."""

    up: float = 10.0
    down: float = 10.0
    floor: float = 1e-9
    tries: int | None = 12
    ceiling: float | None = None
    accept_equal: bool = True

    def __post_init__(self) -> None:
        if not (self.up > 1.0 and self.down >= 1.0 and self.floor >= 0.0):
            raise ValueError(f"a damping rule needs up > 1, down >= 1, floor >= 0, got {self}")
        if self.tries is not None and self.tries < 1:
            raise ValueError(f"a damping rule needs tries >= 1 or None, got {self.tries}")


def damped_step(try_step: Callable[[float], tuple[Any, float]], current: float, lam: float,
                rule: Damping) -> tuple[Any, float, float, bool]:
    """One Levenberg-Marquardt step under the damping ``rule``, the one driver of the
    viewpoint adjustments' loops: ``try_step(lam)`` returns a trial state and its cost; it is
    called with ``lam`` raised by the rule until the cost is finite and falls below ``current``
    (or equals it, ``rule.accept_equal``). Returns ``(trial, cost, lam, accepted)``: the
    accepted trial, its cost and the lowered damping; or, when no try was accepted,
    ``(None, current, lam, False)`` with the raised damping."""
    tries = 0
    while ((rule.tries is None or tries < rule.tries)
           and (rule.ceiling is None or lam < rule.ceiling)):
        trial, new = try_step(lam)
        if np.isfinite(new) and (new <= current if rule.accept_equal else new < current):
            return trial, new, max(lam / rule.down, rule.floor), True
        lam *= rule.up
        tries += 1
    return None, current, lam, False
