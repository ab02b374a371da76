"""COVIS-3D: anchors held where they are, a map that spans space, its pieces checked alone."""

import numpy as np
import pytest

from mappers.core.scores_3d import mean_position_error_3d
from mappers.spatial import CoVisibility3D
from mappers.spatial.covisibility_3d import anchor_mean_start, anchor_scale
from tests.mappers.spatial.test_spatial_ba import ANCHORS, camera_world


def sightings(m=40, n=400):
    P, X, _ = camera_world(m=m, n=n)
    return P, (np.abs(X[:, 0::3]) + np.abs(X[:, 2::3]) > 0).astype(float)


def test_anchors_stay_and_the_map_spans_space():
    P, vis = sightings()
    Y = CoVisibility3D().fit_transform(vis, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS])
    np.testing.assert_allclose(Y[ANCHORS], P[ANCHORS], atol=1e-12)
    rest = Y[6:] - Y[6:].mean(axis=0)
    s = np.linalg.svd(rest, compute_uv=False)
    assert s[2] > 0.1 * s[0]  # not flattened onto a plane
    centroid = np.linalg.norm(P[6:] - P[ANCHORS].mean(axis=0), axis=1).mean()
    assert mean_position_error_3d(Y, P, ANCHORS) < 0.7 * centroid


def test_anchor_mean_start_and_scale():
    pos = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [0, 0, 2.0]])
    S = np.zeros((5, 5))
    S[4, :4] = S[:4, 4] = [1, 1, 0, 0]
    Y = anchor_mean_start(S, np.arange(4), pos)
    np.testing.assert_allclose(Y[4], [1, 0, 0])
    np.testing.assert_allclose(Y[:4], pos)
    D = np.linalg.norm(pos[:, None] - pos[None], axis=2) / 3.0
    assert anchor_scale(D, np.arange(4), pos) == pytest.approx(3.0)
    with pytest.raises(ValueError, match="all 0"):
        anchor_scale(np.zeros((4, 4)), np.arange(4), pos)


def test_anchor_never_seen_with_another_refused():
    P, vis = sightings()
    vis[0] = 0.0
    vis[0, 0] = 1.0
    vis[1:, 0] = 0.0
    with pytest.raises(ValueError, match=r"anchors \[0\] were never seen"):
        CoVisibility3D().fit(vis, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS])
