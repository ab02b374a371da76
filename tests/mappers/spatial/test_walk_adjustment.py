"""The joint adjustment of tags and viewpoints with the walk prior (FRUSTUM-BA-WALK's
``walk_joint``): its banded step, its cost, its effect on the walk, bad input."""

import math

import numpy as np
import pytest

from mappers.spatial.frustum import FrustumCamera, FrustumProblem
from mappers.spatial.frustum_walk import FrustumWalkAdjustment
from mappers.spatial.walk_adjustment import (
    WalkPrior,
    _viewpoint_band,
    walk_joint_steps,
    walk_schur_step,
)
from tests.mappers.spatial.test_frustum_walk import ANCHORS, CAMERA, walk_world

PRIOR = WalkPrior(0.15, math.radians(30.0))


def problem(P, seen, softness=0.05):
    free_index = np.full(len(P), -1, dtype=np.int64)
    free_index[len(ANCHORS):] = np.arange(len(P) - len(ANCHORS))
    cam = FrustumCamera(*CAMERA.values())
    return FrustumProblem(seen, free_index, len(P) - len(ANCHORS),
                          cam.args(softness, 0.1, 0.02))


def perturbed(P, C, seed=1):
    """The tags moved by 0.25 m per axis (the anchors held), the viewpoints by 0.2 m and 20
    degrees per step, independently."""
    rng = np.random.default_rng(seed)
    P0 = P + np.r_[np.zeros((len(ANCHORS), 3)), rng.normal(0.0, 0.25, (len(P) - len(ANCHORS), 3))]
    C0 = C + rng.normal(0.0, 1.0, C.shape) * [0.2, 0.2, math.radians(20.0)]
    return P0, C0


def test_the_prior_cost_gradient_and_band_agree():
    rng = np.random.default_rng(0)
    C = rng.normal(0.0, 1.0, (7, 3))
    C[3, 2], C[4, 2] = 3.1, -3.1  # a turn across the wrap costs its short way round
    g = PRIOR.gradient(C)
    eps = 1e-6
    for t, r in [(0, 0), (3, 2), (4, 2), (6, 1)]:
        Cp = C.copy()
        Cp[t, r] += eps
        assert (PRIOR.cost(Cp) - PRIOR.cost(C)) / eps == pytest.approx(g[t, r], rel=1e-4, abs=1e-4)
    d = np.diff(C, axis=0)
    d[:, 2] = (d[:, 2] + math.pi) % (2 * math.pi) - math.pi
    assert abs(d[3, 2]) < 0.1
    assert PRIOR.cost(C) == pytest.approx(0.5 * np.sum(d**2 * PRIOR.weights))


def test_the_banded_step_solves_the_full_normal_equations():
    P, C, seen = walk_world(m=14, n=40)
    prob = problem(P, seen)
    P0, C0 = perturbed(P, C)
    _, U, V, W, g, h = prob.blocks(P0, C0)
    g = g + PRIOR.gradient(C0)
    lam = 0.1
    dc, dp = walk_schur_step(U, V, W, g, h, lam, PRIOR)
    n, f = U.shape[0], V.shape[0]
    ab = _viewpoint_band(U, PRIOR, lam)
    A = np.zeros((3 * n, 3 * n))
    for k in range(6):  # the upper band back to the full symmetric matrix
        i = np.arange(3 * n - (5 - k))
        A[i, i + 5 - k] = ab[k, 5 - k:]
    A = np.triu(A) + np.triu(A, 1).T
    Vd = np.zeros((3 * f, 3 * f))
    for j in range(f):
        Vd[3 * j:3 * j + 3, 3 * j:3 * j + 3] = V[j] + lam * np.diag(np.diag(V[j]))
    Vd += 1e-9 * np.eye(3 * f)
    Wf = W.reshape(3 * n, 3 * f)
    x = np.linalg.solve(np.block([[A, Wf], [Wf.T, Vd]]), -np.r_[g.ravel(), h.ravel()])
    scale = np.abs(x).max()
    np.testing.assert_allclose(dc.ravel(), x[:3 * n], atol=1e-8 * scale)
    np.testing.assert_allclose(dp.ravel(), x[3 * n:], atol=1e-8 * scale)


