"""A joint adjustment of tags and viewpoints under the frustum likelihood and the walk prior.

FRUSTUM-BA's joint rounds (:meth:`mappers.spatial.frustum.FrustumProblem.joint`) move tags and
viewpoints together with the steps independent of one another; on a walk's history they let the
viewpoints drift from the walk (``docs/dead-ends.md``, "Camera3D sightings"). Here the walk prior
of FRUSTUM-BA-WALK (:mod:`mappers.spatial.frustum_walk`: a Gaussian random walk of width
``step_sigma`` [m] per axis and ``turn_sigma`` [rad] in heading per step, a motion prior, not
odometry) enters the adjustment as quadratic terms on consecutive viewpoints' differences,

    cost = frustum loss(P, C) + 1/2 sum_t [ (dx_t / step_sigma)^2 + (dy_t / step_sigma)^2
                                            + (wrap(dtheta_t) / turn_sigma)^2 ],

``d._t`` the difference of viewpoints ``t + 1`` and ``t`` (the heading's wrapped to
``[-pi, pi)``). Its minimum is the maximum a posteriori map and walk of the same model whose
posterior means the walk search returns on a grid. That point is a shrunk walk (the prior's cost
falls with the walk's scale), so FRUSTUM-BA-WALK runs a few rounds from the walk search's means
rather than to convergence (``docs/dead-ends.md``, "Camera3D sightings").

The viewpoints' block of the Gauss-Newton normal equations becomes block-tridiagonal (3 x 3
blocks: a step is linked to its neighbours), a band of half-width 5 in the 3N unknowns. Each
Levenberg-Marquardt round eliminates the viewpoints through that band's Cholesky factor
(``scipy.linalg.cholesky_banded`` / ``cho_solve_banded``: O(N) for the 3F + 1 right-hand sides)
and solves the small dense (3F x 3F) Schur complement of the free tags (Triggs et al., *Bundle
Adjustment — A Modern Synthesis*, 2000, section 6; Golub & Van Loan, *Matrix Computations*,
section 4.3, for banded Cholesky). It is written here because :mod:`mappers.viewpoints`' Schur
engine (``schur_step``) inverts each viewpoint's block on its own: it has no term linking
steps. The damping driver is that engine's (:func:`mappers.viewpoints.damped_step`, with
FRUSTUM-BA's rule).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import LinAlgError, cho_solve_banded, cholesky_banded

from mappers.spatial.frustum import DAMPING, FrustumProblem
from mappers.viewpoints import damped_step

__all__ = ["WalkPrior", "walk_joint_steps"]

_BAND = 5
"""Half-bandwidth of the viewpoints' block-tridiagonal system in its 3N unknowns."""


def _wrap(a: np.ndarray) -> np.ndarray:
    """Angles wrapped to ``[-pi, pi)``."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class WalkPrior:
    """The walk prior's quadratic cost on a walk's viewpoints ``C`` (N, 3: x, y, heading), the
    steps in walk order: width ``step_sigma`` [m] per axis and ``turn_sigma`` [rad] in heading
    per step (the module's docstring)."""

    def __init__(self, step_sigma: float, turn_sigma: float) -> None:
        for name, value in (("step_sigma", step_sigma), ("turn_sigma", turn_sigma)):
            if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value)
                    and value > 0):
                raise ValueError(f"the walk prior needs {name} > 0 and finite, got {value!r}")
        self.step_sigma, self.turn_sigma = float(step_sigma), float(turn_sigma)
        self.weights = np.array([step_sigma**-2, step_sigma**-2, turn_sigma**-2])
        """The precisions of a step's (dx, dy, dtheta)."""

    def _diffs(self, C: np.ndarray) -> np.ndarray:
        d = np.diff(C, axis=0)
        d[:, 2] = _wrap(d[:, 2])
        return d

    def cost(self, C) -> float:
        """``1/2 sum_t d_t^T diag(weights) d_t`` over consecutive viewpoints."""
        C = np.asarray(C, dtype=float)
        return 0.5 * float(np.sum(self._diffs(C) ** 2 * self.weights))

    def gradient(self, C) -> np.ndarray:
        """(N, 3): the cost's gradient in the viewpoints."""
        C = np.asarray(C, dtype=float)
        wd = self._diffs(C) * self.weights
        g = np.zeros_like(C)
        g[:-1] -= wd
        g[1:] += wd
        return g

    def add_to_band(self, ab: np.ndarray) -> None:
        """Add the cost's Hessian (constant: the wrap is locally the identity) into ``ab``, the
        upper band (``scipy.linalg.cholesky_banded``'s layout, half-width 5) of a 3N x 3N
        matrix ordered ``(x_0, y_0, theta_0, x_1, ...)``."""
        n = ab.shape[1] // 3
        if n < 2:
            return
        links = np.full(n, 2.0)
        links[[0, -1]] = 1.0
        ab[_BAND] += (links[:, None] * self.weights[None, :]).reshape(-1)
        # entry (3t + r, 3(t + 1) + r) = -w_r lies 3 above the diagonal: row _BAND - 3 of the band
        ab[_BAND - 3, 3:] -= np.tile(self.weights, n - 1)


