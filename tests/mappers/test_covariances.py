"""build_map(uncertainty=...): Map.covariances from the adjustments' normal equations and from a
bootstrap over steps (mappers.covariances)."""

import warnings

import numpy as np
import pytest

from mappers import build_map
from mappers.core.uncertainty import coverage
from tests.synthetic_walk import ANCHORS, layout, sensed, walk


def _bearing(seed, n_objects=16, n_steps=150, noise_deg=2.0):
    P, poses = layout(n_objects, seed), walk(n_steps, seed=seed)
    _, b, _ = sensed(P, poses)
    b = b + np.random.default_rng(seed).normal(0.0, np.radians(noise_deg), b.shape)
    return P, np.stack([np.cos(b), np.sin(b)], -1).reshape(len(P), -1)


def _quiet(*args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return build_map(*args, **kwargs)


def _check_shape(m, n_objects):
    cov = m.covariances
    assert cov.shape == (n_objects, 2, 2)
    np.testing.assert_array_equal(cov[ANCHORS], 0.0)
    others = np.setdiff1d(np.arange(n_objects), [*ANCHORS, *m.unmapped])
    np.testing.assert_allclose(cov[others], cov[others].transpose(0, 2, 1), atol=1e-15)
    assert np.all(np.linalg.eigvalsh(cov[others]) > 0)


def test_no_uncertainty_changes_nothing():
    P, X = _bearing(0)
    plain = _quiet(X, ANCHORS, P[ANCHORS])
    with_cov = _quiet(X, ANCHORS, P[ANCHORS], uncertainty=True)
    assert plain.covariances is None
    np.testing.assert_array_equal(plain.positions, with_cov.positions)
    assert plain.method == with_cov.method == "BEARING-BA"
    _check_shape(with_cov, len(P))


def test_unmapped_objects_get_nan():
    P, X = _bearing(1)
    X[7] = 0.0  # never sensed
    m = _quiet(X, ANCHORS, P[ANCHORS], uncertainty="model")
    assert 7 in m.unmapped and np.isnan(m.covariances[7]).all()
    _check_shape(m, len(P))


def test_model_needs_an_adjustment():
    P, X = _bearing(2)
    with pytest.raises(ValueError, match="bundle adjustment"):
        _quiet(X, ANCHORS, P[ANCHORS], "CAL-SMA", uncertainty="model")
    with pytest.raises(ValueError, match="uncertainty must be one of"):
        _quiet(X, ANCHORS, P[ANCHORS], uncertainty="exact")


def test_floor_is_the_model_plus_a_share_of_the_anchors_extent():
    from mappers.core.uncertainty import SYSTEMATIC_FLOOR

    P, X = _bearing(2)
    model = _quiet(X, ANCHORS, P[ANCHORS], uncertainty="model")
    floor = _quiet(X, ANCHORS, P[ANCHORS], uncertainty="floor")
    np.testing.assert_array_equal(floor.positions, model.positions)
    np.testing.assert_array_equal(floor.covariances[ANCHORS], 0.0)
    others = np.setdiff1d(np.arange(len(P)), [*ANCHORS, *model.unmapped])
    extent = np.max(np.linalg.norm(P[ANCHORS][:, None] - P[ANCHORS][None], axis=2))
    np.testing.assert_allclose(floor.covariances[others] - model.covariances[others],
                               np.broadcast_to((SYSTEMATIC_FLOOR * extent) ** 2 * np.eye(2),
                                               (len(others), 2, 2)), rtol=1e-9, atol=1e-15)
    with pytest.raises(ValueError, match="uncertainty='floor' needs a method"):
        _quiet(X, ANCHORS, P[ANCHORS], "CAL-SMA", uncertainty="floor")


def test_model_covariances_beyond_the_dense_coupling_are_refused():
    """Issue 34: an adjustment on the sparse engine has no dense normal equations to invert."""
    P, X = _bearing(3)
    with pytest.raises(ValueError, match="dense_coupling_bytes.*bootstrap"):
        _quiet(X, ANCHORS, P[ANCHORS], "BEARING-BA", uncertainty="model", dense_coupling_bytes=0)


def test_a_compact_history_gets_the_dense_historys_model_covariances():
    import scipy.sparse as sp

    P, X = _bearing(4)
    dense = _quiet(X, ANCHORS, P[ANCHORS], "BEARING-BA", uncertainty="model")
    compact = _quiet(sp.csr_array(X), ANCHORS, P[ANCHORS], "BEARING-BA", sensor="bearing",
                     uncertainty="model")
    np.testing.assert_array_equal(compact.positions, dense.positions)
    np.testing.assert_allclose(compact.covariances, dense.covariances, rtol=1e-12, atol=0)


def test_bearing_model_covers_the_truth():
    """2-degree noise, 10 layouts: the 95 % regions hold most true positions, and are not
    merely wide (RMS radius of the ellipses a few times the mean error)."""
    inside, radius, error = [], [], []
    for seed in range(10):
        P, X = _bearing(seed)
        m = _quiet(X, ANCHORS, P[ANCHORS], uncertainty="model")
        objects = np.setdiff1d(np.arange(len(P)), ANCHORS)
        inside.append(coverage(m.positions, m.covariances, P, objects))
        radius.append(np.sqrt(np.trace(m.covariances[objects], axis1=1, axis2=2)).mean())
        error.append(np.linalg.norm(m.positions[objects] - P[objects], axis=1).mean())
    assert 0.8 <= np.mean(inside) <= 1.0
    assert 0.5 < np.mean(radius) / np.mean(error) < 3.0


def test_range_bearing_model():
    P, poses = layout(16, 3), walk(150, seed=3)
    dist, b, _ = sensed(P, poses)
    rng = np.random.default_rng(3)
    b = b + rng.normal(0.0, np.radians(2.0), b.shape)
    H = {"range": np.abs(dist + rng.normal(0.0, 0.02, dist.shape)),
         "bearing": np.stack([np.cos(b), np.sin(b)], -1).reshape(len(P), -1)}
    m = _quiet(H, ANCHORS, P[ANCHORS], uncertainty=True)
    assert m.method == "LOC-SMA"
    _check_shape(m, len(P))
    # about 1 cm of error: ellipses of millimetres to centimetres
    assert 1e-4 < np.sqrt(np.trace(m.covariances[4:], axis1=1, axis2=2)).mean() < 0.05


def test_bootstrap_of_a_visibility_map():
    P, poses = layout(12, 4), walk(150, seed=4)
    X = (sensed(P, poses)[0] < 0.4).astype(float)
    m = _quiet(X, ANCHORS, P[ANCHORS], uncertainty="bootstrap")  # (True: the jackknife)
    assert m.method == "CAL-SMA"
    _check_shape(m, len(P))
    # centimetres of spread for centimetres of error, not metres or microns
    radius = np.sqrt(np.trace(m.covariances[4:], axis1=1, axis2=2)).mean()
    error = np.linalg.norm(m.positions[4:] - P[4:], axis=1).mean()
    assert 0.2 < radius / error < 5.0


def _offset_bearings():
    """A layout of 16 objects and its bearing history (0.5 degrees of noise) sensed where the
    objects are not: a fixed offset of 4 cm each, which the readings' residuals cannot see."""
    P, poses = layout(16, 3), walk(150, seed=3)
    offset = np.random.default_rng(3).normal(0.0, 0.04, P.shape)
    _, b, _ = sensed(P + offset, poses)
    b = b + np.random.default_rng(4).normal(0.0, np.radians(0.5), b.shape)
    return P, np.stack([np.cos(b), np.sin(b)], -1).reshape(len(P), -1)


def test_held_out_anchors_widen_covariances_that_miss_a_systematic_error():
    # every object is sensed where it is not: a fixed offset of 4 cm each (a landmark's marker
    # off its surveyed centre), which the readings' residuals cannot see: the model's ellipses
    # miss it, the held-out anchors see it and widen them
    P, X = _offset_bearings()
    model = _quiet(X, ANCHORS, P[ANCHORS], uncertainty="model")
    checked = _quiet(X, ANCHORS, P[ANCHORS], uncertainty="anchors")
    np.testing.assert_array_equal(checked.positions, model.positions)
    note = [w for w in checked.warnings if "held-out anchors" in w]
    assert note and "multiplied by" in note[0]
    others = np.setdiff1d(np.arange(len(P)), [*ANCHORS, *model.unmapped])
    ratio = checked.covariances[others] / model.covariances[others]
    assert np.allclose(ratio, ratio.flat[0]) and ratio.flat[0] > 2
    np.testing.assert_array_equal(checked.covariances[ANCHORS], 0.0)
    assert coverage(checked.positions, checked.covariances, P, others) > coverage(
        model.positions, model.covariances, P, others)


def test_true_adds_the_floor_its_held_out_anchors_estimate():
    # Issue 35: the systematic offset above, which the model's ellipses miss, is what the
    # anchors released from the adjustment see; True adds it as one isotropic floor
    P, X = _offset_bearings()
    model = _quiet(X, ANCHORS, P[ANCHORS], uncertainty="model")
    m = _quiet(X, ANCHORS, P[ANCHORS], uncertainty=True)
    np.testing.assert_array_equal(m.positions, model.positions)
    np.testing.assert_array_equal(m.covariances[ANCHORS], 0.0)
    assert any("systematic floor" in w for w in m.warnings)
    others = np.setdiff1d(np.arange(len(P)), [*ANCHORS, *model.unmapped])
    added = m.covariances[others] - model.covariances[others]
    floor = added[0, 0, 0]
    np.testing.assert_allclose(added, np.broadcast_to(floor * np.eye(2), added.shape),
                               rtol=1e-9, atol=1e-12 * floor)
    assert 0.01 < np.sqrt(floor) < 0.2  # the offsets' size (4 cm per axis), not the noise's
    assert coverage(m.positions, m.covariances, P, others) >= 0.8 > coverage(
        model.positions, model.covariances, P, others)


def test_true_keeps_a_model_its_anchors_agree_with():
    # simulated bearings with the noise the model assumes: the anchors fall inside their
    # regions, so True adds no floor (seed chosen so; the floor is then exactly 0)
    P, X = _bearing(2)
    model = _quiet(X, ANCHORS, P[ANCHORS], uncertainty="model")
    m = _quiet(X, ANCHORS, P[ANCHORS], uncertainty=True)
    # (from one linearisation with the anchors' columns: equal to rounding)
    np.testing.assert_allclose(m.covariances, model.covariances, rtol=1e-9, atol=1e-18)
    assert not any("systematic floor" in w for w in m.warnings)


def test_without_two_held_out_anchors_true_falls_back_to_the_fixed_floor():
    from mappers.covariances import with_held_out_floor

    P, X = _bearing(2)
    model = _quiet(X, ANCHORS, P[ANCHORS], uncertainty="model")
    floor = _quiet(X, ANCHORS, P[ANCHORS], uncertainty="floor")
    a = len(ANCHORS)
    one = np.full((a, 2), np.nan)
    one[0] = P[ANCHORS[0]] + 0.5  # one anchor held out, far off: still too few to estimate
    covs = np.full((a, 2, 2), np.nan)
    covs[0] = 1e-4 * np.eye(2)
    m = with_held_out_floor(model, one, covs, P[ANCHORS])
    np.testing.assert_allclose(m.covariances, floor.covariances, rtol=1e-12, equal_nan=True)
    assert "only 1 of" in m.warnings[-1] and "fixed systematic floor" in m.warnings[-1]


def test_released_anchor_is_placed_by_the_readings_and_the_other_anchors():
    from mappers.core.uncertainty import mahalanobis_squared
    from mappers.viewpoints import BearingAdjustment, released_anchor

    P, X = _bearing(1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = BearingAdjustment().fit(X, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS])
        p, c = released_anchor(est, X, None, ANCHORS, P[ANCHORS], 2)
    assert np.all(np.linalg.eigvalsh(c) > 0)
    assert 0.0 < np.linalg.norm(p - P[2]) < 0.05  # freed: moved, but by the readings' noise
    assert mahalanobis_squared((p - P[2])[None], c[None])[0] < 30.0
