"""The Schur-complement step of a bundle adjustment with the pose-object coupling kept sparse.

The dense step (:func:`mappers.viewpoints.engine.schur_step` given an array) holds the coupling
of every pose with every free object, ``Wf`` of shape (N, p, d F): at N = 20,000 steps and
F = 1,000 objects that is a gigabyte, though a step sees only the few dozen objects near it.
Here the coupling is one (p, d) block per observation (:class:`Coupling`), and the reduced
system of the objects,

    S = blockdiag(V) - sum_t W_t^T U_t^-1 W_t,

is a ``scipy.sparse`` matrix (step t couples only the objects it sees), solved by a sparse LU
(:func:`scipy.sparse.linalg.spsolve`, SuperLU) or, ``solver="cg"``, by conjugate gradients on
``S`` as an operator (one compiled loop over the observations,
:mod:`mappers.viewpoints.sparse_schur_kernels`) with a block-Jacobi preconditioner (the inexact step of large bundle
adjusters: Agarwal et al., *Bundle Adjustment in the Large*, ECCV 2010; Triggs et al.,
*Bundle Adjustment — A Modern Synthesis*, 2000, for the Schur complement). It is the same step as
the dense one, summed in another order (equal to rounding; the tests compare them to 1e-9).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator, cg, spsolve

from mappers.viewpoints import sparse_schur_kernels as kernels

__all__ = ["CG_RTOL", "DENSE_COUPLING_MAX_BYTES", "Coupling", "sparse_schur_step", "use_sparse_coupling"]

DENSE_COUPLING_MAX_BYTES = 2**28
"""Largest dense coupling ``Wf`` (float64 bytes, ``8 N p d F``) the adjustments build; above it
they use the sparse step. 256 MiB: every 2-D result and benchmark of the project (at most
N = 8,000 steps with F = 200 free objects, 77 MB) stays on the dense path, bit for bit, while
the dense step's (d F, p N) products grow slower than the sparse one's beyond it."""

CG_RTOL = 1e-6
"""Relative residual at which the conjugate gradients stop by default: an inexact step (a
truncated Newton step, as Agarwal et al.'s) is all Levenberg-Marquardt needs."""


class Coupling(NamedTuple):
    """The pose-object blocks of the normal equations, one per observation of a free object:
    ``blocks`` (K, p, d) the weighted ``J_pose^T J_object`` of the observation, ``step`` (K,) its
    pose's index, ``free`` (K,) its free object's index, and the numbers of steps and of free
    objects. Several observations of one pair are summed."""

    blocks: np.ndarray
    step: np.ndarray
    free: np.ndarray
    n_steps: int
    n_free: int

    def matrix(self, values: np.ndarray | None = None) -> sp.bsr_array:
        """The (p N, d F) sparse matrix of ``values`` (default: the blocks) at the coupling's
        places (several blocks at one place summed): block sparse rows, a row of blocks per
        step, so that it is built without sorting when the observations come by step."""
        vals = self.blocks if values is None else values
        k, p, d = vals.shape
        step, free = self.step, self.free
        if np.any(np.diff(step) < 0):
            order = np.argsort(step, kind="stable")
            vals, step, free = vals[order], step[order], free[order]
        indptr = np.zeros(self.n_steps + 1, dtype=np.int64)
        np.cumsum(np.bincount(step, minlength=self.n_steps), out=indptr[1:])
        return sp.bsr_array((vals, free, indptr), shape=(p * self.n_steps, d * self.n_free))


def use_sparse_coupling(n_steps: int, p: int, d: int, n_free: int,
                        limit: float = DENSE_COUPLING_MAX_BYTES) -> bool:
    """Whether the dense coupling (``8 N p d F`` bytes) would exceed ``limit``."""
    return 8.0 * n_steps * p * d * n_free > limit


def _block_diagonal(blocks: np.ndarray) -> sp.bsr_array:
    """The block-diagonal sparse matrix of (n, a, a) blocks."""
    n, a = blocks.shape[:2]
    return sp.bsr_array((blocks, np.arange(n), np.arange(n + 1)), shape=(a * n, a * n))


def sparse_schur_step(U, V, W: Coupling, g, h, lam, solver: str = "lu", rtol: float = CG_RTOL):
    """The damped Gauss-Newton step (``diag *= 1 + lam``) of the poses and the free objects with
    the poses eliminated, as :func:`mappers.viewpoints.engine.schur_step`, from the sparse
    coupling ``W``: ``U`` (N, p, p), ``V`` (F, d, d), ``g`` (N, p), ``h`` (F, d). ``solver``:
    ``"lu"`` (exact, sparse LU of the reduced system) or ``"cg"`` (conjugate gradients with a
    block-Jacobi preconditioner to the relative residual ``rtol``, the reduced system never
    formed). Returns the pose steps (N, p) and the object steps (F, d)."""
    if solver not in ("lu", "cg"):
        raise ValueError(f"solver must be 'lu' or 'cg', got {solver!r}")
    n, p = U.shape[:2]
    f, d = V.shape[:2]
    if W.blocks.shape[1:] != (p, d) or W.n_steps != n or W.n_free != f:
        raise ValueError(f"the coupling's blocks {W.blocks.shape[1:]} and sizes ({W.n_steps}, "
                         f"{W.n_free}) do not match U {U.shape} and V {V.shape}")
    pd, dd = np.arange(p), np.arange(d)
    U = U.copy()
    U[:, pd, pd] *= 1.0 + lam
    U[:, pd, pd] += 1e-12
    Ui = np.linalg.inv(U)
    Vd = V.copy()
    Vd[:, dd, dd] *= 1.0 + lam
    Vd[:, dd, dd] += 1e-12
    if solver == "cg":
        return _cg_step(Ui, Vd, W, g, h, rtol)
    Wm, Uim, Vm = W.matrix(), _block_diagonal(Ui), _block_diagonal(Vd)
    WmT = Wm.T
    Uig = np.einsum("nij,nj->ni", Ui, g)
    rhs = -h.reshape(-1) + WmT @ Uig.reshape(-1)
    if not f:
        dp = np.zeros(0)
    else:
        S = Vm.tocsr() - WmT.tocsr() @ (Uim @ Wm).tocsr()
        dp = spsolve(S.tocsc(), rhs)
    dc = -Uig - (Uim @ (Wm @ dp)).reshape(n, p)
    return dc, np.asarray(dp).reshape(f, d)


def _cg_step(Ui, Vd, W: Coupling, g, h, rtol: float):
    """The ``"cg"`` step of :func:`sparse_schur_step` from the inverted (damped) pose blocks
    ``Ui`` and the damped object blocks ``Vd``: the reduced system applied by one compiled loop
    over the observations (:mod:`mappers.viewpoints.sparse_schur_kernels`), never formed, and
    solved by conjugate gradients with a block-Jacobi preconditioner."""
    n, p = Ui.shape[:2]
    f, d = Vd.shape[:2]
    blocks, step, free = W.blocks, W.step, W.free
    if np.any(np.diff(step) < 0):  # the product visits the blocks step by step
        order = np.argsort(step, kind="stable")
        blocks, step, free = blocks[order], step[order], free[order]
    blocks = np.ascontiguousarray(blocks, dtype=np.float64)
    step = np.ascontiguousarray(step, dtype=np.int64)
    free = np.ascontiguousarray(free, dtype=np.int64)
    Ui, Vd = np.ascontiguousarray(Ui), np.ascontiguousarray(Vd)
    Uig = np.einsum("nij,nj->ni", Ui, g)
    if not f:
        return -Uig, np.zeros((0, d))
    rhs = -np.array(h, dtype=np.float64).reshape(f, d)
    kernels.couple_transpose(blocks, step, free, Uig, rhs)
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(step, minlength=n), out=indptr[1:])
    diag = np.empty_like(Vd)
    kernels.schur_diagonal(Ui, blocks, step, free, Vd, diag)
    pre = _block_diagonal(np.linalg.inv(diag))

    def matvec(x):
        out = np.empty((f, d))
        kernels.schur_matvec(Ui, blocks, indptr, free, Vd,
                             np.ascontiguousarray(x, dtype=np.float64).reshape(f, d), out)
        return out.reshape(-1)

    op = LinearOperator((d * f, d * f), matvec=matvec, dtype=float)
    dp, info = cg(op, rhs.reshape(-1), rtol=rtol, atol=0.0, maxiter=10 * d * f, M=pre)
    if info != 0:
        raise RuntimeError(f"conjugate gradients did not converge ({info} iterations)")
    dp = dp.reshape(f, d)
    Wdp = np.zeros((n, p))
    kernels.couple(blocks, step, free, dp, Wdp)
    return -Uig - np.einsum("nij,nj->ni", Ui, Wdp), dp
