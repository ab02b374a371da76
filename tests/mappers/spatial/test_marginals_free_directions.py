"""SPATIAL-BA's covariances for an object its posed steps fix only up to a turn: the left-out
image pairs of two objects give the turn's direction a finite, honest variance
(mappers/spatial/pair_distances.py, issue 35)."""

import functools
import warnings

import numpy as np
from scipy.spatial.transform import Rotation

from mappers.core.uncertainty import block_marginals, chi2_quantile, mahalanobis_squared
from mappers.spatial.marginals import spatial_covariances, spatial_held_out
from mappers.spatial.pair_distances import (
    complete_free_directions,
    left_out_pairs,
    pair_distance_information,
)
from mappers.spatial.spatial_ba import SpatialAdjustment

ANCHORS = np.arange(6)
TAG, A, B = 16, 6, 7  # the tag seen by one posed step, with A and B
PARTNERS = (8, 9, 10, 11)  # each seen with the tag alone in a step of two
NOISE_DEG, RANGE_NOISE = 0.5, 0.01
N_POSED = 30
FIT = {"loss": None}
"""Least squares: the residuals' variance then estimates the noise's (a robust loss's weights
estimate the inliers', smaller: with the default Cauchy loss 7 of 10 draws cover the tag)."""


def _looking_at(c, target, rng):
    """A rotation sensor -> world whose z axis points from ``c`` to ``target``."""
    z = (target - c) / np.linalg.norm(target - c)
    x = np.cross(z, rng.normal(size=3))
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def turn_world(seed):
    """One layout (17 objects in a 6 x 6 x 2 m room; 30 steps that each see 6-10 objects other
    than the tag, one step that sees the tag, A and B only, so the adjustment fixes the tag up
    to a turn about the line AB, and one step of two per partner: the tag and that partner)
    read with draw ``seed`` of the noise (rays ``NOISE_DEG``, ranges ``RANGE_NOISE``):
    ``(P, {"bearing", "range"})``."""
    rng = np.random.default_rng(0)
    P = rng.uniform([-3, -3, 0], [3, 3, 2], (17, 3))
    P[ANCHORS] = [[-3, -3, 0], [3, -3, 2], [3, 3, 0], [-3, 3, 2], [0, 0, 2], [0, -2, 0]]
    P[[A, B, TAG]] = [[-1.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.5]]
    seen = [rng.choice(np.r_[0:TAG], size=rng.integers(6, 11), replace=False)
            for _ in range(N_POSED)]
    seen += [np.array([TAG, A, B])] + [np.array([TAG, k]) for k in PARTNERS]
    n = len(seen)
    X, Rg = np.zeros((len(P), 3 * n)), np.zeros((len(P), n))
    noise = np.random.default_rng(1000 + seed)
    for t, objs in enumerate(seen):
        target = P[objs].mean(axis=0)
        c = target + rng.normal(size=3) * 0.3 - np.array([0.0, 0.0, 2.5])
        R = _looking_at(c, target, rng)
        v = (P[objs] - c) @ R
        d = np.linalg.norm(v, axis=1)
        turn = noise.normal(0, np.deg2rad(NOISE_DEG), v.shape)
        X[objs, 3 * t:3 * t + 3] = Rotation.from_rotvec(turn).apply(v / d[:, None])
        Rg[objs, t] = d + noise.normal(0, RANGE_NOISE, len(objs))
    return P, {"bearing": X, "range": Rg}


@functools.lru_cache(maxsize=1)
def _fit(seed):
    P, H = turn_world(seed)
    est = SpatialAdjustment(bearing_noise=float(np.deg2rad(NOISE_DEG)), range_noise=RANGE_NOISE, **FIT)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est.fit(H, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS])
    return P, est


def test_a_tag_fixed_up_to_a_turn_gets_a_finite_region_that_covers_it():
    inside, draws = 0, 5
    for seed in range(draws):
        P, est = _fit(seed)
        posed = np.isfinite(est.adjusted_.positions[:, 0])
        assert posed[N_POSED] and not posed[N_POSED + 1:].any()  # the tag's one posed step; the pairs left out
        assert np.all(np.isfinite(est.embedding_[TAG]))
        cov = spatial_covariances(est)
        assert np.all(np.isfinite(cov[TAG]))
        radius = np.sqrt(np.trace(cov[TAG]))
        assert 1e-3 < radius < 0.5  # finite and not "anywhere on the map"
        q = mahalanobis_squared((est.embedding_[TAG] - P[TAG])[None], cov[TAG][None])[0]
        inside += q <= chi2_quantile(3)
        if seed == 0:  # uncertainty=True's model covariances (spatial_held_out): the same rule
            np.testing.assert_allclose(spatial_held_out(est, P[ANCHORS], True)[2][TAG],
                                       cov[TAG], rtol=1e-6, atol=1e-12)
    assert inside >= draws - 1


