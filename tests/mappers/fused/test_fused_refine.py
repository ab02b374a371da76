"""Fused defaults refined by bundle adjustment: VB-SMA's ``refine`` (bearing-only, the bearing
part) and LOC-SMA's ``refine`` (range and angle residuals, mappers/viewpoints/range_bearing.py)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from mappers import build_map, mean_position_error
from mappers.fused.loc_sma import LawOfCosinesSMACOF
from mappers.fused.vb_sma import VisibilityBearingSMACOF
from mappers.viewpoints.range_bearing import RangeBearingAdjustment

pytestmark = pytest.mark.usefixtures("one_blas_thread")


def _walk(n_obj=24, n_steps=600, fov_deg=360.0, max_range=None, noise_deg=0.0, noise_r=0.0,
          seed=0):
    """Objects in a 2.5 m square (anchors at the corners) seen from random poses: positions,
    anchors, visibility (within 0.6 m), range and bearing histories and the camera's mask."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(-1.2, 1.2, size=(n_obj, 2))
    P[:4] = [(-1.25, -1.25), (1.25, -1.25), (1.25, 1.25), (-1.25, 1.25)]
    poses = np.column_stack([rng.uniform(-1.1, 1.1, (n_steps, 2)),
                             rng.uniform(-np.pi, np.pi, n_steps)])
    d = P[:, None, :] - poses[None, :, :2]
    r = np.hypot(d[..., 0], d[..., 1])
    th = np.arctan2(d[..., 1], d[..., 0]) - poses[None, :, 2]
    th = np.angle(np.exp(1j * th))
    seen = (np.abs(th) <= np.radians(fov_deg) / 2) & (r <= (np.inf if max_range is None else max_range))
    th = th + rng.normal(0.0, np.radians(noise_deg), th.shape)
    r = np.abs(r + rng.normal(0.0, noise_r, r.shape))
    V = (r < 0.6).astype(float)
    B = np.zeros((n_obj, 2 * n_steps))
    B[:, 0::2], B[:, 1::2] = np.where(seen, np.cos(th), 0.0), np.where(seen, np.sin(th), 0.0)
    R = np.where(seen, r, 0.0)
    return P, np.arange(4), V, R, B, seen


def _mpe(Y, P, anchors):
    return mean_position_error(Y, P, exclude=list(anchors))


def test_vb_sma_default_is_as_good_as_bearing_ba_on_the_bearing_part():
    P, anchors, V, _, B, _ = _walk(noise_deg=5.0, seed=1)
    fix = dict(anchor_ids=anchors, anchor_positions=P[anchors])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fused = build_map({"visibility": V, "bearing": B}, anchors, P[anchors])
        alone = build_map(B, anchors, P[anchors], sensor="bearing")
        paper = VisibilityBearingSMACOF(refine=False, random_state=0).fit({"visibility": V,
                                                                           "bearing": B}, **fix)
    assert fused.method == "VB-SMA" and fused.params["refine"] is True
    assert alone.method == "BEARING-BA"
    e_fused, e_alone = _mpe(fused.positions, P, anchors), _mpe(alone.positions, P, anchors)
    assert e_fused <= 1.02 * e_alone + 1e-6
    assert e_fused < 0.5 * _mpe(paper.embedding_, P, anchors)  # the refinement's gain
    # refine=False is the paper-era blend, untouched
    assert paper.adjustment_ is None
    np.testing.assert_array_equal(paper.embedding_, paper.blend_embedding_)


