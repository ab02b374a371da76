"""Stress on a sparse graph of pairs: dissimilarities, neighbours, a landmark start, anchored SMACOF.

The dense methods hold (M, M) matrices; at M = 10,000 one of them is 800 MB. Everything here works
on pair lists (``i``, ``j`` arrays, i < j) whose length grows like M:

- :func:`candidate_pairs`: the pairs worth a dissimilarity. Visibility rows that never share an
  observation are at the saturation value (``1 - cos = 1``: "far", nothing more), so the pairs
  are exactly the non-zeros of the sparse product ``X X^T`` (scipy.sparse). Rows of bearings or
  ranges are dense: their candidates are each row's nearest rows (scikit-learn's
  ``NearestNeighbors``; measured faster here than an approximate index at these sizes).
- :func:`knn_pairs`: the symmetric kNN graph among candidate pairs (as ``mappers.core.graph.knn_mask``).
- :func:`landmark_mds`: Landmark MDS (de Silva & Tenenbaum, "Global versus local methods in
  nonlinear dimensionality reduction", NIPS 2003) of graph geodesics from a few landmarks
  chosen farthest-first (``scipy.sparse.csgraph.dijkstra`` from each landmark only).
- :func:`sparse_smacof`: weighted SMACOF (de Leeuw 1977; Borg & Groenen 2005, ch. 8) over the
  pairs only, with fixed points: each Guttman update solves ``V_FF X_F = (B(Z) Z)_F - V_FA X_A``
  with ``V`` the weighted graph Laplacian, factorised once (``scipy.sparse.linalg.splu``). This
  is the sparse stress model of Ortmann, Klimenta and Brandes ("A sparse stress model", 2016)
  with our own pair set; scikit-learn's SMACOF is dense and unweighted, and the maintained SGD
  layout library (s_gd2) ships as a source build only, hence these few lines.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.sparse.linalg import splu

__all__ = ["candidate_pairs", "knn_pairs", "landmark_mds", "sparse_smacof"]


def _upper(rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, m: int):
    """Unique pairs i < j (the value of the first occurrence of each)."""
    lo, hi = np.minimum(rows, cols), np.maximum(rows, cols)
    keep = lo < hi
    key = lo[keep] * m + hi[keep]
    key, first = np.unique(key, return_index=True)
    return key // m, key % m, vals[keep][first]


def candidate_pairs(X, kind: str, n_candidates: int):
    """(i, j, delta): pairs i < j worth a dissimilarity, with CAL-SMA's dissimilarity.

    ``kind="cosine"`` (visibility): ``1 - cos`` of the rows, for every pair of rows sharing an
    observation (``X`` may be a scipy sparse matrix). ``kind="euclidean"`` (bearing, range): RMS
    difference ``||x_i - x_j|| / sqrt(D)`` to each row's ``n_candidates`` nearest rows.
    """
    m, d = X.shape
    if kind == "cosine":
        Xs = sp.csr_array(X, dtype=np.float64)
        norms = np.sqrt(np.asarray(Xs.multiply(Xs).sum(axis=1)).ravel())
        Xn = sp.csr_array(sp.diags_array(1.0 / norms) @ Xs)
        G = sp.coo_array(sp.triu(Xn @ Xn.T, k=1))
        delta = np.maximum(1.0 - np.clip(G.data, -1.0, 1.0), 0.0)
        return _upper(G.row.astype(np.int64), G.col.astype(np.int64), delta, m)
    if kind != "euclidean":
        raise ValueError(f"unknown dissimilarity kind {kind!r}")
    from sklearn.neighbors import NearestNeighbors

    dense = X.toarray() if sp.issparse(X) else np.asarray(X, dtype=np.float64)
    k = min(n_candidates + 1, m)
    dist, idx = NearestNeighbors(n_neighbors=k).fit(dense).kneighbors(dense)
    rows = np.repeat(np.arange(m), k)
    return _upper(rows, idx.ravel(), dist.ravel() / np.sqrt(d), m)


def knn_pairs(i: np.ndarray, j: np.ndarray, delta: np.ndarray, m: int, k: int) -> np.ndarray:
    """Bool over the pairs: j among i's ``k`` smallest ``delta`` or i among j's (ties: lower index)."""
    rows = np.concatenate([i, j])
    cols = np.concatenate([j, i])
    vals = np.concatenate([delta, delta])
    order = np.lexsort((cols, vals, rows))  # by row, then delta, then the other end's index
    r = rows[order]
    start = np.searchsorted(r, np.arange(m))
    rank = np.arange(r.size) - start[r]
    chosen = np.zeros(r.size, dtype=bool)
    chosen[order] = rank < k
    n = i.size
    return chosen[:n] | chosen[n:]


def landmark_mds(graph: sp.csr_array, n_landmarks: int, rng: np.random.RandomState) -> np.ndarray:
    """(M, 2) Landmark MDS of the shortest-path distances of ``graph`` (edge weights = lengths).

    Landmarks are chosen farthest-first from a random object; unreachable objects (another
    component) get 1.5 times the largest finite distance.
    """
    m = graph.shape[0]
    n_landmarks = min(n_landmarks, m)
    marks = [int(rng.randint(m))]
    rows = [dijkstra(graph, directed=False, indices=marks[0])]
    nearest = rows[0].copy()
    while len(marks) < n_landmarks:
        nearest[~np.isfinite(nearest)] = np.inf
        nxt = int(np.argmax(np.where(np.isfinite(nearest), nearest, -1.0)))
        if nxt in marks:
            break
        marks.append(nxt)
        rows.append(dijkstra(graph, directed=False, indices=nxt))
        nearest = np.minimum(nearest, rows[-1])
    G = np.array(rows)  # (L, M)
    finite = np.isfinite(G)
    G[~finite] = 1.5 * G[finite].max() if finite.any() else 1.0
    D2 = G**2
    L2 = D2[:, marks]
    n = len(marks)
    J = np.eye(n) - 1.0 / n
    B = -0.5 * J @ L2 @ J
    vals, vecs = np.linalg.eigh(0.5 * (B + B.T))
    top = np.argsort(vals)[::-1][:2]
    lam = np.maximum(vals[top], 1e-12)
    pinv = vecs[:, top] / np.sqrt(lam)  # (L, 2): the landmarks' pseudo-inverse, transposed
    return -0.5 * (D2 - L2.mean(axis=1, keepdims=True)).T @ pinv


def _laplacian(i, j, w, m):
    W = sp.coo_array((np.concatenate([w, w]), (np.concatenate([i, j]), np.concatenate([j, i]))),
                     shape=(m, m)).tocsr()
    return sp.diags_array(np.asarray(W.sum(axis=1)).ravel()) - W


def sparse_smacof(i, j, targets, weights, init, fixed=None, *, max_iter=100, tol=1e-6):
    """Minimise ``sum w_ij (||x_i - x_j|| - t_ij)^2`` over the pairs by Guttman updates.

    ``fixed``: indices held at their rows of ``init``. Objects in a part of the graph without a
    fixed point are kept from drifting by a proximal term of weight 1e-9 x the mean degree (so
    the system is always solvable; it does not move the fixed point of the iteration).
    Returns (X, stress, n_iter).
    """
    m = init.shape[0]
    X = np.array(init, dtype=np.float64)
    free = np.ones(m, dtype=bool)
    if fixed is not None:
        free[np.asarray(fixed)] = False
    F = np.flatnonzero(free)
    V = _laplacian(i, j, weights, m).tocsr()
    eps = 1e-9 * max(float(V.diagonal().mean()), 1e-300)
    VFF = V[F][:, F] + eps * sp.eye_array(F.size)
    VFA = V[F][:, np.flatnonzero(~free)]
    solve = splu(sp.csc_array(VFF)).solve
    pull = VFA @ X[~free] if VFA.shape[1] else 0.0

    def stress(Y):
        d = np.sqrt(((Y[i] - Y[j]) ** 2).sum(axis=1))
        return float(np.sum(weights * (d - targets) ** 2)), d

    s_old, d = stress(X)
    n_iter = 0
    for n_iter in range(1, max_iter + 1):  # noqa: B007  (n_iter is returned)
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(d > 0, weights * targets / d, 0.0)
        diff = (X[i] - X[j]) * r[:, None]  # row i of B(Z) Z gains r_ij (z_i - z_j), row j loses it
        BZ = np.column_stack([np.bincount(i, diff[:, c], m) - np.bincount(j, diff[:, c], m)
                              for c in range(X.shape[1])])
        X[F] = solve(BZ[F] - pull + eps * X[F])
        s_new, d = stress(X)
        if s_old - s_new <= tol * max(s_old, 1e-300):
            s_old = s_new
            break
        s_old = s_new
    return X, s_old, n_iter
