"""FRUSTUM-BA: the kernels' gradient and blocks, a map refined in a small camera world, bad input."""

import math
import warnings

import numpy as np
import pytest

from mappers.spatial import frustum_kernels as kernels
from mappers.spatial.frustum import FrustumAdjustment, FrustumCamera, view_log_prob

CAMERA = {"camera_height": 0.3, "pitch_deg": 20.0, "hfov_deg": 90.0, "vfov_deg": 70.0,
          "max_range": 3.0}
ANCHORS = np.array([0, 1, 2, 3, 4, 5])


def frustum_world(m=20, n=400, seed=3):
    """Objects in a 2.5 m box at heights 0-2 m (the anchors at its corners), viewpoints drawn
    uniformly with any heading, and each step's sightings: the objects inside the hard frustum
    of :data:`CAMERA` (no occlusion)."""
    rng = np.random.default_rng(seed)
    P = np.column_stack([rng.uniform(-1.2, 1.2, (m, 2)), rng.uniform(0.0, 2.0, m)])
    P[:6] = [[-1.2, -1.2, 0.0], [1.2, -1.2, 2.0], [-1.2, 1.2, 1.8], [1.2, 1.2, 0.2],
             [0.0, -1.2, 1.0], [-1.2, 0.0, 0.5]]
    C = np.column_stack([rng.uniform(-1.1, 1.1, (n, 2)), rng.uniform(-math.pi, math.pi, n)])
    cam = FrustumCamera(*CAMERA.values())
    seen = view_log_prob(P, C, cam, 1e-6, 1e-6) > math.log(0.5)
    return P, C, seen.T.astype(float)


def test_gradient_and_blocks_match_the_loss():
    P, C, X = frustum_world(m=10, n=40)
    seen = np.ascontiguousarray(X.T > 0.5)
    rng = np.random.default_rng(0)
    P = P + rng.normal(0, 0.1, P.shape)
    C = C + rng.normal(0, 0.1, C.shape)
    args = FrustumCamera(*CAMERA.values()).args(0.05, 0.1, 0.1)
    free_index = np.array([-1] * 6 + [0, 1, 2, 3])
    n = len(C)
    U, V, W = np.zeros((n, 3, 3)), np.zeros((4, 3, 3)), np.zeros((n, 3, 12))
    g, h = np.zeros((n, 3)), np.zeros((4, 3))
    loss = kernels.frustum_blocks(P, C, seen, free_index, *args, U, V, W, g, h)
    assert loss == pytest.approx(kernels.frustum_loss(P, C, seen, *args), rel=1e-12)
    e = 1e-6
    for j, k in ((6, 0), (7, 1), (9, 2)):
        Q = P.copy()
        Q[j, k] += e
        fd = (kernels.frustum_loss(Q, C, seen, *args) - loss) / e
        assert fd == pytest.approx(h[free_index[j], k], rel=1e-3, abs=1e-4)
    for t, k in ((3, 0), (5, 1), (8, 2)):
        D = C.copy()
        D[t, k] += e
        fd = (kernels.frustum_loss(P, D, seen, *args) - loss) / e
        assert fd == pytest.approx(g[t, k], rel=1e-3, abs=1e-4)
    # the curvature blocks are positive semi-definite
    assert np.linalg.eigvalsh(U).min() > -1e-9
    assert np.linalg.eigvalsh(V).min() > -1e-9


def test_view_log_prob_is_the_kernels_model():
    P, C, X = frustum_world(m=8, n=30)
    cam = FrustumCamera(*CAMERA.values())
    lq = view_log_prob(P, C, cam, 0.05, 0.1)  # (N, M)
    seen = np.ascontiguousarray(X.T > 0.5)
    eps = 0.1
    expected = -np.where(seen, math.log(1 - eps) + lq, np.log1p(-(1 - eps) * np.exp(lq))).sum()
    assert kernels.frustum_loss(P, C, seen, *cam.args(0.05, 0.1, eps)) == pytest.approx(
        expected, rel=1e-10)


def test_pulls_a_misplaced_object_back_and_keeps_the_anchors():
    P, _, X = frustum_world(m=14, n=250)
    start = P.copy()
    start[8] += [0.4, -0.3, 0.5]  # one object far off, the others where they are
    est = FrustumAdjustment(**CAMERA, softness=(0.03,), rounds=15, grid=8, headings=24)
    Y = est.fit_transform(X, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS],
                          start_positions=start)
    np.testing.assert_allclose(Y[ANCHORS], P[ANCHORS], atol=1e-12)
    assert est.refined_ and est.loss_ < est.start_loss_
    # 250 steps of a few sightings each leave the others some slack: the misplaced one is
    # pulled most of the way back (0.71 m -> 0.28 m when measured)
    assert np.linalg.norm(Y[8] - P[8]) < 0.5 * np.linalg.norm(start[8] - P[8])
    assert est.poses_.shape == (X.shape[1], 3)


def test_bad_input_is_refused():
    P, _, X = frustum_world(m=10, n=50)
    kw = {"anchor_ids": ANCHORS, "anchor_positions": P[ANCHORS]}
    with pytest.raises(ValueError, match="calibration"):
        FrustumAdjustment().fit(X, **kw)
    with pytest.raises(ValueError, match="0/1"):
        FrustumAdjustment(**CAMERA).fit(X * 0.5, **kw)
    with pytest.raises(ValueError, match="masked"):
        mask = np.ones(X.shape, dtype=bool)
        mask[0, 0] = False
        FrustumAdjustment(**CAMERA).fit(X, mask=mask, **kw)
    with pytest.raises(ValueError, match="plane"):
        flat = P[ANCHORS].copy()
        flat[:, 2] = 1.0
        FrustumAdjustment(**CAMERA).fit(X, anchor_ids=ANCHORS, anchor_positions=flat)
    with pytest.raises(ValueError, match="softness"):
        FrustumAdjustment(**CAMERA, softness=()).fit(X, **kw)
    with pytest.raises(ValueError, match="start_positions"):
        FrustumAdjustment(**CAMERA).fit(X, start_positions=P[:, :2], **kw)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match="hfov_deg"):
            FrustumAdjustment(**{**CAMERA, "hfov_deg": 190.0}).fit(X, **kw)


def test_build_map_takes_it_by_name_and_the_default_stays_covis_3d():
    from mappers import build_map
    from mappers.spatial.pipeline_3d import default_method_3d

    P, _, X = frustum_world(m=10, n=60)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = build_map(X, ANCHORS, P[ANCHORS], "FRUSTUM-BA", **CAMERA, rounds=2, grid=4,
                      headings=8)
    assert m.method == "FRUSTUM-BA" and m.positions.shape == (10, 3)
    assert m.params["hfov_deg"] == 90.0
    assert default_method_3d("visibility") == "COVIS-3D"
    with pytest.raises(ValueError, match="calibration"):
        build_map(X, ANCHORS, P[ANCHORS], "FRUSTUM-BA")
