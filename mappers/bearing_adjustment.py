"""Bearing-only bundle adjustment of a bearing map (label ``"BEARING-BA"``).

The paper's methods, and every other mapper here, never estimate where the robot was. This one
does: it starts from the map the bearing default drew before it (``start``: CAL-SMA for a
complete history, ``covis-auto`` for a masked one) and refines it by treating each step's
viewpoint as a latent pose ``(x, y, heading)``:

1. *resection* of the start map: each step's pose from the bearings of the objects it observed,
   the objects where the start map puts them, in closed form (linear in ``cos``, ``sin`` of the
   heading and the rotated viewpoint; one 4 x 4 eigenproblem per step), then Gauss-Newton on
   the wrapped angle residuals (one 3 x 3 system per step, batched); a step that observed fewer
   than ``min_step_objects`` objects, or whose system is ill-conditioned, is left out;
2. *adjustment* (``solver="joint"``, the default): Levenberg-Marquardt on the poses and the
   non-anchor objects together, each step's 3 pose unknowns eliminated (Schur complement) so
   the system solved is the objects' 2F x 2F one; the anchors stay at their known positions,
   which fix the gauge (shift, rotation, scale). ``solver="alternate"`` instead alternates the
   resection with an *intersection*, each object from its rays (linear least squares on the
   perpendicular offsets over the range, a 2 x 2 system per object): simpler, but it converges
   linearly (docs/imperfect-sensing.md has the figures);
3. *robust weights*: Huber (or Cauchy) weights on the angle residuals, renewed at every step,
   the scale read from the start's residuals (their median absolute value), so 30 degrees of
   noise or a wrong reading does not dominate;

for at most ``max_rounds`` rounds, or until no object moves more than ``tol`` [m] or the cost
stops falling.

Guards: an object seen from fewer than ``min_views`` usable steps, or from nearly parallel rays
(the smallest to largest eigenvalue of its rays' normal matrix below ``min_spread``), keeps its
start position, and its bearings are left out (the start is not to be trusted); a viewpoint that
drifts beyond the map's bounding box widened by its size on every side (three objects nearly in
line leave a pose free to run away) leaves the problem; if the refined solution's robust angle
cost is above the start's (with the start's poses resected, over the same readings), or anything
is not finite, the start map is returned. Each case is a :class:`BearingAdjustmentWarning`
(``build_map`` lists them in ``Map.warnings``).

*Assumes*: the bearings of one step are taken from one viewpoint and are relative to the robot's
heading at that step (one unknown heading per step, no calibration offset); a static world;
bearings to the objects' centres. No motion model and no odometry: the steps are independent
viewpoints, found from the history alone.
"""

from __future__ import annotations

import warnings
from numbers import Integral, Real

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval, StrOptions

from mappers.adjustment import anchored_start, keep_if_better
from mappers.registry import MethodSpec

__all__ = ["BearingAdjustment", "BearingAdjustmentWarning", "bearing_angles"]

_UNIT_TOL = 1e-3
"""How far an observed (cos, sin) pair's norm may be from 1 (float32 storage, rounding)."""

_MIN_RANGE = 0.05
"""Smallest range [m] in the angle weights of the alternating intersection (an object at the
viewpoint)."""


class BearingAdjustmentWarning(UserWarning):
    """The refinement kept (part of) the start map: too few views, parallel rays, no gain."""


def _wrap(a: np.ndarray) -> np.ndarray:
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


def _robust(res: np.ndarray, scale: float, loss: str | None) -> np.ndarray:
    """IRLS weights of the residuals for the loss (1 inside the scale)."""
    if loss is None:
        return np.ones_like(res)
    u = np.abs(res) / scale
    if loss == "huber":
        return np.where(u <= 1.0, 1.0, 1.0 / np.maximum(u, 1e-300))
    return 1.0 / (1.0 + u * u)  # cauchy