def test_vb_sma_refined_from_perfect_bearings_is_nearly_exact():
    P, anchors, V, _, B, _ = _walk(seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = build_map({"visibility": V, "bearing": B}, anchors, P[anchors])
        alone = build_map(B, anchors, P[anchors], sensor="bearing")
    e = _mpe(m.positions, P, anchors)
    assert e < 1e-3  # the blend alone: about 0.02 m
    assert e <= _mpe(alone.positions, P, anchors) + 1e-4


@pytest.mark.parametrize("bad", ["yes", 2, None])
def test_vb_sma_refuses_a_bad_refine(bad):
    P, anchors, V, _, B, _ = _walk(n_steps=100, seed=3)
    with pytest.raises(ValueError, match="refine"):
        build_map({"visibility": V, "bearing": B}, anchors, P[anchors], refine=bad)


def test_loc_sma_range_bearing_refinement_beats_the_law_of_cosines_map():
    P, anchors, _, R, B, seen = _walk(fov_deg=120.0, max_range=1.5, noise_deg=3.0, noise_r=0.03,
                                      n_steps=1500, seed=4)
    H, masks = {"range": R, "bearing": B}, {"range": seen, "bearing": np.repeat(seen, 2, axis=1)}
    fix = dict(anchor_ids=anchors, anchor_positions=P[anchors])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain = LawOfCosinesSMACOF(refine=None, random_state=0).fit(H, masks=masks, **fix)
        refined = LawOfCosinesSMACOF(random_state=0).fit(H, masks=masks, **fix)  # the default
    assert plain.adjustment_ is None and refined.adjustment_.refined_
    assert _mpe(refined.embedding_, P, anchors) < 0.8 * _mpe(plain.embedding_, P, anchors)
    scale_a, scale_r = refined.adjustment_.scales_
    assert 0.5 < np.degrees(scale_a) / 3.0 < 1.5 and 0.5 < scale_r / 0.03 < 1.5


def test_range_bearing_adjustment_is_exact_on_perfect_readings_and_keeps_unplaced_rows():
    P, anchors, _, R, B, seen = _walk(fov_deg=90.0, n_steps=800, seed=5)
    H, masks = {"range": R, "bearing": B}, {"range": seen, "bearing": np.repeat(seen, 2, axis=1)}
    start = P + np.random.default_rng(0).normal(0.0, 0.05, P.shape)
    start[7] = np.nan
    rba = RangeBearingAdjustment().fit(H, masks=masks, anchor_ids=anchors,
                                       anchor_positions=P[anchors], start_positions=start)
    Y = rba.embedding_
    assert np.all(np.isnan(Y[7]))
    keep = np.setdiff1d(np.arange(len(P)), [7])
    np.testing.assert_allclose(Y[keep], P[keep], atol=1e-5)


def test_range_bearing_adjustment_on_the_sparse_engine_maps_as_the_dense_one():
    """Issue 34: the joint step through the sparse Schur engine (forced) gives the dense map."""
    P, anchors, _, R, B, seen = _walk(fov_deg=120.0, max_range=1.5, noise_deg=2.0, noise_r=0.02,
                                      n_steps=600, seed=6)
    H, masks = {"range": R, "bearing": B}, {"range": seen, "bearing": np.repeat(seen, 2, axis=1)}
    start = P + np.random.default_rng(1).normal(0.0, 0.05, P.shape)
    fix = dict(anchor_ids=anchors, anchor_positions=P[anchors], start_positions=start)
    dense = RangeBearingAdjustment().fit(H, masks=masks, **fix)
    sparse = RangeBearingAdjustment(dense_coupling_bytes=0).fit(H, masks=masks, **fix)
    assert dense.refined_ and _mpe(dense.embedding_, P, anchors) < 0.5 * _mpe(start, P, anchors)
    np.testing.assert_allclose(sparse.embedding_, dense.embedding_, rtol=0, atol=1e-7)


@pytest.mark.parametrize("params, match", [({"refine": "range"}, "refine"),
                                            ({"refine": True}, "refine")])
def test_loc_sma_refuses_a_bad_refine(params, match):
    P, anchors, _, R, B, _ = _walk(n_steps=100, seed=6)
    with pytest.raises(ValueError, match=match):
        build_map({"range": R, "bearing": B}, anchors, P[anchors], **params)


@pytest.mark.parametrize("params", [{"passes": 0}, {"robust_scale": 0.0}, {"loss": "l1"},
                                    {"min_views": 1}])
def test_range_bearing_adjustment_refuses_bad_parameters(params):
    P, anchors, _, R, B, _ = _walk(n_steps=50, seed=7)
    with pytest.raises(ValueError):
        RangeBearingAdjustment(**params).fit({"range": R, "bearing": B}, anchor_ids=anchors,
                                             anchor_positions=P[anchors], start_positions=P)
