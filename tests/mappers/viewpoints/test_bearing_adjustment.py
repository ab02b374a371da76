"""BEARING-BA (mappers/viewpoints/bearing.py): bearing-only bundle adjustment of a bearing map."""

from __future__ import annotations

import numpy as np
import pytest
from map_errors import non_anchor_error
from synthetic_camera import camera_bearings

from mappers import build_map
from mappers.catalog import methods_for, resolve_method
from mappers.defaults import DEFAULT_METHODS
from mappers.pipeline import default_method
from mappers.viewpoints import engine
from mappers.viewpoints.bearing import BearingAdjustment, BearingAdjustmentWarning

pytestmark = pytest.mark.usefixtures("one_blas_thread")


def _camera(fov_deg=360.0, max_range=None, n_obj=24, n_steps=600, noise_deg=0.0, seed=0):
    """Objects in a 2.5 m square seen from random poses: positions, the (M, 2N) bearing
    history, its mask (None when every object is seen at every step), anchors near the corners."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(-1.2, 1.2, size=(n_obj, 2))
    corners = np.array([(-1.25, -1.25), (1.25, -1.25), (1.25, 1.25), (-1.25, 1.25)])
    P[:4] = corners
    poses = np.column_stack([rng.uniform(-1.1, 1.1, (n_steps, 2)), rng.uniform(-np.pi, np.pi, n_steps)])
    X, seen = camera_bearings(P, poses, fov_deg, max_range, noise_deg, rng)
    mask = None if seen.all() else np.repeat(seen, 2, axis=1)
    return P, X, mask, np.arange(4)


def test_registered_for_complete_and_masked_bearing_histories():
    assert "BEARING-BA" in methods_for("bearing", masked=False)
    assert "BEARING-BA" in methods_for("bearing", masked=True)
    assert "BEARING-BA" not in methods_for("visibility")


def test_it_is_the_bearing_default_below_the_scalable_size():
    P, X, mask, ids = _camera(fov_deg=90, n_steps=200)
    assert DEFAULT_METHODS[("bearing", False)] == DEFAULT_METHODS[("bearing", True)] == "BEARING-BA"
    assert default_method(X, sensor="bearing", mask=mask) == "BEARING-BA"
    large_masked = resolve_method(None, "bearing", masked=True, n_objects=1000)
    assert large_masked.label == "BEARING-BA" and large_masked.defaults["start"] == "COVIS-SPARSE"
    large = resolve_method(None, "bearing", n_objects=1000)
    assert large.label == "CAL-SMA" and large.defaults["sparse"] is True


def test_exact_bearings_recover_the_layout_from_a_perturbed_start():
    P, X, mask, ids = _camera()
    start = P + np.random.default_rng(1).normal(scale=0.05, size=P.shape)
    est = BearingAdjustment()
    Y = est.fit_transform(X, mask=mask, anchor_ids=ids, anchor_positions=P[ids],
                          start_positions=start)
    assert est.refined_ and non_anchor_error(start, P, ids) > 0.03
    assert np.abs(Y - P).max() < 1e-6
    assert np.abs(est.poses_[:, 2] - np.nan_to_num(est.poses_[:, 2])).max() == 0  # every step posed


def test_build_map_refines_the_default_start_on_a_complete_history():
    P, X, mask, ids = _camera()
    ref = build_map(X, ids, P[ids], "CAL-SMA", sensor="bearing")
    m = build_map(X, ids, P[ids], "BEARING-BA", sensor="bearing")
    assert m.method == "BEARING-BA" and not m.warnings
    assert non_anchor_error(ref.positions, P, ids) > 1e-3
    assert non_anchor_error(m.positions, P, ids) < 1e-6


def test_noisy_masked_bearings_improve_on_the_start():
    P, X, mask, ids = _camera(fov_deg=90, max_range=1.8, n_steps=1500, noise_deg=2.0, seed=3)
    ref = build_map(X, ids, P[ids], "COVIS-AUTO", sensor="bearing", mask=mask)
    m = build_map(X, ids, P[ids], "BEARING-BA", sensor="bearing", mask=mask)
    assert non_anchor_error(m.positions, P, ids) < 0.5 * non_anchor_error(ref.positions, P, ids)


def test_objects_seen_from_too_few_steps_keep_their_start_with_a_warning():
    P, X, mask, ids = _camera(fov_deg=120, n_steps=800, seed=5)
    mask = np.ones(X.shape, bool) if mask is None else mask.copy()
    rare = 10
    seen_steps = np.flatnonzero(mask[rare, 0::2])
    mask[rare, 2 * seen_steps[3:]] = mask[rare, 2 * seen_steps[3:] + 1] = False  # 3 views left
    X = np.where(mask, X, 0.0)
    start = P + np.random.default_rng(2).normal(scale=0.03, size=P.shape)
    est = BearingAdjustment(max_rounds=30)  # converged: the default's 6 rounds leave ~4e-4 m
    with pytest.warns(BearingAdjustmentWarning, match=rf"objects \[{rare}\] are seen from too few"):
        Y = est.fit_transform(X, mask=mask, anchor_ids=ids, anchor_positions=P[ids],
                              start_positions=start)
    assert np.array_equal(Y[rare], start[rare]) and est.kept_.tolist() == [rare]
    others = np.setdiff1d(np.arange(len(P)), [*ids, rare])
    assert np.abs(Y[others] - P[others]).max() < 1e-5
    m = build_map(X, ids, P[ids], "BEARING-BA", sensor="bearing", mask=mask)
    assert any("too few steps" in w and str(rare) in w for w in m.warnings)


def test_a_refinement_that_fails_keeps_the_start_with_a_warning(monkeypatch):
    P, X, mask, ids = _camera(seed=7)
    start = P + 0.02

    def broken(self, P, C, phi, obs, wb, free, scale):
        return P + np.nan, C, phi, wb, 1

    monkeypatch.setattr(BearingAdjustment, "_joint", broken)
    est = BearingAdjustment()
    with pytest.warns(BearingAdjustmentWarning, match="start map is kept"):
        Y = est.fit_transform(X, mask=mask, anchor_ids=ids, anchor_positions=P[ids],
                              start_positions=start)
    assert not est.refined_ and np.all(np.isfinite(Y))
    assert np.array_equal(Y[4:], start[4:]) and np.array_equal(Y[ids], P[ids])


def test_the_alternating_solver_approaches_exact_bearings_slowly():
    P, X, mask, ids = _camera(seed=4, n_steps=300)
    start = P + np.random.default_rng(3).normal(scale=0.02, size=P.shape)
    Y = BearingAdjustment(solver="alternate", max_rounds=40, tol=1e-9).fit_transform(
        X, mask=mask, anchor_ids=ids, anchor_positions=P[ids], start_positions=start)
    assert non_anchor_error(Y, P, ids) < 0.1 * non_anchor_error(start, P, ids)  # linear convergence: joint is default


def test_bad_input_is_a_clear_value_error():
    P, X, mask, ids = _camera(n_steps=100)
    vis = (np.random.default_rng(0).random((len(P), 100)) < 0.5).astype(float)
    est = BearingAdjustment()
    with pytest.raises(ValueError, match="does not map visibility histories"):
        build_map(vis, ids, P[ids], "BEARING-BA", sensor="visibility")
    with pytest.raises(ValueError, match=r"unit \(cos, sin\) pairs"):
        est.fit_transform(np.repeat(vis, 2, axis=1), anchor_ids=ids, anchor_positions=P[ids])
    with pytest.raises(ValueError, match="BEARING-BA maps bearing histories, got a visibility"):
        est.fit_transform(X, sensor="visibility", anchor_ids=ids, anchor_positions=P[ids])
    with pytest.raises(ValueError, match=r"2 columns \(cos, sin\) per step"):
        est.fit_transform(X[:, :-1], anchor_ids=ids, anchor_positions=P[ids])
    with pytest.raises(ValueError, match="mask must have the shape"):
        est.fit_transform(X, mask=np.ones((3, 3), bool), anchor_ids=ids, anchor_positions=P[ids])
    with pytest.raises(ValueError, match="start_positions must have shape"):
        est.fit_transform(X, anchor_ids=ids, anchor_positions=P[ids], start_positions=P[:5])
    with pytest.raises(ValueError, match="needs anchor_ids"):
        est.fit_transform(X)
    with pytest.raises(ValueError, match="another method than 'BEARING-BA'"):
        BearingAdjustment(start="bearing-ba").fit_transform(X, anchor_ids=ids,
                                                            anchor_positions=P[ids])
    with pytest.raises(ValueError, match="bad parameters|loss"):
        build_map(X, ids, P[ids], "BEARING-BA", sensor="bearing", loss="square")


def test_wrapped_residuals_stay_in_minus_pi_pi():
    a = np.array([-7.0, -np.pi, 0.0, 3.5, 10.0])
    w = engine.wrap_angles(a)
    assert np.all((w >= -np.pi) & (w < np.pi))
    assert np.allclose(np.exp(1j * w), np.exp(1j * a))
