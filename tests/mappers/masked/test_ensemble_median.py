"""COVIS-ENSEMBLE's geometric-median combination (issue 35): robust to a member that failed, and
the default for walk-ordered logs of sightings."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from mappers import build_map, mean_position_error
from mappers.defaults import choose_for_history
from mappers.masked.ensemble import CovisEnsemble, ensemble_embedding, geometric_median
from mappers.masked.pair_maps import UnanchoredGraphError

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from synthetic_walk import ANCHORS, history, layout, walk  # noqa: E402

pytestmark = pytest.mark.usefixtures("one_blas_thread")


def test_geometric_median_of_known_sets():
    # three collinear points: the middle one; a square's corners: its centre
    line = np.array([[[0.0, 0.0]], [[1.0, 0.0]], [[5.0, 0.0]]])
    np.testing.assert_allclose(geometric_median(line), [[1.0, 0.0]], atol=1e-7)
    square = np.array([[[0.0, 0.0]], [[2.0, 0.0]], [[2.0, 2.0]], [[0.0, 2.0]]])
    np.testing.assert_allclose(geometric_median(square), [[1.0, 1.0]], atol=1e-9)
    # it is the minimiser of the summed distances: no nearby point does better
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(9, 1, 2))
    med = geometric_median(pts)[0]
    cost = lambda y: np.linalg.norm(pts[:, 0] - y, axis=1).sum()  # noqa: E731
    assert all(cost(med) <= cost(med + d) + 1e-12 for d in rng.normal(0, 1e-3, (50, 2)))


def test_geometric_median_ignores_a_point_flung_away_moves_with_the_frame_and_keeps_nans():
    rng = np.random.default_rng(1)
    P = rng.normal(size=(12, 5, 2))
    far = P.copy()
    far[3, 2] = [4e3, -1e4]  # one member puts object 2 kilometres away
    base, robust = geometric_median(P), geometric_median(far)
    assert np.linalg.norm(robust[2] - base[2]) < 0.5  # the mean moves by about 900
    assert np.linalg.norm(far.mean(axis=0)[2] - base[2]) > 500
    # rotating and translating every member rotates and translates the median
    th = 0.7
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    moved = geometric_median(P @ R.T + [3.0, -2.0])
    np.testing.assert_allclose(moved, base @ R.T + [3.0, -2.0], atol=1e-7)
    # a member that leaves an object unmapped (NaN) is left out for that object only; an
    # object no member places is unmapped
    P[5, 1, 0] = np.nan
    P[:, 4] = np.nan
    out = geometric_median(P)
    np.testing.assert_allclose(out[1], geometric_median(np.delete(P, 5, 0)[:, [1]])[0], atol=1e-12)
    assert np.all(np.isnan(out[4]))
    np.testing.assert_allclose(out[[0, 2, 3]], base[[0, 2, 3]], atol=1e-12)
    with pytest.raises(ValueError, match=r"\(K, M, d\)"):
        geometric_median(np.zeros((5, 2)))


def _sightings(seed: int = 0):
    P = layout(18, seed=seed)
    X, mask = history(P, walk(250, seed=seed), "visibility", masked=True, fov_deg=90)
    return P, X, mask & (X > 0.5)


def test_median_ensemble_agrees_with_the_mean_when_no_member_fails_and_refuses_bad_combine():
    P, X, seen = _sightings()
    hists = [(X * seen, seen), (X * seen, seen)]
    kw = dict(anchor_ids=ANCHORS, anchor_positions=P[ANCHORS], param_sets=[{"min_co": 3}])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mean = ensemble_embedding(hists, "visibility", "covis-nonmetric", **kw)
        med = ensemble_embedding(hists, "visibility", "covis-nonmetric", combine="median", **kw)
    # two identical members: mean and median are the member's map
    np.testing.assert_allclose(med.positions, mean.positions, atol=1e-8)
    with pytest.raises(ValueError, match="combine must be one of"):
        ensemble_embedding(hists, "visibility", "covis-nonmetric", combine="mode", **kw)
    with pytest.raises(ValueError, match="combine"):
        CovisEnsemble(combine="mode").fit(X, mask=seen, sensor="visibility", anchor_ids=ANCHORS,
                                          anchor_positions=P[ANCHORS])


def test_a_member_that_places_nothing_is_left_out_of_the_median_and_named():
    P, X, seen = _sightings()
    # a second log in which every step sees one object alone: no pair is ever seen together,
    # so its member's pair graph falls apart with no group held by 2 anchors
    lone = np.zeros_like(seen)
    lone[np.arange(seen.shape[1]) % len(P), np.arange(seen.shape[1])] = True
    hists = [(X * seen, seen), (lone.astype(float), lone)]
    kw = dict(anchor_ids=ANCHORS, anchor_positions=P[ANCHORS], param_sets=[{"min_co": 3}])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        alone = ensemble_embedding(hists[:1], "visibility", "covis-nonmetric", **kw)
        med = ensemble_embedding(hists, "visibility", "covis-nonmetric", combine="median", **kw)
        with pytest.raises(UnanchoredGraphError, match="falls apart"):
            ensemble_embedding(hists, "visibility", "covis-nonmetric", **kw)  # the mean
        with pytest.raises(ValueError, match="no member of the ensemble could be mapped"):
            ensemble_embedding(hists[1:], "visibility", "covis-nonmetric", combine="median", **kw)
    np.testing.assert_allclose(med.positions, alone.positions, atol=1e-8)
    assert any("1 of 2 members placed nothing" in w for w in med.warnings)


def test_a_walk_ordered_log_of_sightings_gets_the_median_ensemble_with_a_note():
    P, X, seen = _sightings()
    notes: list[str] = []
    label, params = choose_for_history(X, seen, "visibility", notes=notes)
    assert label == "COVIS-ENSEMBLE" and params["combine"] == "median"
    assert len(notes) == 1 and "ordered like a walk's" in notes[0]
    # the same log with its steps shuffled is no walk: the localisation-free map
    order = np.random.default_rng(3).permutation(X.shape[1])
    assert choose_for_history(X[:, order], seen[:, order], "visibility")[0] == "DROPOUT-BLEND"
    m = build_map(X, ANCHORS, P[ANCHORS], sensor="visibility", mask=seen)
    assert m.method == "COVIS-ENSEMBLE" and any("log of what was seen" in w for w in m.warnings)
    # so short a log (250 steps, 343 sightings of 18 objects) leaves the members too few
    # co-observations to agree (the median of their maps is metres off): the guard names it
    # and the map is DROPOUT-BLEND's
    assert any("so the map is DROPOUT-BLEND's" in w for w in m.warnings)
    keep = np.setdiff1d(np.arange(len(P)), ANCHORS)
    assert np.all(np.isfinite(m.positions[keep]))
    # the anchors' centroid would be 0.25-0.3 m off on this unit square
    assert mean_position_error(m.positions[keep], P[keep]) < 0.08
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        unguarded = build_map(X, ANCHORS, P[ANCHORS], "COVIS-ENSEMBLE", sensor="visibility",
                              mask=seen, **{**params, "max_spread": None})
    placed = keep[np.all(np.isfinite(unguarded.positions[keep]), axis=1)]
    assert mean_position_error(unguarded.positions[placed], P[placed]) > 1.0
