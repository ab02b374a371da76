"""Masked (missing-data) mapping: mappers/masked/pair_maps.py, mappers/masked/coobservation.py, the SMACOF
variants and the covisibility ensemble."""

from __future__ import annotations

import numpy as np
import pytest

from mappers.core.sensors import step_observations
from mappers.masked.coobservation import covisibility_dissimilarity, range_pair_distances
from mappers.masked.pair_maps import MASKED_METHODS, masked_embedding
from mappers.smacof.variants import nonmetric_smacof


def _corners(P: np.ndarray) -> np.ndarray:
    lo, hi = P.min(0), P.max(0)
    ids: list[int] = []
    for c in [(lo[0], lo[1]), (hi[0], lo[1]), (hi[0], hi[1]), (lo[0], hi[1])]:
        d = np.linalg.norm(P - np.array(c), axis=1)
        d[ids] = np.inf
        ids.append(int(np.argmin(d)))
    return np.array(ids)


def _simulate(n_obj=20, n_steps=3000, fov=0.6, max_range=6.0, noise=0.0, seed=0):
    """Landmarks in a 5 x 10 m area seen by a camera with a +-fov field of view from random
    poses: returns positions and per-step (seen, range, bearing)."""
    rng = np.random.default_rng(seed)
    P = rng.uniform([0, 0], [5, 10], size=(n_obj, 2))
    poses = np.column_stack([rng.uniform(-0.5, 5.5, n_steps), rng.uniform(-0.5, 10.5, n_steps),
                             rng.uniform(-np.pi, np.pi, n_steps)])
    d = P[None] - poses[:, None, :2]
    r = np.linalg.norm(d, axis=2)
    b = np.angle(np.exp(1j * (np.arctan2(d[..., 1], d[..., 0]) - poses[:, 2:3])))
    seen = (np.abs(b) <= fov) & (r <= max_range) & (r > 0.3)
    r = r + noise * rng.standard_normal(r.shape)
    return P, seen.T, r.T, b.T


def _score(est, P, anchors):
    na = np.setdiff1d(np.arange(len(P)), anchors)
    return float(np.mean(np.linalg.norm(est[na] - P[na], axis=1)))


def test_step_observations_per_sensor():
    seen = np.array([[True, False, True], [False, False, True]])
    X = np.where(seen, 2.0, 0.0)
    s, v = step_observations(X, seen, "range")
    assert np.array_equal(s, seen) and np.isnan(v[1, 0]) and v[0, 0] == 2.0
    s, v = step_observations(seen.astype(float), None, "visibility")
    assert np.array_equal(s, seen)
    ang = np.array([[0.3, 0.0, -0.2]])
    Xb = np.zeros((1, 6))
    Xb[:, 0::2], Xb[:, 1::2] = np.cos(ang), np.sin(ang)
    mask = np.repeat(np.array([[True, False, True]]), 2, axis=1)
    s, v = step_observations(Xb, mask, "bearing")
    assert s.tolist() == [[True, False, True]]
    assert np.allclose(v[0, [0, 2]], [0.3, -0.2])
    with pytest.raises(ValueError, match="sensor"):
        step_observations(X, None, "sonar")
    with pytest.raises(ValueError, match="mask"):
        step_observations(X, seen.astype(int), "range")


def test_range_pair_distances_are_lower_bounds_close_to_truth():
    P, seen, r, _ = _simulate(seed=1)
    delta, counts = range_pair_distances(r, seen, quantile=1.0, min_pairs=5)
    D = np.linalg.norm(P[:, None] - P[None], axis=2)
    ok = counts > 0
    assert ok.sum() > 0.5 * ok.size  # most pairs are measured despite the narrow view
    assert np.all(delta[ok] <= D[ok] + 1e-9)  # |r_i - r_j| <= d_ij, noise-free
    assert np.median(D[ok] - delta[ok]) < 0.05


