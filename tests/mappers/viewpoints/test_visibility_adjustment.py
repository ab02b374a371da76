"""The visibility adjustment (mappers/viewpoints/visibility.py; label VIS-BA-WALK): a visibility
map refined by estimating viewpoints."""

from __future__ import annotations

import numpy as np
import pytest
from map_errors import non_anchor_error

from mappers import build_map
from mappers.catalog import METHODS, methods_for, resolve_method
from mappers.viewpoints.visibility import (
    VisibilityAdjustment,
    VisibilityAdjustmentWarning,
    visibility_bits,
)

pytestmark = pytest.mark.usefixtures("one_blas_thread")


def _threshold(n_obj=30, n_steps=800, radius=0.55, seed=0):
    """Objects in a 2.4 m square (anchors at the corners) seen from random viewpoints inside
    it; an object is visible iff its centre is within ``radius`` (exact threshold, no occlusion).
    Returns positions, the (M, N) 0/1 history, the anchors and the viewpoints."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(-1.1, 1.1, size=(n_obj, 2))
    P[:4] = [(-1.1, -1.1), (1.1, -1.1), (1.1, 1.1), (-1.1, 1.1)]
    C = rng.uniform(-1.2, 1.2, size=(n_steps, 2))
    X = (np.linalg.norm(P[:, None] - C[None], axis=2) < radius).astype(float)
    return P, X, np.arange(4), C


# VIS-BA, the adjustment with independent steps (a dead end, docs/dead-ends.md): VIS-BA-WALK
# with the walk's options off and VisibilityAdjustment's own defaults
INDEPENDENT = {"continuity": False, "align": False, "overrelax": 0.0, "grid_cells": 6,
               "prior_iters": 2, "model_rounds": None}


def test_registered_for_visibility_only():
    assert "VIS-BA-WALK" in methods_for("visibility", masked=False)
    assert "VIS-BA-WALK" in methods_for("visibility", masked=True)
    assert "VIS-BA-WALK" not in methods_for("bearing")
    assert "VIS-BA" not in METHODS
    with pytest.raises(ValueError, match=r"'VIS-BA' is no longer a label.*docs/dead-ends.md.*"
                                         r"VIS-BA-WALK"):
        resolve_method("VIS-BA", "visibility")


def test_threshold_visibility_improves_a_perturbed_start():
    P, X, ids, C = _threshold()
    start = P + np.random.default_rng(1).normal(scale=0.06, size=P.shape)
    est = VisibilityAdjustment(max_rounds=6)
    Y = est.fit_transform(X, anchor_ids=ids, anchor_positions=P[ids], start_positions=start)
    before, after = non_anchor_error(start, P, ids), non_anchor_error(Y, P, ids)
    assert est.refined_ and est.loglik_ >= est.start_loglik_
    assert after < 0.75 * before, (before, after)
    np.testing.assert_array_equal(Y[ids], P[ids])  # anchors held
    assert abs(est.radius_ - 0.55) < 0.05
    assert est.miss_rate_ < 0.05  # no occlusion, no misses
    seen = np.isfinite(est.viewpoints_[:, 0])
    assert np.median(np.linalg.norm(est.viewpoints_[seen] - C[seen], axis=1)) < 0.15


def test_objects_seen_from_few_steps_keep_their_start():
    P, X, ids, _ = _threshold()
    P = np.vstack([P, [[3.0, 3.0]]])  # far from every viewpoint ...
    X = np.vstack([X, np.zeros(X.shape[1])])
    X[-1, :2] = 1  # ... yet "seen" twice (a misread label)
    start = P + np.random.default_rng(2).normal(scale=0.03, size=P.shape)
    start[ids] = P[ids]
    est = VisibilityAdjustment(max_rounds=3, min_views=5)
    with pytest.warns(VisibilityAdjustmentWarning, match="fewer than 5 usable steps"):
        Y = est.fit_transform(X, anchor_ids=ids, anchor_positions=P[ids], start_positions=start)
    assert est.kept_.tolist() == [len(P) - 1]
    np.testing.assert_array_equal(Y[-1], start[-1])


def test_nothing_seen_keeps_the_start():
    P, X, ids, _ = _threshold(n_steps=50)
    start = P + 0.01
    start[ids] = P[ids]
    est = VisibilityAdjustment()
    with pytest.warns(VisibilityAdjustmentWarning) as caught:
        Y = est.fit_transform(np.zeros_like(X), anchor_ids=ids, anchor_positions=P[ids],
                              start_positions=start)
    messages = " ".join(str(w.message) for w in caught)
    assert "fewer than 5 usable steps" in messages and "nothing to refine" in messages
    assert not est.refined_
    np.testing.assert_array_equal(Y, start)


def test_masked_entries_do_not_count():
    """An entry the mask calls unobserved is unknown: flipping it changes nothing."""
    P, X, ids, _ = _threshold(n_steps=300)
    mask = np.random.default_rng(3).random(X.shape) < 0.5
    start = P + np.random.default_rng(4).normal(scale=0.04, size=P.shape)
    kw = dict(anchor_ids=ids, anchor_positions=P[ids], start_positions=start)
    Y1 = VisibilityAdjustment(max_rounds=2).fit_transform(np.where(mask, X, 0.0), mask=mask, **kw)
    Y2 = VisibilityAdjustment(max_rounds=2).fit_transform(np.where(mask, X, 1.0), mask=mask, **kw)
    np.testing.assert_allclose(Y1, Y2)


def test_build_map_with_independent_steps():
    P, X, ids, _ = _threshold(n_steps=600)
    m = build_map(X, ids, P[ids], "VIS-BA-WALK", sensor="visibility", **INDEPENDENT)
    assert m.method == "VIS-BA-WALK" and np.all(np.isfinite(m.positions))
    assert {k: m.params[k] for k in INDEPENDENT} == INDEPENDENT
    start = build_map(X, ids, P[ids], sensor="visibility")
    assert non_anchor_error(m.positions, P, ids) < non_anchor_error(start.positions, P, ids)


def test_as_the_default_it_refines_the_former_default(monkeypatch):
    """Were VIS-BA-WALK the complete visibility default, its start map would not recurse into
    it."""
    import dataclasses
    from types import MappingProxyType

    from mappers import defaults

    P, X, ids, _ = _threshold(n_steps=400)
    row = dataclasses.replace(defaults.DEFAULTS[("visibility", False)], method="VIS-BA-WALK")
    monkeypatch.setattr(defaults, "DEFAULTS",
                        MappingProxyType({**defaults.DEFAULTS, ("visibility", False): row}))
    m = build_map(X, ids, P[ids], sensor="visibility")
    assert m.method == "VIS-BA-WALK" and np.all(np.isfinite(m.positions))


def test_bad_input_is_a_clear_value_error():
    P, X, ids, _ = _threshold(n_steps=200)
    kw = dict(anchor_ids=ids, anchor_positions=P[ids], start_positions=P)
    angles = np.random.default_rng(5).uniform(-np.pi, np.pi, size=(len(P), 200))
    bearing = np.stack([np.cos(angles), np.sin(angles)], -1).reshape(len(P), -1)
    with pytest.raises(ValueError, match="0/1"):
        VisibilityAdjustment().fit(bearing, **kw)
    with pytest.raises(ValueError, match="does not map bearing"):
        build_map(bearing, ids, P[ids], "VIS-BA-WALK", sensor="bearing")
    with pytest.raises(ValueError, match="mask must have the shape"):
        VisibilityAdjustment().fit(X, mask=np.ones((3, 3), bool), **kw)
    with pytest.raises(ValueError, match="boolean"):
        VisibilityAdjustment().fit(X, mask=np.ones(X.shape), **kw)
    with pytest.raises(ValueError, match="start_positions must have shape"):
        VisibilityAdjustment().fit(X, anchor_ids=ids, anchor_positions=P[ids],
                                   start_positions=P[:5])
    with pytest.raises(ValueError, match="shape"):
        visibility_bits(np.ones(5))
    with pytest.raises(ValueError, match="anchor"):
        VisibilityAdjustment().fit(X, start_positions=P)
    with pytest.raises(ValueError, match="max_rounds"):
        VisibilityAdjustment(max_rounds=0).fit(X, **kw)
    with pytest.raises(ValueError, match="grid_cells"):
        VisibilityAdjustment(grid_cells=1).fit(X, **kw)
    with pytest.raises(ValueError, match="another method"):
        VisibilityAdjustment(start="vis-ba").fit(X, anchor_ids=ids, anchor_positions=P[ids])
    with pytest.raises(ValueError, match="visibility"):
        VisibilityAdjustment().fit(X, sensor="range", **kw)
    with pytest.raises(ValueError, match="unknown parameter"):
        build_map(X, ids, P[ids], "VIS-BA-WALK", sensor="visibility", radius=0.5)