def _viewpoint_band(U: np.ndarray, prior: WalkPrior, lam: float) -> np.ndarray:
    """The damped viewpoints' matrix ``blockdiag(U) + prior Hessian``, its diagonal times
    ``1 + lam`` plus 1e-9 (Levenberg-Marquardt), as the upper band of half-width 5."""
    n = U.shape[0]
    ab = np.zeros((_BAND + 1, 3 * n))
    for r in range(3):
        for c in range(r, 3):
            ab[_BAND + r - c, c::3] = U[:, r, c]
    prior.add_to_band(ab)
    ab[_BAND] = ab[_BAND] * (1.0 + lam) + 1e-9
    return ab


def walk_schur_step(U, V, W, g, h, lam: float, prior: WalkPrior):
    """The damped Gauss-Newton step ``(dc (N, 3), dp (F, 3))`` of viewpoints and free tags
    under the frustum blocks (``U`` (N, 3, 3), ``V`` (F, 3, 3), ``W`` (N, 3, 3F), ``g`` (N, 3),
    ``h`` (F, 3): :meth:`FrustumProblem.blocks`) plus the walk prior (its gradient must be in
    ``g`` already): the viewpoints eliminated through the banded Cholesky factor (the module's
    docstring). Raises ``numpy.linalg.LinAlgError`` if the damped system is not positive
    definite."""
    n, f = U.shape[0], V.shape[0]
    chol = cholesky_banded(_viewpoint_band(U, prior, lam))
    Wf = W.reshape(3 * n, 3 * f)
    X = cho_solve_banded((chol, False), np.column_stack([Wf, g.reshape(-1)]))
    XW, Xg = X[:, :-1], X[:, -1]
    S = np.zeros((3 * f, 3 * f))
    idx = np.arange(f)
    for r in range(3):
        for c in range(3):
            S[3 * idx + r, 3 * idx + c] = V[:, r, c] * (1.0 + lam if r == c else 1.0)
    S -= Wf.T @ XW
    S[np.diag_indices_from(S)] += 1e-9
    dp = np.linalg.solve(S, -h.reshape(-1) + Wf.T @ Xg)
    dc = -Xg - XW @ dp
    return dc.reshape(n, 3), dp.reshape(f, 3)


def walk_joint_steps(problem: FrustumProblem, P, C, rounds: int, prior: WalkPrior):
    """``(P, C, loss)`` after up to ``rounds`` joint Levenberg-Marquardt rounds of the free tags
    (``problem.free_index``; the others held) and the viewpoints ``C`` (N, 3, the steps in walk
    order) on the frustum loss of ``problem`` plus ``prior``'s cost; ``loss`` is the frustum
    loss alone (what FRUSTUM-BA's guard compares). A round whose every damping fails stops."""
    if not (isinstance(rounds, (int, np.integer)) and rounds >= 0):
        raise ValueError(f"rounds must be an integer >= 0, got {rounds!r}")
    P = np.asarray(P, dtype=float)
    C = np.asarray(C, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or C.ndim != 2 or C.shape[1] != 3:
        raise ValueError(f"P must be (M, 3) and C (N, 3), got {P.shape} and {C.shape}")
    if C.shape[0] != problem.seen.shape[0] or P.shape[0] != problem.seen.shape[1]:
        raise ValueError(f"the sightings are {problem.seen.shape} (steps, objects); P is "
                         f"{P.shape} and C {C.shape}")
    free = problem.free_index >= 0

    def total(P2, C2):
        return problem.cost(P2, C2) + prior.cost(C2)

    cost, lam = total(P, C), 1e-2
    for _ in range(rounds):
        _, U, V, W, g, h = problem.blocks(P, C)
        g = g + prior.gradient(C)

        def trial(lam, U=U, V=V, W=W, g=g, h=h, P=P, C=C):
            try:
                dc, dp = walk_schur_step(U, V, W, g, h, lam, prior)
            except (LinAlgError, np.linalg.LinAlgError):
                return None, math.inf  # not positive definite at this damping: raise it
            P2 = P.copy()
            P2[free] += dp
            C2 = C + dc
            return (P2, C2), total(P2, C2)

        state, cost, lam, moved = damped_step(trial, cost, lam, DAMPING)
        if not moved:
            break
        P, C = state
    return P, C, problem.cost(P, C)
