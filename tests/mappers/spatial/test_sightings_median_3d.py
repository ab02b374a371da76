"""COVIS-3D-MEDIAN: the median of three anchored embeddings of a camera walk's sightings."""

import numpy as np
import pytest

from mappers import MapWarning, build_map
from mappers.masked import geometric_median
from mappers.spatial import SightingsMedian3D
from mappers.spatial.sightings_median_3d import frame_gaps, window_sightings

ANCHORS = np.arange(6)


def walk_world(m=40, n=300, seed=0):
    """Objects in a 6 x 6 x 2 m room seen by a camera carried round a loop (1.2 m up, swaying
    +-46 degrees about the direction of travel, 10 degrees down): a 70 degree cone, 3.5 m.
    Returns the objects' positions (m, 3) and the ordered sightings (m, n) of 0/1."""
    rng = np.random.default_rng(seed)
    P = rng.uniform([-3, -3, 0], [3, 3, 2], (m, 3))
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    C = np.c_[2 * np.cos(t), 2 * np.sin(t), np.full(n, 1.2)] + rng.normal(0, 0.05, (n, 3))
    yaw = t + np.pi / 2 + 0.8 * np.sin(3 * t)
    seen = np.zeros((m, n))
    for k in range(n):
        fwd = np.array([np.cos(yaw[k]), np.sin(yaw[k]), -0.3])
        v = P - C[k]
        d = np.linalg.norm(v, axis=1)
        seen[(v @ fwd / np.linalg.norm(fwd) > np.cos(np.deg2rad(35)) * d) & (d < 3.5), k] = 1
    return P, seen


def test_walk_mapped_well_inside_the_centroid_baseline_anchors_held():
    P, seen = walk_world(seed=1)
    with pytest.warns(MapWarning, match="could not be placed"):  # the objects never seen
        m = build_map(seen, ANCHORS, P[ANCHORS], method="COVIS-3D-MEDIAN")
    assert m.method == "COVIS-3D-MEDIAN" and m.positions.shape == P.shape
    np.testing.assert_allclose(m.positions[ANCHORS], P[ANCHORS], atol=1e-12)
    # the objects the walk never saw are the unmapped ones, and only they
    assert set(m.unmapped) == set(np.flatnonzero(seen.sum(axis=1) == 0).tolist())
    rest = np.setdiff1d(np.arange(len(P)), [*m.unmapped, *ANCHORS])
    err = np.linalg.norm(m.positions[rest] - P[rest], axis=1).mean()
    centroid = np.linalg.norm(P[rest] - P[ANCHORS].mean(axis=0), axis=1).mean()
    assert err < 0.45 * centroid  # 0.95 m against 2.57 m (COVIS-3D: 1.08 m)


def test_each_object_at_the_geometric_median_of_its_members():
    P, seen = walk_world(seed=0)
    est = SightingsMedian3D().fit(seen, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS])
    members, Y = est.members_, est.embedding_
    assert members.shape == (4, len(P), 3)  # windows 10 and 20, geodesic, frame gap
    placed = np.flatnonzero(np.all(np.isfinite(members[:, :, 0]), axis=0))
    free = np.setdiff1d(placed, ANCHORS)
    np.testing.assert_allclose(Y[free], geometric_median(members[:, free]), atol=1e-9)
    for k in range(3):  # the members differ (else the median would be one of them)
        assert np.linalg.norm(members[k, free] - members[k + 1, free], axis=1).mean() > 0.1


def test_window_sightings_and_harmonic_pieces():
    seen = np.array([[1, 0, 0, 0, 1], [0, 0, 1, 0, 0]], dtype=bool)
    np.testing.assert_array_equal(window_sightings(seen, 1), seen)
    np.testing.assert_array_equal(window_sightings(seen, 2),
                                  [[1, 0, 0, 1], [0, 1, 1, 0]])
    with pytest.raises(ValueError, match="window must be >= 1"):
        window_sightings(seen, 0)
    with pytest.raises(ValueError, match="longer than the 5 steps"):
        window_sightings(seen, 6)
    # object 0 seen at steps 0 and 4, object 1 at step 2: from 0's sightings 1 is 2 steps off
    # each time, from 1's the nearest of 0's is 2 steps off: log(3) both ways
    np.testing.assert_allclose(frame_gaps(seen), [[0, np.log(3)], [np.log(3), 0]])
    three = np.array([[1, 1, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0], [0, 0, 0, 0, 0, 1]], dtype=bool)
    G = frame_gaps(three)  # (0, 1): from 1's one sighting 0 steps; (0, 2) the smaller: 4 steps
    np.testing.assert_allclose([G[0, 1], G[0, 2], G[1, 2]], [0.0, np.log(5), np.log(5)])
    with pytest.raises(ValueError, match="every object seen at least once"):
        frame_gaps(np.zeros((2, 3), dtype=bool))


def test_bad_input_named():
    P, seen = walk_world(seed=0)
    with pytest.raises(ValueError, match="needs anchors"):
        SightingsMedian3D().fit(seen)
    with pytest.raises(ValueError, match="an \\(M, N\\) array of 0/1"):
        SightingsMedian3D().fit(seen * 2.0, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS])
    with pytest.raises(ValueError, match="windows must be"):
        SightingsMedian3D(windows=(0,)).fit(seen, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS])
    lonely = seen.copy()
    lonely[0] = 0.0
    with pytest.raises(ValueError, match=r"anchors \[0\] were never seen"):
        SightingsMedian3D().fit(lonely, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS])