def test_the_turn_is_unbounded_without_the_pairs():
    # the same linearisation without the left-out pairs: the tag is free to turn
    P, est = _fit(0)
    obs = est.observations_
    pairs = left_out_pairs(obs, np.isfinite(est.adjusted_.points[:, 0]),
                           np.isfinite(est.adjusted_.positions[:, 0]))
    assert sorted(sorted(p) for p in obs.obj[pairs].tolist()) == [[k, TAG] for k in PARTNERS]
    stripped = SpatialAdjustment(bearing_noise=est.bearing_noise, range_noise=est.range_noise)
    stripped.__dict__.update({k: v for k, v in est.__dict__.items() if k.endswith("_")})
    keep = obs.step <= N_POSED
    stripped.observations_ = obs._replace(step=obs.step[keep], obj=obs.obj[keep],
                                          ray=obs.ray[keep], range=obs.range[keep])
    cov = spatial_covariances(stripped)
    # (unbounded: infinite, or rounding's finite remainder of a zero eigenvalue, kilometres)
    assert not np.all(np.isfinite(cov[TAG])) or np.trace(cov[TAG]) > 1e6
    finite = np.setdiff1d(np.arange(len(P)), [*ANCHORS, TAG])
    assert np.all(np.isfinite(cov[finite]))
    assert np.all(np.trace(spatial_covariances(est)[finite], axis1=1, axis2=2) < 1.0)


def test_completion_keeps_the_fixed_objects_and_frees_what_nothing_fixes():
    rng = np.random.default_rng(3)
    J = rng.normal(size=(20, 9))
    J[:, 6:] = 0.0  # object 2 is unseen by the "adjustment"
    J[:, 3] = 0.0  # and object 1 is free along x
    S = J.T @ J
    before = block_marginals(S, 3)
    assert np.isinf(before[1]).any() and np.isinf(before[2]).any()
    np.testing.assert_array_equal(complete_free_directions(S, np.zeros((9, 9))), S)
    # a distance between object 1 and object 0 along x fixes object 1's free direction only
    m = np.zeros(9)
    m[0], m[3] = 1.0, -1.0
    D = 4.0 * np.outer(m, m)
    after = block_marginals(complete_free_directions(S, D), 3)
    np.testing.assert_allclose(after[0], before[0], rtol=1e-9, atol=1e-12)
    assert np.all(np.isfinite(after[1])) and np.isinf(after[2]).any()
    # along x, object 1 = object 0's x (its own error carried) + the distance's (variance 1/4)
    np.testing.assert_allclose(after[1][0, 0], before[0][0, 0] + 0.25, rtol=1e-9)
    # a positive definite information is returned as it is
    S2 = S + np.eye(9)
    np.testing.assert_array_equal(complete_free_directions(S2, D), S2)


def test_pair_distance_variance_is_the_sensors_propagated():
    # two objects straight ahead of the sensor at 1 m and 3 m: the distance runs along both rays,
    # so its variance is the two ranges' alone
    from mappers.spatial.rays import RayObservations
    obs = RayObservations(step=np.array([0, 0]), obj=np.array([0, 1]),
                          ray=np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]),
                          range=np.array([1.0, 3.0]), n_steps=1, n_objects=2)
    pts = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 3.0]])
    D = pair_distance_information(obs, pts, np.array([False]), np.array([0, -1]), 1,
                                  bearing_noise=0.01, range_noise=0.02, range_growth=0.01,
                                  loss=None, loss_scale=3.0)
    var = (0.02 + 0.01 * 1.0) ** 2 + (0.02 + 0.01 * 9.0) ** 2
    np.testing.assert_allclose(D, np.diag([0.0, 0.0, 1.0 / var]), atol=1e-12)
    # across the rays (side by side at 2 m): the angles' alone, r² σ_b² each
    obs = obs._replace(ray=np.array([[0.6, 0.0, 0.8], [-0.6, 0.0, 0.8]]), range=np.array([2.0, 2.0]))
    pts = np.array([[1.2, 0.0, 1.6], [-1.2, 0.0, 1.6]])
    D = pair_distance_information(obs, pts, np.array([False]), np.array([0, -1]), 1,
                                  bearing_noise=0.01, range_noise=0.02, range_growth=0.0,
                                  loss=None, loss_scale=3.0)
    cos = 0.6  # each ray's cosine to the pair's line (x)
    var = 2 * (cos**2 * 0.02**2 + 4.0 * 0.01**2 * (1 - cos**2))
    np.testing.assert_allclose(D[0, 0], 1.0 / var, rtol=1e-12)