def test_range_quantile_recovers_layout_with_heavy_missingness():
    P, seen, r, _ = _simulate(noise=0.02, seed=2)
    assert seen.mean() < 0.15  # each landmark is missing from > 85 % of the steps
    X = np.where(seen, r, 0.0)
    anchors = _corners(P)
    mm = masked_embedding(X, seen, "range", anchor_ids=anchors, anchor_positions=P[anchors])
    assert mm.method == "range-quantile"
    assert np.allclose(mm.positions[anchors], P[anchors])
    assert _score(mm.positions, P, anchors) < 0.15
    assert len(mm.components) == 1 and not mm.warnings


def test_covis_nonmetric_beats_zero_filled_baseline():
    P, seen, _, _ = _simulate(n_steps=4000, seed=3)
    anchors = _corners(P)
    mm = masked_embedding(seen.astype(float), None, "visibility",
                          anchor_ids=anchors, anchor_positions=P[anchors])
    err = _score(mm.positions, P, anchors)
    centroid = _score(np.repeat(P[anchors].mean(0)[None], len(P), 0), P, anchors)
    assert err < 0.35 * centroid
    assert err < 1.0


def _layout_and_start(seed: int, side: float, jitter: float):
    """12 points uniform in a square of ``side``, their distances, equal weights, the first
    four as fixed points, and a start ``jitter`` off the truth."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(0, side, size=(12, 2))
    D = np.linalg.norm(P[:, None] - P[None], axis=2)
    start = P + rng.normal(scale=jitter, size=P.shape)
    return P, D, 1.0 - np.eye(12), np.array([0, 1, 2, 3]), start


def test_nonmetric_smacof_uses_only_the_order_of_dissimilarities():
    P, D, W, fixed, start = _layout_and_start(4, 4, 0.5)
    a = nonmetric_smacof(D, W, start, fixed=fixed, fixed_positions=P[fixed])
    b = nonmetric_smacof(np.exp(D), W, start, fixed=fixed, fixed_positions=P[fixed])
    assert np.allclose(a, b, atol=1e-6)
    assert np.mean(np.linalg.norm(a - P, axis=1)) < 0.1


def test_censored_pairs_are_kept_at_least_as_far_as_measured_ones():
    rng = np.random.default_rng(5)
    P = np.vstack([rng.uniform(0, 1, (8, 2)), rng.uniform(0, 1, (8, 2)) + [4.0, 1.0]])
    D = np.linalg.norm(P[:, None] - P[None], axis=2)
    cens = D > 2  # never co-observed: only "farther than anything measured" is known
    W = 1.0 - np.eye(16)
    fixed = np.array([0, 1, 2, 8])
    start = P + rng.normal(scale=0.3, size=P.shape)
    X = nonmetric_smacof(np.where(cens, 0, D), W, start, censored=cens,
                         fixed=fixed, fixed_positions=P[fixed], max_iter=1000)
    d = np.linalg.norm(X[:, None] - X[None], axis=2)
    measured = ~cens & (W > 0)
    assert d[cens].min() >= 0.9 * d[measured].max()
    assert np.mean(np.linalg.norm(X - P, axis=1)) < 0.5


def test_covisibility_dissimilarity_orders_by_co_observation():
    seen = np.array([[1, 1, 1, 0, 0, 0], [1, 1, 0, 0, 0, 0], [0, 0, 1, 1, 1, 1]], bool)
    delta, C = covisibility_dissimilarity(seen)
    assert C[0, 1] == 2 and C[1, 2] == 0
    assert delta[0, 1] < delta[0, 2] < delta[1, 2]


def test_never_sensed_objects_are_unmapped_and_hook_shape():
    P, seen, r, _ = _simulate(seed=6)
    seen[7] = False
    X = np.where(seen, r, 0.0)
    anchors = _corners(P)
    anchors = anchors[anchors != 7]
    if len(anchors) < 3:
        anchors = np.array([0, 1, 2])
    Y = masked_embedding(X, seen, "range", anchor_ids=anchors, anchor_positions=P[anchors]).positions
    assert Y.shape == (len(P), 2)
    assert np.isnan(Y[7]).all() and np.isfinite(np.delete(Y, 7, axis=0)).all()


def test_bad_arguments_raise_value_error():
    P, seen, r, _ = _simulate(n_obj=8, n_steps=500, seed=7)
    X = np.where(seen, r, 0.0)
    with pytest.raises(ValueError, match="method"):
        masked_embedding(X, seen, "range", "nope")
    with pytest.raises(ValueError, match="unknown parameter"):
        masked_embedding(X, seen, "range", "range-quantile", bogus=1)
    with pytest.raises(ValueError, match="range history"):
        masked_embedding(seen.astype(float), None, "visibility", "range-quantile")
    with pytest.raises(ValueError, match="quantile"):
        masked_embedding(X, seen, "range", quantile=1.5)
    with pytest.raises(ValueError, match="anchors"):
        masked_embedding(X, seen, "range", anchor_ids=np.array([0, 1]),
                         anchor_positions=P[:2])
    assert set(MASKED_METHODS) >= {"range-quantile", "covis-nonmetric", "masked-euclidean"}


def test_build_map_maps_masked_histories_with_the_masked_methods():
    from mappers import build_map

    P, seen, r, _ = _simulate(noise=0.01, seed=8)
    X = np.where(seen, r, 0.0)
    anchors = _corners(P)
    m = build_map(X, anchors, P[anchors], sensor="range", mask=seen)
    assert _score(m.positions, P, anchors) < 0.3
    assert m.method == "RANGE-QUANTILE"
    direct = masked_embedding(X, seen, "range", anchor_ids=anchors, anchor_positions=P[anchors])
    np.testing.assert_allclose(m.positions, direct.positions, atol=1e-12)  # anchors held: affine = I
    # a method for complete histories is refused, naming those that fit
    with pytest.raises(ValueError, match="'UNFOLD' does not map masked range.*RANGE-QUANTILE"):
        build_map(X, anchors, P[anchors], "UNFOLD", sensor="range", mask=seen)


def test_range_bounds_bracket_the_truth_and_map_well():
    from mappers.masked.coobservation import range_pair_bounds

    P, seen, r, _ = _simulate(fov=0.6, seed=9)
    upper = range_pair_bounds(r, seen, fov=1.2, upper_quantile=0.0)
    lower, counts = range_pair_distances(r, seen, quantile=1.0)
    D = np.linalg.norm(P[:, None] - P[None], axis=2)
    ok = counts > 0
    assert np.all(lower[ok] <= D[ok] + 1e-9) and np.all(D[ok] <= upper[ok] + 1e-9)
    assert np.all(np.isinf(upper[~ok & ~np.eye(len(P), dtype=bool)]))
    with pytest.raises(ValueError, match="fov"):
        range_pair_bounds(r, seen, fov=0.0)
    X = np.where(seen, r + 0.02 * np.random.default_rng(0).standard_normal(r.shape), 0.0)
    anchors = _corners(P)
    mm = masked_embedding(X, seen, "range", "range-bounds", anchor_ids=anchors,
                          anchor_positions=P[anchors], fov=1.2)
    assert _score(mm.positions, P, anchors) < 0.15


def test_bounded_smacof_has_no_stress_inside_the_intervals():
    from mappers.smacof.variants import bounded_smacof

    rng = np.random.default_rng(10)
    P = rng.uniform(0, 3, size=(8, 2))
    D = np.linalg.norm(P[:, None] - P[None], axis=2)
    W = 1.0 - np.eye(8)
    # the truth satisfies the intervals: started there, nothing moves
    X = bounded_smacof(0.8 * D, 1.2 * D, W, P, fixed=np.array([0, 1, 2]))
    assert np.allclose(X, P)
    # tight intervals pull a perturbed start back to the truth
    X = bounded_smacof(D, D, W, P + rng.normal(scale=0.2, size=P.shape),
                       fixed=np.array([0, 1, 2]), fixed_positions=P[:3])
    assert np.allclose(X, P, atol=1e-3)


def test_ensemble_is_the_mean_of_its_members_and_no_worse_than_them_on_average():
    from mappers.masked.ensemble import ensemble_embedding

    P, seen, _, _ = _simulate(n_obj=14, n_steps=3000, seed=11)
    anchors = _corners(P)

    def binned(k):  # steps grouped k at a time: a coarser "bin width"
        n = seen.shape[1] // k * k
        return seen[:, :n].reshape(len(P), -1, k).any(axis=2).astype(float)

    hists = [(binned(k), None) for k in (1, 2, 3)]
    sets = [{"min_co": 3}, {"min_co": 5}]
    # 100 SMACOF updates, not the default 300: the same map here (mean error 0.079 of the
    # centroid's against 0.078, bound 0.4) at a third of the CPU (12 non-metric maps)
    ens = ensemble_embedding(hists, "visibility", "covis-nonmetric", anchor_ids=anchors,
                             anchor_positions=P[anchors], param_sets=sets, max_iter=100)
    members = [masked_embedding(X, m, "visibility", "covis-nonmetric", anchor_ids=anchors,
                                anchor_positions=P[anchors], max_iter=100, **ps).positions
               for X, m in hists for ps in sets]
    assert np.allclose(ens.positions, np.mean(members, axis=0))
    assert np.allclose(ens.positions[anchors], P[anchors])
    assert len(ens.params["members"]) == 6
    err = _score(ens.positions, P, anchors)
    # mean position error is convex in the map: the mean map is never worse than the mean member
    assert err <= np.mean([_score(m, P, anchors) for m in members]) + 1e-12
    centroid = _score(np.repeat(P[anchors].mean(0)[None], len(P), 0), P, anchors)
    assert err < 0.4 * centroid
    with pytest.raises(ValueError, match="anchor"):
        ensemble_embedding(hists, "visibility", anchor_ids=None, anchor_positions=None)
    with pytest.raises(ValueError, match="histories"):
        ensemble_embedding([], "visibility", anchor_ids=anchors, anchor_positions=P[anchors])
    with pytest.raises(ValueError, match="same objects"):
        ensemble_embedding([hists[0], (hists[1][0][:-1], None)], "visibility",
                           anchor_ids=anchors, anchor_positions=P[anchors])


def test_power_link_smacof_recovers_a_layout_from_a_power_of_its_distances():
    from mappers.smacof.variants import power_link_smacof

    P, D, W, fixed, start = _layout_and_start(12, 5, 0.4)
    # delta = 7 d^2: with power 0.5 the link a * delta**0.5 is linear in d (a = 1/sqrt(7))
    X, a = power_link_smacof(7 * D**2, W, start, power=0.5, fixed=fixed,
                             fixed_positions=P[fixed], n_rounds=200)
    assert np.mean(np.linalg.norm(X - P, axis=1)) < 0.02
    assert a == pytest.approx(1 / np.sqrt(7), rel=0.02)
    # the wrong exponent cannot fit the same data as well
    Y, _ = power_link_smacof(7 * D**2, W, start, power=1.0, fixed=fixed,
                             fixed_positions=P[fixed], n_rounds=200)
    assert np.mean(np.linalg.norm(Y - P, axis=1)) > 0.05
    with pytest.raises(ValueError, match="power"):
        power_link_smacof(D, W, start, power=0.0)


def test_covis_power_maps_a_simulated_camera_and_falls_back_on_a_split_layout():
    P, seen, _, _ = _simulate(n_steps=4000, max_range=5.0, seed=13)
    anchors = _corners(P)
    mm = masked_embedding(seen.astype(float), None, "visibility", "covis-power",
                          anchor_ids=anchors, anchor_positions=P[anchors])
    centroid = _score(np.repeat(P[anchors].mean(0)[None], len(P), 0), P, anchors)
    assert mm.params["power"] == 0.5 and not mm.warnings
    assert _score(mm.positions, P, anchors) < 0.35 * centroid
    # two groups never seen together: no common link, so the non-metric map is kept (and said)
    split = seen.copy()
    left = P[:, 1] < 5
    split[left, : seen.shape[1] // 2] = False
    split[~left, seen.shape[1] // 2:] = False
    a2 = np.array([np.flatnonzero(left)[0], np.flatnonzero(left)[1],
                   np.flatnonzero(~left)[0], np.flatnonzero(~left)[1]])
    kw = {"anchor_ids": a2, "anchor_positions": P[a2]}
    pw = masked_embedding(split.astype(float), None, "visibility", "covis-power", **kw)
    nm = masked_embedding(split.astype(float), None, "visibility", "covis-nonmetric", **kw)
    assert any("kept the covis-nonmetric map" in w for w in pw.warnings)
    assert np.allclose(pw.positions, nm.positions)


@pytest.mark.parametrize("method", ["covis-nonmetric", "covis-power", "range-quantile"])
def test_a_group_held_by_fewer_than_two_anchors_is_left_unmapped_not_flung_away(method):
    """Two groups never sensed together: the group with 2 anchors is mapped in the anchors'
    frame; the other (1 anchor: scale and rotation unmeasured) is NaN and said so, its anchor
    kept at its known position. (MRCLAM DS6 with anchors 10, 17, 20 put it ~100 km away.)"""
    P, seen, r, _ = _simulate(n_steps=4000, max_range=5.0, seed=13)
    left = P[:, 1] < 5
    split = seen.copy()
    split[left, : seen.shape[1] // 2] = False
    split[~left, seen.shape[1] // 2:] = False
    L, R = np.flatnonzero(left), np.flatnonzero(~left)
    anchors = np.array([L[0], L[1], L[2], R[0]])
    X, mask = (np.where(split, r, 0.0), split) if method == "range-quantile" else (
        split.astype(float), None)
    sensor = "range" if method == "range-quantile" else "visibility"
    mm = masked_embedding(X, mask, sensor, method, anchor_ids=anchors, anchor_positions=P[anchors])
    lost = np.setdiff1d(R, anchors)
    assert np.isnan(mm.positions[lost]).all()
    assert set(mm.unmapped) == set(lost.tolist())
    assert np.array_equal(mm.positions[anchors], P[anchors])
    placed = np.setdiff1d(L, anchors)
    assert np.isfinite(mm.positions[placed]).all()
    assert np.abs(mm.positions[placed]).max() < 20  # in the layout's frame, not flung away
    assert any("fewer than 2 anchors" in w for w in mm.warnings)
    assert len(mm.components) == 2  # the data's groups, as measured


def test_no_group_with_two_anchors_is_a_clear_error():
    P, seen, _, _ = _simulate(n_steps=4500, max_range=5.0, seed=13)
    group = np.digitize(P[:, 1], [10 / 3, 20 / 3])  # three bands never sensed together
    split = seen.copy()
    third = seen.shape[1] // 3
    for g in range(3):
        split[group == g] &= (np.arange(seen.shape[1]) // third == g)[None, :]
    anchors = np.array([np.flatnonzero(group == g)[0] for g in range(3)])
    with pytest.raises(ValueError, match="no group holds 2 or more anchors"):
        masked_embedding(split.astype(float), None, "visibility", "covis-nonmetric",
                         anchor_ids=anchors, anchor_positions=P[anchors])


def test_window_steps_merges_ticks_per_robot_and_never_across_robots():
    from mappers.masked.ensemble import window_steps

    # two robots; robot 0 at ticks 0, 1, 2, 5 and robot 1 at ticks 0, 3
    timeline = np.array([[0, 0], [0, 1], [0, 2], [0, 5], [1, 0], [1, 3]])
    seen = np.array([[1, 0, 0, 0, 0, 1],
                     [0, 1, 0, 1, 1, 0]], dtype=bool)
    got = window_steps(seen, 2, timeline)
    # windows of 2 ticks: robot 0 -> {0,1}, {2}, {5}; robot 1 -> {0}, {3}
    assert got.tolist() == [[True, False, False, False, True],
                            [True, False, True, True, False]]
    assert window_steps(seen, 1, timeline).shape == (2, 6)  # one window per step
    assert window_steps(seen[:, :3], 2).tolist() == [[True, False], [True, False]]  # ticks 0-1, 2
    with pytest.raises(ValueError):
        window_steps(seen, 2, timeline[:-1])  # one timeline row per step