def test_lowers_the_cost_and_keeps_the_walk_together():
    P, C, seen = walk_world(m=20, n=200)
    prob = problem(P, seen)
    P0, C0 = perturbed(P, C)
    before = prob.cost(P0, C0) + PRIOR.cost(C0)
    P1, C1, loss = walk_joint_steps(prob, P0, C0, 8, PRIOR)
    assert loss == pytest.approx(prob.cost(P1, C1))
    assert loss + PRIOR.cost(C1) < 0.8 * before
    np.testing.assert_array_equal(P1[ANCHORS], P[ANCHORS])
    # FRUSTUM-BA's joint rounds, no prior: each step on its own, the walk's links apart
    P2, C2, _ = prob.joint(P0, C0, 8)
    link = np.linalg.norm(np.diff(C1[:, :2], axis=0), axis=1)
    link_free = np.linalg.norm(np.diff(C2[:, :2], axis=0), axis=1)
    true_link = np.linalg.norm(np.diff(C[:, :2], axis=0), axis=1)  # 0.2 m each
    assert np.median(link) < 0.5 * np.median(link_free)
    assert np.median(link) < 1.5 * np.median(true_link)
    assert PRIOR.cost(C1) < 0.5 * PRIOR.cost(C2)
    # no rounds: the start back
    P3, C3, loss3 = walk_joint_steps(prob, P0, C0, 0, PRIOR)
    np.testing.assert_array_equal(C3, C0)
    assert loss3 == pytest.approx(prob.cost(P0, C0))


def test_bad_input():
    P, C, seen = walk_world(m=10, n=20)
    prob = problem(P, seen)
    with pytest.raises(ValueError, match="step_sigma"):
        WalkPrior(0.0, 0.5)
    with pytest.raises(ValueError, match="turn_sigma"):
        WalkPrior(0.15, math.nan)
    with pytest.raises(ValueError, match="rounds"):
        walk_joint_steps(prob, P, C, -1, PRIOR)
    with pytest.raises(ValueError, match="sightings"):
        walk_joint_steps(prob, P, C[:-1], 2, PRIOR)
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        walk_joint_steps(prob, P[:, :2], C, 2, PRIOR)
    X = seen.T.astype(float)
    with pytest.raises(ValueError, match="final_rounds"):
        FrustumWalkAdjustment(**CAMERA, final_rounds=-1).fit(
            X, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS])


def test_frustum_ba_walk_ends_on_the_walk_priors_optimum():
    """FRUSTUM-BA-WALK's ``final_rounds`` start where ``final_rounds=0`` ends and only take
    steps that lower the frustum loss plus the walk prior's cost."""
    P, C, seen = walk_world(m=14, n=120)
    rng = np.random.default_rng(2)
    start = P + np.r_[np.zeros((6, 3)), rng.normal(0.0, 0.1, (len(P) - 6, 3))]
    X = seen.T.astype(float)
    kw = {**CAMERA, "softness": (0.05,), "rounds": 3, "walk_spacing": 0.2, "walk_headings": 18}
    fits = [FrustumWalkAdjustment(**kw, final_rounds=r).fit(
        X, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS], start_positions=start)
        for r in (0, 5)]
    assert all(f.refined_ for f in fits)
    n_pairs = seen.size
    cost = [f.loss_ * n_pairs + PRIOR.cost(f.poses_) for f in fits]
    assert cost[1] < cost[0]
    assert not np.allclose(fits[0].poses_, fits[1].poses_)
    np.testing.assert_allclose(fits[1].embedding_[ANCHORS], P[ANCHORS], atol=1e-12)