def _rho(res: np.ndarray, scale: float, loss: str | None) -> np.ndarray:
    """The loss of each residual (least squares: ``res**2 / 2``)."""
    if loss is None:
        return 0.5 * res * res
    u = np.abs(res) / scale
    if loss == "huber":
        return scale * scale * np.where(u <= 1.0, 0.5 * u * u, u - 0.5)
    return 0.5 * scale * scale * np.log1p(u * u)


def _sum(idx: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Per index, the sum of ``values`` (K,) or (K, ...) over the observations with that index."""
    if values.ndim == 1:
        return np.bincount(idx, weights=values, minlength=n)
    flat = values.reshape(len(values), -1)
    out = np.stack([np.bincount(idx, weights=flat[:, k], minlength=n) for k in range(flat.shape[1])],
                   axis=1)
    return out.reshape((n, *values.shape[1:]))


def _residuals(P, C, phi, obs):
    """Angle residuals (K,) of the observations ``obs = (t, i, theta)`` and the offsets object -
    viewpoint (K, 2)."""
    t, i, th = obs
    d = P[i] - C[t]
    return _wrap(np.arctan2(d[:, 1], d[:, 0]) - phi[t] - th), d


def _pose_jacobian(d):
    """d residual / d (x, y, heading) of the viewpoint, (K, 3); the object's is minus the first two."""
    r2 = np.maximum(np.einsum("kj,kj->k", d, d), 1e-12)
    return np.column_stack([d[:, 1] / r2, -d[:, 0] / r2, -np.ones_like(r2)])


def _initial_poses(P, obs, n):
    """Each step's pose from the start map in closed form. In the robot's frame an object is at
    ``e = R(phi)^T p - s`` with ``s = R(phi)^T c``, and its bearing ``v`` is parallel to ``e``:
    ``a (p x v) + b (p . v) - s1 v_y + s2 v_x = 0`` with ``(a, b) = (cos phi, sin phi)``, linear
    in ``(a, b, s1, s2)``; the least-squares solution is the normal matrix's eigenvector of the
    smallest eigenvalue, scaled to ``a^2 + b^2 = 1`` and signed so that the objects lie ahead
    along their rays. Returns the poses and which steps gave one."""
    t, i, th = obs
    vx, vy = np.cos(th), np.sin(th)
    px, py = P[i, 0], P[i, 1]
    rows = np.column_stack([px * vy - py * vx, py * vy + px * vx, -vy, vx])
    A = _sum(t, rows[:, :, None] * rows[:, None, :], n)
    ev, vec = np.linalg.eigh(A)
    z = vec[:, :, 0]
    norm = np.hypot(z[:, 0], z[:, 1])
    ok = (norm > 1e-9) & (ev[:, 1] > 1e-12 * np.maximum(ev[:, -1], 1e-300))
    z = z / np.where(ok, norm, 1.0)[:, None]
    ahead = _sum(t, (rows[:, 1] * z[t, 0] - rows[:, 0] * z[t, 1]  # e . v = (R^T p - s) . v
                     - z[t, 2] * vx - z[t, 3] * vy), n)
    z *= np.where(ahead < 0, -1.0, 1.0)[:, None]
    phi = np.arctan2(z[:, 1], z[:, 0])
    C = np.column_stack([z[:, 0] * z[:, 2] - z[:, 1] * z[:, 3], z[:, 1] * z[:, 2] + z[:, 0] * z[:, 3]])
    return C, phi, ok


def _resect(P, C, phi, obs, w, iters: int):
    """Gauss-Newton on each step's pose (batched 3 x 3 systems), the objects fixed; returns the
    poses and which steps have a well-conditioned system."""
    n, t = len(C), obs[0]
    ok = np.ones(n, dtype=bool)
    for _ in range(iters):
        res, d = _residuals(P, C, phi, obs)
        a = _pose_jacobian(d)
        H = _sum(t, w[:, None, None] * a[:, :, None] * a[:, None, :], n)
        g = _sum(t, (w * res)[:, None] * a, n)
        ev = np.linalg.eigvalsh(H)
        ok = ev[:, 0] > 1e-8 * np.maximum(ev[:, -1], 1e-300)
        H[~ok] = np.eye(3)
        step = -np.linalg.solve(H, g[..., None])[..., 0]
        step[~ok] = 0.0
        step[:, 2] = np.clip(step[:, 2], -0.5, 0.5)
        C = C + step[:, :2]
        phi = _wrap(phi + step[:, 2])
    return C, phi, ok


def _intersect(P, C, phi, obs, w):
    """Each object's least-squares point of its rays' lines, the perpendicular offsets divided by
    the current range (the angle residuals to first order); returns the points (M, 2)."""
    t, i, th = obs
    m = len(P)
    a = th + phi[t]
    nx, ny = -np.sin(a), np.cos(a)
    d = P[i] - C[t]
    w = w / np.maximum(np.einsum("kj,kj->k", d, d), _MIN_RANGE**2)
    rhs = nx * C[t, 0] + ny * C[t, 1]
    A11, A12, A22 = _sum(i, w * nx * nx, m), _sum(i, w * nx * ny, m), _sum(i, w * ny * ny, m)
    b1, b2 = _sum(i, w * nx * rhs, m), _sum(i, w * ny * rhs, m)
    det = A11 * A22 - A12 * A12
    safe = np.where(det > 0, det, 1.0)
    Q = np.column_stack([(A22 * b1 - A12 * b2) / safe, (A11 * b2 - A12 * b1) / safe])
    return np.where((det > 0)[:, None], Q, P)


def _spread(phi, obs, used, m):
    """Per object, the smallest over the largest eigenvalue of its rays' (unweighted) normal
    matrix: 0 for parallel rays, 1 for rays in every direction."""
    t, i, th = obs
    a = th + phi[t]
    nx, ny = -np.sin(a) * used, np.cos(a) * used
    A11, A12, A22 = _sum(i, nx * nx, m), _sum(i, nx * ny, m), _sum(i, ny * ny, m)
    tr, det = A11 + A22, A11 * A22 - A12 * A12
    disc = np.sqrt(np.maximum(tr * tr / 4 - det, 0.0))
    return np.where(tr > 0, (tr / 2 - disc) / np.maximum(tr / 2 + disc, 1e-300), 0.0)


def _normal_blocks(P, C, phi, obs, w, free_index, n_free):
    """The blocks of the Gauss-Newton normal equations of the joint problem (poses and free
    objects): ``U`` (N, 3, 3), ``V`` (F, 2, 2), ``Wf`` (N, 3, 2F), gradients ``g`` (N, 3) and
    ``h`` (F, 2), for weighted residuals ``w * res**2 / 2``."""
    t, i, _ = obs
    n = len(C)
    res, d = _residuals(P, C, phi, obs)
    a = _pose_jacobian(d)
    U = _sum(t, w[:, None, None] * a[:, :, None] * a[:, None, :], n)
    g = _sum(t, (w * res)[:, None] * a, n)
    f = free_index[i]
    k = np.flatnonzero(f >= 0)
    tf, ff, wf, af, bf = t[k], f[k], w[k], a[k], -a[k, :2]
    V = _sum(ff, wf[:, None, None] * bf[:, :, None] * bf[:, None, :], n_free)
    h = _sum(ff, (wf * res[k])[:, None] * bf, n_free)
    Wf = np.zeros((n, 3, n_free, 2))
    Wf[tf, :, ff, :] = wf[:, None, None] * af[:, :, None] * bf[:, None, :]
    return U, V, Wf.reshape(n, 3, 2 * n_free), g, h


def _joint_step(U, V, Wf, g, h, lam):
    """The damped Gauss-Newton step (Levenberg-Marquardt, ``diag *= 1 + lam``) of the poses and
    the free objects, the poses eliminated per step (Schur complement on the objects)."""
    n, f = len(U), len(V)
    U = U.copy()
    U[:, [0, 1, 2], [0, 1, 2]] *= 1.0 + lam
    U[:, [0, 1, 2], [0, 1, 2]] += 1e-12
    Ui = np.linalg.inv(U)
    S = np.zeros((2 * f, 2 * f))
    idx = np.arange(f)
    for r in range(2):
        for c in range(2):
            S[2 * idx + r, 2 * idx + c] = V[:, r, c] * (1.0 + lam if r == c else 1.0)
    Y = Ui @ Wf  # (N, 3, 2F)
    S -= Wf.reshape(3 * n, -1).T @ Y.reshape(3 * n, -1)
    Uig = np.einsum("nij,nj->ni", Ui, g)
    rhs = -h.reshape(-1) + Wf.reshape(3 * n, -1).T @ Uig.reshape(-1)
    dp = np.linalg.solve(S + 1e-12 * np.eye(2 * f), rhs)
    dc = -Uig - Y @ dp
    return dc, dp.reshape(f, 2)


class BearingAdjustment(TransformerMixin, BaseEstimator):
    """Refine a bearing map by estimating each step's viewpoint (module docstring).

    Parameters:
        start: label of the method that draws the start map (None: the bearing default before
            this method, CAL-SMA for a complete history and ``covis-auto`` for a masked one).
        loss: ``"huber"``, ``"cauchy"`` or None (least squares) on the angle residuals.
        robust_scale: the loss's scale in robust standard deviations of the residuals (1.4826
            times their median absolute value).
        max_rounds: rounds (Levenberg-Marquardt steps, or resection and intersection) at most.
        tol: stop when no object moves more than this [m].
        pose_iters: Gauss-Newton iterations of the resection per round (``"alternate"``).
        min_step_objects: a step that observed fewer objects gives no pose (3 unknowns).
        min_views: an object observed from fewer usable steps keeps its start position.
        min_spread: an object whose rays' normal matrix has a smaller eigenvalue ratio (nearly
            parallel rays) keeps its start position.
        solver: ``"joint"`` (Levenberg-Marquardt on poses and objects) or ``"alternate"``.
        random_state: handed to the start method.

    Attributes:
        embedding_ (M, 2) in world coordinates; start_ the start map; poses_ (N, 3) the
        estimated viewpoints (NaN rows: steps left out); kept_ indices of non-anchor objects
        that kept their start; n_rounds_, cost_, start_cost_ (robust angle cost, start's scale);
        refined_ whether the refinement was kept; scale_ the robust loss's scale [rad] (read from
        the start's residuals).
    """

    _parameter_constraints: dict = {
        "start": [str, None],
        "loss": [StrOptions({"huber", "cauchy"}), None],
        "robust_scale": [Interval(Real, 0, None, closed="neither")],
        "max_rounds": [Interval(Integral, 1, None, closed="left")],
        "tol": [Interval(Real, 0, None, closed="left")],
        "pose_iters": [Interval(Integral, 1, None, closed="left")],
        "min_step_objects": [Interval(Integral, 3, None, closed="left")],
        "min_views": [Interval(Integral, 2, None, closed="left")],
        "min_spread": [Interval(Real, 0, 1, closed="both")],
        "solver": [StrOptions({"joint", "alternate"})],
        "random_state": ["random_state"],
    }

    def __init__(self, *, start: str | None = None, loss: str | None = "huber",
                 robust_scale: float = 2.0, max_rounds: int = 6, tol: float = 1e-7,
                 pose_iters: int = 2, min_step_objects: int = 3, min_views: int = 5,
                 min_spread: float = 1e-3, solver: str = "joint", random_state=0) -> None:
        self.start = start
        self.loss = loss
        self.robust_scale = robust_scale
        self.max_rounds = max_rounds
        self.tol = tol
        self.pose_iters = pose_iters
        self.min_step_objects = min_step_objects
        self.min_views = min_views
        self.min_spread = min_spread
        self.solver = solver
        self.random_state = random_state

    def _start_map(self, X, mask, ids, pos) -> np.ndarray:
        from mappers.pipeline import build_map  # the pipeline imports the registry

        masked = mask is not None and not np.all(mask)
        label = self.start or ("covis-auto" if masked else "CAL-SMA")
        if label.strip().upper() == "BEARING-BA":
            raise ValueError("start must name another method than 'BEARING-BA'")
        m = build_map(X, ids, pos, label, sensor="bearing", mask=mask if masked else None,
                      random_state=self.random_state)
        for note in m.warnings:
            warnings.warn(f"start map ({m.method}): {note}", BearingAdjustmentWarning, stacklevel=3)
        return m.positions

    def fit(self, X, y=None, *, mask=None, sensor: str = "bearing", anchor_ids=None,
            anchor_positions=None, start_positions=None):
        """Map the bearing history ``X`` ((M, 2N), unit (cos, sin) per step; ``mask`` True where
        observed) with the anchors (rows of X) held at their positions. ``start_positions``
        ((M, 2), NaN rows: not placed) replaces the start method's map."""
        self._validate_params()
        if sensor != "bearing":
            raise ValueError(f"BEARING-BA maps bearing histories, got a {sensor} history")
        theta, seen = bearing_angles(X, mask)
        m = theta.shape[1]
        ids, pos, P0 = anchored_start(
            "BEARING-BA", anchor_ids, anchor_positions, m, start_positions,
            lambda ids, pos: self._start_map(X, mask, ids, pos),
        )
        self.start_ = P0.copy()
        self.embedding_ = self._refine(theta, seen, P0, ids)
        return self

    def _refine(self, theta, seen, P0, ids) -> np.ndarray:
        n, m = theta.shape
        placed = np.all(np.isfinite(P0), axis=1)
        free = placed.copy()
        free[ids] = False
        seen = seen & placed[None, :]
        seen &= (seen.sum(1) >= self.min_step_objects)[:, None]
        t, i = np.nonzero(seen)
        obs = (t, i, theta[t, i])
        P = np.where(placed[:, None], P0, 0.0)
        self.kept_ = np.array([], dtype=int)
        C, phi, ok0 = _initial_poses(P, obs, n)
        C, phi, ok = _resect(P, C, phi, obs, np.ones(len(t)), 3)
        ok &= ok0
        lo, hi = P[placed].min(0), P[placed].max(0)
        self._box = (lo - (hi - lo).max(), hi + (hi - lo).max())
        ok &= self._inside(C)
        wb = ok[t].astype(float)  # steps whose pose the start map pins down
        res, _ = _residuals(P, C, phi, obs)
        used = wb > 0
        scale = self.robust_scale * 1.4826 * max(
            float(np.median(np.abs(res[used]))) if used.any() else 0.0, 1e-9)
        start_rho = _rho(res, scale, self.loss)
        self.scale_ = scale
        # objects the usable steps do not pin down keep their start
        views = _sum(i, wb, m)
        weak = free & ((views < self.min_views) | (_spread(phi, obs, wb, m) < self.min_spread))
        if weak.any():
            self.kept_ = np.flatnonzero(weak)
            warnings.warn(f"objects {self.kept_.tolist()} are seen from too few steps or along "
                          "nearly parallel rays: they keep the start map's positions",
                          BearingAdjustmentWarning, stacklevel=3)
        free &= ~weak
        if weak.any():  # their start is not to be trusted: their bearings leave the problem
            wb = wb * ~weak[i]
            wb = wb * (_sum(t, wb, n) >= self.min_step_objects)[t]
        if self.solver == "joint":
            P, C, phi, wb, rounds = self._joint(P, C, phi, obs, wb, free, scale)
            ok = np.zeros(n, dtype=bool)
            ok[t[wb > 0]] = True
        else:
            P, C, phi, wb, ok, rounds = self._alternate(P, C, phi, obs, wb, free, scale)
        res, _ = _residuals(P, C, phi, obs)
        self.cost_ = float(np.sum(wb * _rho(res, scale, self.loss)))
        self.start_cost_ = float(np.sum(wb * start_rho))  # the same readings, start's poses
        self.n_rounds_ = rounds
        self.poses_ = np.where(ok[:, None], np.column_stack([C, phi]), np.nan)
        self.refined_, out = keep_if_better(P, P0, placed, self.cost_, self.start_cost_,
                                            "bearings", BearingAdjustmentWarning)
        return out

    def _inside(self, C):
        """Viewpoints within the map's bounding box widened by its size on every side: a pose
        beyond drifted along a degenerate direction (three objects nearly in line)."""
        return np.all((C >= self._box[0]) & (C <= self._box[1]), axis=1)

    def _alternate(self, P, C, phi, obs, wb, free, scale):
        """Resection and intersection in turn (see the module docstring)."""
        rounds, ok, t = 0, wb > 0, obs[0]
        for rounds in range(1, self.max_rounds + 1):  # noqa: B007 - the count is returned
            res, _ = _residuals(P, C, phi, obs)
            w = wb * _robust(res, scale, self.loss)
            Q = _intersect(P, C, phi, obs, w)
            move = np.abs(Q[free] - P[free]).max() if free.any() else 0.0
            P[free] = Q[free]
            C, phi, ok_steps = _resect(P, C, phi, obs, w, self.pose_iters)
            ok = ok_steps & self._inside(C)
            wb = wb * ok[t]
            if move <= self.tol:
                break
        return P, C, phi, wb, ok, rounds

    def _joint(self, P, C, phi, obs, wb, free, scale):
        """Levenberg-Marquardt on the poses and the free objects together, robust weights
        renewed at every step (IRLS), the poses eliminated per step (Schur complement)."""

        def cost(P, C, phi):
            return float(np.sum(wb * _rho(_residuals(P, C, phi, obs)[0], scale, self.loss)))

        free_index = np.full(len(P), -1)
        free_index[free] = np.arange(free.sum())
        lam, current, rounds = 1e-4, cost(P, C, phi), 0
        for rounds in range(1, self.max_rounds + 1):  # noqa: B007 - the count is returned
            res, _ = _residuals(P, C, phi, obs)
            blocks = _normal_blocks(P, C, phi, obs, wb * _robust(res, scale, self.loss),
                                    free_index, int(free.sum()))
            for _ in range(12):
                dc, dp = _joint_step(*blocks, lam)
                P2 = P.copy()
                P2[free] += dp
                C2, phi2 = C + dc[:, :2], _wrap(phi + dc[:, 2])
                new = cost(P2, C2, phi2)
                if np.isfinite(new) and new <= current:
                    break
                lam *= 10.0
            else:
                break  # no step lowers the cost: converged (or stuck)
            P, C, phi, lam = P2, C2, phi2, max(lam / 10.0, 1e-9)
            done = current - new <= 1e-6 * current or not dp.size or np.abs(dp).max() <= self.tol
            current = new
            out = ~self._inside(C)
            if out.any():  # drifting viewpoints leave the problem
                wb = wb * ~out[obs[0]]
                current = cost(P, C, phi)
                done = False
            if done:
                break
        return P, C, phi, wb, rounds

    def fit_transform(self, X, y=None, *, mask=None, sensor: str = "bearing", anchor_ids=None,
                      anchor_positions=None, start_positions=None):
        """Fit and return the (M, 2) map in world coordinates (NaN rows: not placed)."""
        return self.fit(X, mask=mask, sensor=sensor, anchor_ids=anchor_ids,
                        anchor_positions=anchor_positions,
                        start_positions=start_positions).embedding_


def _bearing_ba(*, start=None, loss="huber", robust_scale=2.0, max_rounds=6, tol=1e-7,
                pose_iters=2, min_step_objects=3, min_views=5, min_spread=1e-3,
                solver="joint", random_state=0) -> BearingAdjustment:
    return BearingAdjustment(start=start, loss=loss, robust_scale=robust_scale,
                             max_rounds=max_rounds, tol=tol, pose_iters=pose_iters,
                             min_step_objects=min_step_objects, min_views=min_views,
                             min_spread=min_spread, solver=solver, random_state=random_state)


SPEC = MethodSpec(
    "BEARING-BA",
    _bearing_ba,
    {},
    {},  # the defaults were chosen on tuning layouts (docs/imperfect-sensing.md): no sweep
    "the bearing default's map refined by estimating the viewpoints (bearing-only bundle "
    "adjustment), anchors fixed",
    uses_anchors=True,
    sensors=("bearing",),
    normalize=False,
    histories=("complete", "masked"),
)
