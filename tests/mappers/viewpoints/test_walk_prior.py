"""The continuity prior of VIS-BA-WALK: forward-backward over grid cells (mappers/viewpoints/walk_prior.py)
and VisibilityAdjustment(continuity=True) on walks with dropouts."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from map_errors import non_anchor_error

from mappers.viewpoints.visibility import VisibilityAdjustment
from mappers.viewpoints.walk_prior import forward_backward, gaussian_taps

pytestmark = pytest.mark.usefixtures("one_blas_thread")


def _brute_force(E, top, init, cells, shape, sigma, h, starts):
    """Posteriors, log-likelihood and expected squared displacement by enumerating every path of
    every run (the transition: the truncated Gaussian between kept cells, renormalised)."""
    k, _ = gaussian_taps(sigma, h)
    r = (len(k) - 1) // 2
    ix, iy = np.divmod(cells, shape[1])

    def tap(d):
        return k[d + r] if abs(d) <= r else 0.0

    K = np.array([[tap(ix[j] - ix[i]) * tap(iy[j] - iy[i]) for j in range(len(cells))]
                  for i in range(len(cells))])
    T = K / K.sum(axis=1, keepdims=True)
    D2 = ((ix[:, None] - ix[None]) ** 2 + (iy[:, None] - iy[None]) ** 2) * h * h
    L = E.astype(float) * np.exp(top)[:, None]
    post, loglik, disp = np.zeros(E.shape), 0.0, 0.0
    bounds = [*np.flatnonzero(starts), len(starts)]
    for a, b in itertools.pairwise(bounds):
        Z, marg, d2 = 0.0, np.zeros((b - a, len(cells))), 0.0
        for path in itertools.product(range(len(cells)), repeat=b - a):
            p = init[path[0]] * L[a, path[0]]
            for s in range(1, b - a):
                p *= T[path[s - 1], path[s]] * L[a + s, path[s]]
            Z += p
            marg[np.arange(b - a), path] += p
            d2 += p * sum(D2[path[s - 1], path[s]] for s in range(1, b - a))
        post[a:b], loglik, disp = marg / Z, loglik + np.log(Z), disp + d2 / Z
    return post, loglik, disp


def test_forward_backward_matches_brute_force():
    rng = np.random.default_rng(0)
    shape, h, sigma = (4, 3), 0.1, 0.12
    cells = np.sort(rng.choice(12, 8, replace=False))  # some cells dropped from the grid
    n = 7
    E = (rng.random((n, len(cells))) ** 3).astype(np.float32)
    top = rng.normal(size=n)
    init = rng.random(len(cells))
    init /= init.sum()
    starts = np.zeros(n, dtype=bool)
    starts[[0, 4]] = True  # two runs: 4 and 3 steps
    post, ll, disp = forward_backward(E, top, init, cells, shape, sigma, h, starts, cutoff=0.0)
    ref_post, ref_ll, ref_disp = _brute_force(E, top, init, cells, shape, sigma, h, starts)
    np.testing.assert_allclose(post, ref_post, atol=1e-6)
    assert ll == pytest.approx(ref_ll, rel=1e-10)
    assert disp == pytest.approx(ref_disp, rel=1e-10)
    # the default cutoff (mass below 1e-6 of a step's largest left out) changes little
    post2, ll2, _ = forward_backward(E, top, init, cells, shape, sigma, h, starts)
    np.testing.assert_allclose(post2, ref_post, atol=1e-4)
    # the displacement is only computed when asked for
    assert forward_backward(E, top, init, cells, shape, sigma, h, starts, want_disp=False,
                            cutoff=0.0)[2] == 0.0


def test_forward_backward_refuses_bad_input():
    E, top, init = np.ones((3, 2), np.float32), np.zeros(3), np.full(2, 0.5)
    cells, starts = np.array([0, 1]), np.array([True, False, False])
    with pytest.raises(ValueError, match="starts"):
        forward_backward(E, top, init, cells, (2, 1), 0.1, 0.1, ~starts)
    with pytest.raises(ValueError, match="E must be"):
        forward_backward(E[:2], top, init, cells, (2, 1), 0.1, 0.1, starts)
    with pytest.raises(ValueError, match="index the"):
        forward_backward(E, top, init, np.array([0, 5]), (2, 1), 0.1, 0.1, starts)
    with pytest.raises(ValueError, match="positive"):
        forward_backward(E, top, init, cells, (2, 1), 0.0, 0.1, starts)


def _walk(n_obj=30, n_steps=1500, radius=0.55, miss=0.5, seed=0):
    """Objects in a 2.4 m square (anchors at the corners) seen from a random walk of 0.2 m steps
    inside it (a new random heading when a step would leave it); an object within ``radius`` is
    seen with probability ``1 - miss``. Returns positions, the (M, N) history, the anchors and
    the viewpoints."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(-1.1, 1.1, size=(n_obj, 2))
    P[:4] = [(-1.1, -1.1), (1.1, -1.1), (1.1, 1.1), (-1.1, 1.1)]
    C = np.zeros((n_steps, 2))
    heading = rng.uniform(0, 2 * np.pi)
    for t in range(1, n_steps):
        heading += rng.normal(scale=0.5)
        step = 0.2 * np.array([np.cos(heading), np.sin(heading)])
        while np.any(np.abs(C[t - 1] + step) > 1.2):
            heading = rng.uniform(0, 2 * np.pi)
            step = 0.2 * np.array([np.cos(heading), np.sin(heading)])
        C[t] = C[t - 1] + step
    near = np.linalg.norm(P[:, None] - C[None], axis=2) < radius
    X = (near & (rng.random(near.shape) >= miss)).astype(float)
    return P, X, np.arange(4), C


