"""Classical metric unfolding of range histories (UNFOLD, the range default)."""

from __future__ import annotations

import numpy as np
import pytest

from mappers import (
    DEFAULT_METHODS,
    METHODS,
    ClassicalUnfolding,
    MappingError,
    build_map,
    mean_position_error,
)


def _ranges(n_obj=30, n_steps=400, noise=0.0, seed=0):
    rng = np.random.default_rng(seed)
    P = rng.uniform(-1.2, 1.2, size=(n_obj, 2))
    robot = rng.uniform(-1.25, 1.25, size=(n_steps, 2))  # any path: unfolding never uses it
    R = np.linalg.norm(P[:, None, :] - robot[None], axis=2)
    R = np.abs(R + noise * rng.standard_normal(R.shape))
    anchors = np.array([int(np.argmin(np.linalg.norm(P - c, axis=1)))
                        for c in ([-1.2, -1.2], [1.2, -1.2], [1.2, 1.2], [-1.2, 1.2])])
    return P, R, anchors


def test_exact_ranges_give_the_exact_map_and_rank_two():
    P, R, a = _ranges()
    est = ClassicalUnfolding()
    Y = est.fit_transform(R)
    assert Y.shape == (30, 2)
    s = est.singular_values_
    assert s[2] < 1e-9 * s[0]  # the double-centred squared ranges are rank 2
    m = build_map(R, a, P[a])  # the range default, raw ranges (no row normalisation)
    assert m.method == "UNFOLD" == DEFAULT_METHODS[("range", False)] and m.sensor == "range"
    np.testing.assert_allclose(m.positions, P, atol=1e-8)


def test_noisy_ranges_degrade_gracefully_and_beat_smacof():
    P, R, a = _ranges(noise=0.05, seed=1)
    keep = np.setdiff1d(np.arange(len(P)), a)
    unfold = build_map(R, a, P[a], "UNFOLD").positions
    sma = build_map(R, a, P[a], "SMA(WGT)").positions
    e_unfold = mean_position_error(unfold[keep], P[keep])
    assert e_unfold < 0.02
    assert e_unfold < 0.5 * mean_position_error(sma[keep], P[keep])


def test_refuses_other_sensors_normalisation_and_unsensed_zeros():
    P, R, a = _ranges(n_steps=100)
    vis = (R < 0.8).astype(float)
    with pytest.raises(ValueError, match="maps range histories only"):
        build_map(vis, a, P[a], "UNFOLD", sensor="visibility")
    with pytest.raises(ValueError, match="raw histories"):
        build_map(R, a, P[a], "UNFOLD", normalize=True)
    far = np.where(R > 2.0, 0.0, R)  # a max_range sensor: 0 = not sensed
    assert (far == 0).any()
    with pytest.raises(ValueError, match=r"range\(s\) are 0, i.e. not sensed"):
        build_map(far, a, P[a], "UNFOLD", sensor="range")
    with pytest.raises(ValueError, match="Negative values"):
        ClassicalUnfolding().fit_transform(-R)
    # the estimator alone takes 0 as a distance unless told that 0 means "not sensed"
    assert np.isfinite(ClassicalUnfolding().fit_transform(far)).all()
    with pytest.raises(ValueError, match="not sensed"):
        ClassicalUnfolding(zero_is_missing=True).fit_transform(far)


def test_collinear_robot_path_is_a_mapping_error():
    rng = np.random.default_rng(3)
    P = rng.uniform(-1, 1, size=(10, 2))
    robot = np.column_stack([np.linspace(-1, 1, 50), np.zeros(50)])  # one line: rank 1
    R = np.linalg.norm(P[:, None] - robot[None], axis=2)
    with pytest.raises(MappingError, match="UNFOLD"):
        ClassicalUnfolding().fit_transform(R)


def test_registered_for_range_only_and_left_out_of_other_tables():
    from lfmdr_gym.experiments.protocol import ProtocolConfig, resolve_methods

    assert METHODS["UNFOLD"].sensors == ("range",) and not METHODS["UNFOLD"].normalize
    assert "UNFOLD" not in ProtocolConfig(mode="visibility").methods
    assert "UNFOLD" not in ProtocolConfig(mode="bearing").methods
    with pytest.raises(ValueError, match="does not map bearing histories"):
        resolve_methods(["unfold"], "bearing")
    assert resolve_methods(["unfold"], "range") == ("UNFOLD",)
    from mappers import MethodSpec, register_method

    for bad in (("sonar",), "range", ()):
        with pytest.raises(ValueError, match="sensors must be None or a non-empty tuple"):
            register_method(MethodSpec("BAD-SENSORS", ClassicalUnfolding, sensors=bad))
    assert "BAD-SENSORS" not in METHODS
