"""LFMDR-Camera3D-v0's range sensor alone: recorded by ``collect`` and mapped by RANGE-3D (issue 34)."""

from __future__ import annotations

import warnings

import numpy as np

from lfmdr_gym import RandomWalkPolicy, collect
from mappers import build_map, default_method


def test_collect_records_a_masked_range_history_that_maps_in_3d():
    h = collect("LFMDR-Camera3D-v0", RandomWalkPolicy(), 150, seed=34,
                make_kwargs={"sensor": "range", "range_noise": 0.02})
    assert h.sensor == "range" and h.dimension == 3 and h.shape == (50, 150)
    assert h.mask is not None and h.mask.dtype == np.bool_ and 0.05 < h.mask.mean() < 0.5
    assert np.all(h.matrix[h.mask] > 0) and not h.matrix[~h.mask].any()
    assert default_method(h, anchor_positions=h.anchor_positions) == "RANGE-3D"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        m = build_map(h, h.anchor_ids, h.anchor_positions)
    assert m.method == "RANGE-3D" and m.positions.shape == (50, 3)
    # the camera rides a planar robot: the map says each tag's side of its plane is not measured
    assert any("viewpoints lie on one plane" in str(w.message) for w in caught)
    rest = np.setdiff1d(np.arange(50), [*h.anchor_ids, *m.unmapped])
    assert rest.size >= 30
    # what ranges from one plane do measure: each tag's horizontal place and its height's distance
    # from the camera's plane (0.3 m)
    est, truth = m.positions[rest], h.object_positions[rest]
    folded = np.hypot(np.linalg.norm(est[:, :2] - truth[:, :2], axis=1),
                      np.abs(est[:, 2] - 0.3) - np.abs(truth[:, 2] - 0.3))
    assert np.median(folded) < 0.1
