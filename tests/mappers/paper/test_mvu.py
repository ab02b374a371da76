"""SDE / MVU: the solution meets its constraints, recovers a layout, repairs graphs, checks."""

import numpy as np
import pytest
import scipy.sparse as sp

from mappers import GraphRepairWarning, MaximumVarianceUnfolding, apply_affine, fit_affine
from mappers.paper.mvu import mvu_constraint_matrix


def _curled(n=40, seed=0):
    """Points on a 2-D sheet rolled into 3-D (a quarter Swiss roll): MVU should unroll it."""
    rng = np.random.default_rng(seed)
    uv = rng.uniform(0, 1, (n, 2))
    t = 1.0 + 1.5 * uv[:, 0]
    X = np.column_stack([t * np.cos(t), uv[:, 1] * 2, t * np.sin(t)])
    return X, uv


# bound: relative violation allowed (first-order SCS at 1e-3 vs interior-point CLARABEL)
@pytest.mark.parametrize("solver, tol, bound", [("SCS", 1e-3, 5e-2), ("CLARABEL", 1e-8, 1e-4)])
def test_solution_meets_constraints(solver, tol, bound):
    X, _ = _curled(30)
    est = MaximumVarianceUnfolding(n_neighbors=6, solver=solver, tol=tol).fit(X)
    K = est.kernel_
    scale = np.abs(np.diag(K)).max()
    assert np.linalg.eigvalsh(K).min() >= -bound * scale  # PSD
    assert abs(K.sum()) <= bound * scale * len(K)  # centred
    ei, ej = sp.triu(est.graph_, 1).nonzero()
    d2 = np.sum((X[ei] - X[ej]) ** 2, axis=1)
    got = K[ei, ei] + K[ej, ej] - 2 * K[ei, ej]
    assert np.max(np.abs(got - d2)) <= bound * d2.mean()  # local distances kept
    # optimality: the centred Gram matrix of the input is feasible, so the optimum is no smaller
    Xc = X - X.mean(0)
    assert np.trace(K) >= (1 - bound) * np.sum(Xc**2)


def test_constraint_matrix_matches_loop():
    rng = np.random.default_rng(0)
    K = rng.normal(size=(6, 6))
    ei, ej = np.array([0, 1, 4]), np.array([3, 2, 5])
    got = mvu_constraint_matrix(ei, ej, 6) @ K.ravel()
    want = [K[i, i] + K[j, j] - K[i, j] - K[j, i] for i, j in zip(ei, ej, strict=True)]
    np.testing.assert_allclose(got, want)


def test_unrolls_the_sheet():
    X, uv = _curled(50, seed=1)
    for est in (MaximumVarianceUnfolding(n_neighbors=6), MaximumVarianceUnfolding(n_neighbors=6, n_basis=12)):
        Y = est.fit_transform(X)
        err = np.mean(np.linalg.norm(apply_affine(Y, fit_affine(Y, uv)) - uv, axis=1))
        # exact ~0.02, fast MVU (12 Laplacian eigenvectors) ~0.07; the rolled input ~0.27
        assert err < (0.04 if est.n_basis is None else 0.1), (est, err)
    # the rolled-up input itself is far from the sheet
    Xp = X[:, [0, 2]]
    assert np.mean(np.linalg.norm(apply_affine(Xp, fit_affine(Xp, uv)) - uv, axis=1)) > 0.15


def test_disconnected_graph_is_joined_with_warning():
    rng = np.random.default_rng(2)
    X = np.vstack([rng.normal(size=(10, 2)), rng.normal(size=(10, 2)) + 20])
    with pytest.warns(GraphRepairWarning, match="joined"):
        est = MaximumVarianceUnfolding(n_neighbors=3).fit(X)
    assert len(est.added_edges_) == 1
    assert np.all(np.isfinite(est.embedding_))


def test_bad_solver_and_deterministic_signs():
    X, _ = _curled(20)
    with pytest.raises(ValueError, match="not installed"):
        MaximumVarianceUnfolding(solver="NOPE").fit(X)
    a = MaximumVarianceUnfolding(n_neighbors=5).fit_transform(X)
    b = MaximumVarianceUnfolding(n_neighbors=5).fit_transform(X)
    np.testing.assert_allclose(a, b)
