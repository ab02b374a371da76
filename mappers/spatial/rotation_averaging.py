"""Rotation averaging: the steps' absolute rotations from relative rotations between pairs.

Given ``R_ab ~ R_b^T R_a`` for the edges of a view graph (sensor -> world rotations ``R``), the
chordal average minimises ``sum w_ab ||R_b^T R_a - R_ab||_F^2``. Its spectral relaxation takes
the three leading eigenvectors of the symmetric block matrix with blocks ``w_ab R_ab`` (the
matrix ``Q Q^T`` with ``Q`` the stacked ``R_i^T`` has exactly these blocks), and projects each
3 x 3 block onto the rotations (Martinec & Pajdla, *Robust rotation and translation estimation
in multiview reconstruction*, CVPR 2007; Arie-Nachimson et al., *Global motion estimation from
point matches*, 3DIMPVT 2012). The relaxation is then refined by iteratively reweighted least
squares in the tangent space, each edge weighted by a Cauchy weight of its residual angle, so
that wrong relative rotations lose their pull (Chatterjee & Govindu, *Efficient and robust
large-scale rotation averaging*, ICCV 2013). SciPy's sparse matrices, spanning tree and sparse least
squares do the linear algebra; the result is defined up to one rotation of the world.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree
from scipy.sparse.linalg import lsqr
from scipy.spatial.transform import Rotation

__all__ = ["average_rotations", "largest_component"]


def largest_component(a: np.ndarray, b: np.ndarray, n: int) -> np.ndarray:
    """(n,) bool: the nodes of the largest connected component of the graph of edges
    ``a``-``b`` among ``n`` nodes (a node with no edge is in none)."""
    if len(a) == 0:
        return np.zeros(n, dtype=bool)
    G = sparse.coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    _, label = connected_components(G, directed=False)
    has_edge = np.zeros(n, dtype=bool)
    has_edge[a] = has_edge[b] = True
    sizes = np.bincount(label[has_edge], minlength=label.max() + 1)
    return has_edge & (label == np.argmax(sizes))


def average_rotations(a: np.ndarray, b: np.ndarray, rel: np.ndarray, n: int, *,
                      weights: np.ndarray | None = None, scale: float = np.deg2rad(2.0),
                      rounds: int = 5):
    """``(R, residual)``: sensor -> world rotations (n, 3, 3) of the nodes of a connected view
    graph with edges ``a``-``b`` and relative rotations ``rel`` (E, 3, 3) ``~ R_b^T R_a``
    (see the module's docstring), NaN for nodes without an edge; ``residual`` (E,) each edge's
    angle [rad] to the averaged rotations. ``weights``: the edges' confidence (None: 1);
    ``scale`` [rad]: the Cauchy scale of the reweighting; ``rounds`` of it."""
    a, b = np.asarray(a), np.asarray(b)
    w = np.ones(len(a)) if weights is None else np.asarray(weights, dtype=float)
    R = _spectral(a, b, rel, w, n)
    has = np.isfinite(R[:, 0, 0])
    for _ in range(rounds):
        res = _residual_angles(R, a, b, rel)
        R = _tangent_step(R, a, b, rel, w / (1.0 + (res / scale) ** 2), has)
    return R, _residual_angles(R, a, b, rel)


def _spectral(a, b, rel, w, n):
    rows = (3 * b[:, None, None] + np.arange(3)[None, :, None]) * np.ones((1, 1, 3), int)
    cols = (3 * a[:, None, None] + np.arange(3)[None, None, :]) * np.ones((1, 3, 1), int)
    vals = w[:, None, None] * rel
    H = sparse.coo_matrix((np.concatenate([vals.ravel(), vals.ravel()]),
                           (np.concatenate([rows.ravel(), cols.ravel()]),
                            np.concatenate([cols.ravel(), rows.ravel()]))),
                          shape=(3 * n, 3 * n)).tocsr()
    has = np.zeros(n, dtype=bool)
    has[a] = has[b] = True
    # the nodes' blocks: keep those with edges (an isolated node has a zero block)
    idx = np.flatnonzero(np.repeat(has, 3))
    Hs = H[idx][:, idx]
    # the leading eigenvalue has multiplicity three, which a single-vector Lanczos (eigsh)
    # cannot resolve: block power iteration on H + c I (c bounds H's spectrum from below, so the
    # leading eigenvalues stay leading), started from the rotations chained along the graph's
    # maximum spanning tree (already near the leading space, and deterministic)
    Rt0 = _tree_chain(a, b, rel, w, n)[has].transpose(0, 2, 1).reshape(-1, 3)
    c = float(np.abs(Hs).sum(axis=1).max())
    vec = np.linalg.qr(Rt0)[0]
    for _ in range(_POWER_ITER):
        vec = np.linalg.qr(Hs @ vec + c * vec)[0]
    Q = vec.reshape(-1, 3, 3)  # block i ~ R_i^T (times a common 3 x 3 orthogonal matrix)
    if np.sum(np.linalg.det(Q) < 0) > len(Q) / 2:
        Q[:, :, 0] *= -1.0
    U, _, Vt = np.linalg.svd(Q)
    D = np.ones((len(Q), 3))
    D[:, 2] = np.where(np.linalg.det(U @ Vt) < 0, -1.0, 1.0)
    Rt = (U * D[:, None, :]) @ Vt
    R = np.full((n, 3, 3), np.nan)
    R[has] = Rt.transpose(0, 2, 1)
    return R


_POWER_ITER = 50
"""Block power iterations of the spectral relaxation from the tree's start."""


def _tree_chain(a, b, rel, w, n):
    """Rotations chained from the first node of the graph along its maximum spanning tree by
    weight ``w`` (``R_a = R_b rel``), NaN for nodes without an edge."""
    G = sparse.coo_matrix((1.0 / w, (a, b)), shape=(n, n)).tocsr()
    tree = minimum_spanning_tree(G)
    tree = tree + tree.T
    R = np.full((n, 3, 3), np.nan)
    edge = {(int(i), int(j)): k for k, (i, j) in enumerate(zip(a, b, strict=True))}
    for root in np.unique(np.concatenate([a, b])):
        if np.isfinite(R[root, 0, 0]):
            continue
        order, pred = breadth_first_order(tree, int(root), directed=False,
                                          return_predecessors=True)
        R[root] = np.eye(3)
        for node in order[1:]:  # by hand: a walk down the tree, one product per node
            p = int(pred[node])
            if (node, p) in edge:
                R[node] = R[p] @ rel[edge[(node, p)]]
            else:
                R[node] = R[p] @ rel[edge[(p, node)]].T
    return R


def _residual_angles(R, a, b, rel):
    """Angle [rad] of ``rel^T R_b^T R_a`` per edge."""
    D = np.einsum("kji,kjl->kil", rel, np.einsum("kji,kjl->kil", R[b], R[a]))
    return np.arccos(np.clip((np.trace(D, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0))


def _tangent_step(R, a, b, rel, w, has):
    """One Gauss-Newton step of ``sum w ||log(rel^T R_b^T R_a)||^2`` in the world-frame tangent
    space (``R_i <- exp([x_i]) R_i``): the edge's error ``log(R_b rel R_a^T) ~ x_b - x_a``."""
    err = Rotation.from_matrix(np.einsum("kij,kjl,klm->kim", R[b], rel,
                                         R[a].transpose(0, 2, 1))).as_rotvec()
    nodes = np.flatnonzero(has)
    index = np.full(len(R), -1)
    index[nodes] = np.arange(nodes.size)
    e = len(a)
    sw = np.sqrt(w)
    rows = np.repeat(np.arange(3 * e), 2)
    cols = np.stack([3 * index[b][:, None] + np.arange(3), 3 * index[a][:, None] + np.arange(3)],
                    axis=2).reshape(-1)
    vals = (sw[:, None, None] * np.array([1.0, -1.0])[None, None, :]
            * np.ones((1, 3, 1))).reshape(-1)
    A = sparse.csr_matrix((vals, (rows, cols)), shape=(3 * e, 3 * nodes.size))
    # the gauge (one world rotation): a light pull of every correction to zero
    reg = sparse.identity(3 * nodes.size, format="csr") * 1e-6
    x = lsqr(sparse.vstack([A, reg]), np.concatenate([(sw[:, None] * -err).ravel(),
                                                      np.zeros(3 * nodes.size)]),
             atol=1e-10, btol=1e-10, iter_lim=2000)[0].reshape(-1, 3)
    out = R.copy()
    out[nodes] = Rotation.from_rotvec(x).as_matrix() @ R[nodes]
    return out