def test_continuity_improves_a_walk_with_dropouts():
    P, X, ids, C = _walk()
    start = P + np.random.default_rng(1).normal(scale=0.06, size=P.shape)
    start[ids] = P[ids]
    kw = dict(anchor_ids=ids, anchor_positions=P[ids], start_positions=start)
    plain = VisibilityAdjustment(grid_cells=4)
    walk = VisibilityAdjustment(grid_cells=4, continuity=True)
    e_plain = non_anchor_error(plain.fit_transform(X, **kw), P, ids)
    e_walk = non_anchor_error(walk.fit_transform(X, **kw), P, ids)
    assert walk.refined_ and walk.loglik_ >= walk.start_loglik_
    assert e_walk < 0.85 * e_plain, (e_plain, e_walk)
    assert 0.1 < walk.step_sigma_ < 0.3  # the walk's width fitted (0.14 m per axis)
    assert np.isnan(plain.step_sigma_)
    vp_plain = np.nanmedian(np.linalg.norm(plain.viewpoints_ - C, axis=1))
    vp_walk = np.median(np.linalg.norm(walk.viewpoints_ - C, axis=1))
    assert vp_walk < vp_plain


def test_continuity_follows_the_timeline():
    """Steps in a shuffled column order with the timeline saying their ticks give the same map
    as the ordered history."""
    P, X, ids, _ = _walk(n_steps=600)
    start = P + np.random.default_rng(2).normal(scale=0.05, size=P.shape)
    start[ids] = P[ids]
    kw = dict(anchor_ids=ids, anchor_positions=P[ids], start_positions=start)
    Y = VisibilityAdjustment(grid_cells=4, continuity=True, max_rounds=2).fit_transform(X, **kw)
    perm = np.random.default_rng(3).permutation(X.shape[1])
    timeline = np.column_stack([np.zeros(len(perm), int), perm])
    Y2 = VisibilityAdjustment(grid_cells=4, continuity=True, max_rounds=2).fit_transform(
        X[:, perm], timeline=timeline, **kw)
    np.testing.assert_allclose(Y, Y2, atol=1e-4)


def test_bad_continuity_parameters_are_refused():
    P, X, ids, _ = _walk(n_steps=100)
    kw = dict(anchor_ids=ids, anchor_positions=P[ids], start_positions=P)
    with pytest.raises(ValueError, match="step_sigma"):
        VisibilityAdjustment(continuity=True, step_sigma=0.0).fit(X, **kw)
    with pytest.raises(ValueError, match="step_sigma"):
        VisibilityAdjustment(continuity=True, step_sigma="wide").fit(X, **kw)
    with pytest.raises(ValueError, match="only continuity=True"):
        VisibilityAdjustment(step_sigma=0.2).fit(X, **kw)
    with pytest.raises(ValueError, match="overrelax"):
        VisibilityAdjustment(overrelax=1.5).fit(X, **kw)
    with pytest.raises(ValueError, match="continuity"):
        VisibilityAdjustment(continuity="yes").fit(X, **kw)
    with pytest.raises(ValueError, match="align"):
        VisibilityAdjustment(align=1.0).fit(X, **kw)


def test_vis_ba_walk_is_registered_and_maps_a_walk():
    from mappers import build_map
    from mappers.catalog import methods_for

    assert "VIS-BA-WALK" in methods_for("visibility", masked=False)
    assert "VIS-BA-WALK" in methods_for("visibility", masked=True)
    assert "VIS-BA-WALK" not in methods_for("bearing")
    P, X, ids, _ = _walk(n_steps=800)
    m = build_map(X, ids, P[ids], "VIS-BA-WALK", sensor="visibility")
    cal = build_map(X, ids, P[ids], "CAL-SMA", sensor="visibility")
    assert m.method == "VIS-BA-WALK" and m.params["continuity"] and np.all(np.isfinite(m.positions))
    assert non_anchor_error(m.positions, P, ids) < non_anchor_error(cal.positions, P, ids)
