"""Held-out anchors by one Gauss-Newton step (``released_steps``): the prediction a released
anchor gets from an adjustment fitted again, at the cost of a solve, and ``uncertainty="anchors"``
built on it without mapping again."""

import warnings

import numpy as np

from mappers import build_map
from mappers.spatial.marginals import spatial_held_out
from mappers.spatial.pipeline_3d import fit_map_3d
from mappers.viewpoints import (
    BearingAdjustment,
    RangeBearingAdjustment,
    held_out_anchors,
    released_anchor,
)
from tests.mappers.spatial.test_spatial_ba import ANCHORS as ANCHORS_3D
from tests.mappers.spatial.test_spatial_ba import camera_world
from tests.synthetic_walk import ANCHORS, layout, sensed, walk


def _histories(seed):
    P, poses = layout(16, seed), walk(150, seed=seed)
    dist, b, _ = sensed(P, poses)
    rng = np.random.default_rng(seed)
    b = b + rng.normal(0.0, np.radians(2.0), b.shape)
    return P, {"range": np.abs(dist + rng.normal(0.0, 0.02, dist.shape)),
               "bearing": np.stack([np.cos(b), np.sin(b)], -1).reshape(len(P), -1)}


def test_planar_linearised_anchor_is_the_refitted_adjustments():
    # each anchor released: the one-step prediction lies where the adjustment fitted again from
    # the map puts it (to a small part of its displacement) and has its covariance
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for seed, kind in ((1, "bearing"), (2, "range-bearing")):
            P, H = _histories(seed)
            if kind == "bearing":
                X, est = H["bearing"], BearingAdjustment()
                est.fit(X, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS])
            else:
                X, est = H, RangeBearingAdjustment()
                start = P + np.random.default_rng(seed).normal(0.0, 0.02, P.shape)
                est.fit(X, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS],
                        start_positions=start)
            pos, cov = held_out_anchors(est, X, None, ANCHORS)
            assert pos.shape == (4, 2) and cov.shape == (4, 2, 2)
            for j in range(len(ANCHORS)):
                p, c = released_anchor(est, X, None, ANCHORS, P[ANCHORS], j)
                moved = np.linalg.norm(p - P[j])
                assert moved > 1e-4  # released: the readings move it
                assert np.linalg.norm(pos[j] - p) < 0.3 * moved + 2e-4, (kind, j)
                np.testing.assert_allclose(np.trace(cov[j]), np.trace(c), rtol=0.3)


def test_spatial_linearised_anchor_is_the_map_without_it():
    # 3-D, anchors held exactly and by a prior (anchor_noise, STAR-loc's setting): the one-step
    # prediction of each released anchor is where a map made without it puts it
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        P, X, Rg = camera_world(seed=0, noise_deg=1.0, range_noise=0.02)
        H = {"bearing": X, "range": Rg}
        for kw in ({}, {"anchor_noise": 0.03}):
            _, est, *_ = fit_map_3d(H, ANCHORS_3D, P[ANCHORS_3D], None, **kw)
            pos, cov = spatial_held_out(est, P[ANCHORS_3D])
            for j in (4,):
                keep = ANCHORS_3D != j
                m = build_map(H, ANCHORS_3D[keep], P[ANCHORS_3D[keep]], uncertainty=True, **kw)
                moved = np.linalg.norm(m.positions[j] - P[j])
                assert moved > 0.01
                assert np.linalg.norm(pos[j] - m.positions[j]) < 0.2 * moved, (kw, j)
                np.testing.assert_allclose(np.trace(cov[j]), np.trace(m.covariances[j]),
                                           rtol=0.2)


def test_anchors_check_of_an_adjustment_maps_once(monkeypatch):
    # the check of a method with an adjustment needs no map without each anchor: build_map is
    # entered once, and the held-out anchors still see the systematic error of
    # test_covariances' offset landmarks
    import mappers.pipeline as pipeline

    P, poses = layout(16, 3), walk(150, seed=3)
    offset = np.random.default_rng(3).normal(0.0, 0.04, P.shape)
    _, b, _ = sensed(P + offset, poses)
    b = b + np.random.default_rng(4).normal(0.0, np.radians(0.5), b.shape)
    X = np.stack([np.cos(b), np.sin(b)], -1).reshape(len(P), -1)
    calls = []
    real = pipeline._build_2d
    monkeypatch.setattr(pipeline, "_build_2d", lambda *a, **k: calls.append(1) or real(*a, **k))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        checked = build_map(X, ANCHORS, P[ANCHORS], uncertainty="anchors")
    assert len(calls) == 1
    note = [w for w in checked.warnings if "held-out anchors" in w]
    assert note and note[0].startswith("uncertainty: 4 held-out anchors") and "multiplied" in note[0]
