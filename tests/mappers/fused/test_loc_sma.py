"""Fused histories: the registry's sensor sets, build_map's checks, and range + bearing mapping
by the law of cosines (LOC-SMA)."""

import warnings

import numpy as np
import pytest

from mappers import DEFAULT_METHODS, METHODS, MethodSpec, build_map, methods_for, register_method
from mappers.catalog import _METHODS, resolve_method
from mappers.core.sensors import check_sensor_set, sensor_name
from mappers.fused.law_of_cosines import frame_values, pooled_frame_distances
from mappers.fused.loc_sma import LawOfCosinesSMACOF, RigidityWarning

RB = frozenset({"range", "bearing"})


def camera(P, n_steps=600, fov=np.pi / 3, max_range=1.0, seed=0, size=2.0):
    """Noise-free fused range + bearing histories of a camera at random poses, and masks."""
    rng = np.random.default_rng(seed)
    poses = np.column_stack([rng.uniform(-size / 2, size / 2, (n_steps, 2)),
                             rng.uniform(-np.pi, np.pi, n_steps)])
    rel = P[:, None, :] - poses[None, :, :2]
    r = np.hypot(rel[..., 0], rel[..., 1])
    th = np.angle(np.exp(1j * (np.arctan2(rel[..., 1], rel[..., 0]) - poses[None, :, 2])))
    seen = (np.abs(th) <= fov / 2) & (r <= (np.inf if max_range is None else max_range))
    R = np.where(seen, r, 0.0)
    B = np.zeros((len(P), 2 * n_steps))
    B[:, 0::2], B[:, 1::2] = np.where(seen, np.cos(th), 0.0), np.where(seen, np.sin(th), 0.0)
    return {"range": R, "bearing": B}, {"range": seen, "bearing": np.repeat(seen, 2, axis=1)}


def grid_layout(n=6, spacing=0.35, seed=0):
    rng = np.random.default_rng(seed)
    g = (np.arange(n) - (n - 1) / 2) * spacing
    P = np.array([(x, y) for x in g for y in g]) + rng.uniform(-0.05, 0.05, (n * n, 2))
    anchors = np.array([0, n - 1, n * n - n, n * n - 1])  # the corners
    return P, anchors


# ---------------------------------------------------------------- vocabulary and registry
def test_sensor_sets_are_canonical_and_named():
    assert check_sensor_set(("bearing", "range")) == RB == check_sensor_set("range-bearing")
    assert check_sensor_set(["range"]) == "range"
    assert sensor_name(RB) == "range-bearing"
    assert sensor_name(frozenset({"visibility", "bearing"})) == "visibility-bearing"
    with pytest.raises(ValueError, match="unknown sensor name"):
        check_sensor_set(("range", "sonar"))
    with pytest.raises(ValueError, match="distinct"):
        check_sensor_set(("range", "range"))


def test_registry_lists_fused_methods_and_defaults():
    assert DEFAULT_METHODS[(RB, False)] == "LOC-SMA" == DEFAULT_METHODS[(RB, True)]
    assert "LOC-SMA" in methods_for(("range", "bearing"), masked=True)
    assert "LOC-SMA" not in methods_for("range")
    assert "SMA(WGT)" not in methods_for(RB)  # single-sensor methods do not take fused input
    assert METHODS["LOC-SMA"].fused and not METHODS["SMA(WGT)"].fused
    with pytest.raises(ValueError, match="maps range-bearing histories only"):
        resolve_method("LOC-SMA", "range")
    with pytest.raises(ValueError, match="single-sensor histories only"):
        resolve_method("SMA(WGT)", ("range", "bearing"))


def test_register_fused_spec_and_bad_sensor_sets():
    spec = MethodSpec("test-fused", LawOfCosinesSMACOF, sensors=(RB,), uses_anchors=True,
                      normalize=False, histories=("complete", "masked"))
    try:
        register_method(spec)
        assert "test-fused" in methods_for(RB)
    finally:
        _METHODS.pop("test-fused", None)
    for bad in ((frozenset({"range"}),), (frozenset({"range", "sonar"}),), ("range", 3)):
        with pytest.raises(ValueError, match="sensors must be None or a non-empty tuple"):
            register_method(MethodSpec("test-bad", LawOfCosinesSMACOF, sensors=bad))
    assert "test-bad" not in METHODS


# ---------------------------------------------------------------- bad fused input
def test_bad_fused_inputs_are_refused_by_name():
    P, anchors = grid_layout()
    H, masks = camera(P)
    pos = P[anchors]
    with pytest.raises(ValueError, match="unknown sensor name.*sonar"):
        build_map({"range": H["range"], "sonar": H["bearing"]}, anchors, pos)
    with pytest.raises(ValueError, match="two or more sensors"):
        build_map({"range": H["range"]}, anchors, pos)
    with pytest.raises(ValueError, match="same objects and steps"):
        build_map({"range": H["range"][:-1], "bearing": H["bearing"]}, anchors, pos)
    with pytest.raises(ValueError, match="same objects and steps"):
        build_map({"range": H["range"][:, :-1], "bearing": H["bearing"]}, anchors, pos)
    with pytest.raises(ValueError, match=r"histories\['bearing'\] has 1199 columns"):
        build_map({"range": H["range"], "bearing": H["bearing"][:, :-1]}, anchors, pos)
    with pytest.raises(ValueError, match=r"mask must have one entry per sensor.*missing \['bearing'\]"):
        build_map(H, anchors, pos, mask={"range": masks["range"]})
    with pytest.raises(ValueError, match="must be a mapping sensor -> mask"):
        build_map(H, anchors, pos, mask=masks["range"])
    with pytest.raises(ValueError, match=r"mask\['range'\] must be a boolean array"):
        build_map(H, anchors, pos, mask={**masks, "range": masks["range"].astype(int)})
    with pytest.raises(ValueError, match="does not name the sensors"):
        build_map(H, anchors, pos, sensor="visibility")
    with pytest.raises(ValueError, match="does not map"):
        build_map(H, anchors, pos, method="SMA(WGT)")


# ---------------------------------------------------------------- the law of cosines
def test_law_of_cosines_distances_exact_on_noise_free_frames():
    P, _ = grid_layout()
    H, masks = camera(P, fov=2 * np.pi, max_range=None, n_steps=50)
    r, theta = frame_values(H, masks)
    D, S, C = pooled_frame_distances(r, theta)
    true = np.linalg.norm(P[:, None] - P[None], axis=2)
    assert np.all(C[~np.eye(len(P), dtype=bool)] > 0)
    np.testing.assert_allclose(D, true, atol=1e-9)
    np.testing.assert_allclose(S, 0.0, atol=1e-9)


def test_loc_sma_recovers_a_layout_from_a_narrow_camera():
    P, anchors = grid_layout()
    H, masks = camera(P, n_steps=1500)
    m = build_map(H, anchors, P[anchors], mask=masks)
    assert m.method == "LOC-SMA" and m.sensor == "range-bearing" and m.unmapped == ()
    np.testing.assert_allclose(m.positions, P, atol=1e-4)


def test_two_clusters_with_two_anchors_each_are_placed_by_handedness():
    """No pair joins the clusters; each has two anchors, so distances leave a mirror image that
    only the frames' handedness resolves."""
    P1, _ = grid_layout(n=3, spacing=0.3, seed=1)
    P = np.vstack([P1 - 1.5, P1 + 1.5])
    anchors = np.array([0, 8, 9, 17])  # two corners of each cluster, diagonally opposite
    H, masks = camera(P, n_steps=3000, max_range=0.9, size=4.0, seed=2)
    r, theta = frame_values(H, masks)
    _, _, C = pooled_frame_distances(r, theta)
    assert C[:9, 9:].max() == 0  # the clusters are never seen together
    with warnings.catch_warnings():
        warnings.simplefilter("error", RigidityWarning)
        m = build_map(H, anchors, P[anchors], mask=masks)
    np.testing.assert_allclose(m.positions, P, atol=1e-4)


def test_a_cluster_tied_to_one_anchor_is_not_placed_but_warned():
    P1, _ = grid_layout(n=3, spacing=0.3, seed=1)
    P = np.vstack([P1 - 1.5, P1 + 1.5])
    anchors = np.array([0, 2, 8, 17])  # three in the first cluster, one in the second
    H, masks = camera(P, n_steps=3000, max_range=0.9, size=4.0, seed=2)
    m = build_map(H, anchors, P[anchors], mask=masks)
    assert set(range(9, 17)) <= set(m.unmapped)
    assert any("tied to 1 anchor" in w for w in m.warnings)
    np.testing.assert_allclose(m.positions[:9], P[:9], atol=1e-4)


def test_vb_sma_blends_the_fused_map_with_the_bearing_only_map():
    from mappers.calibrated.cal_sma import CalibratedSMACOF
    from mappers.fused.vb_sma import VisibilityBearingSMACOF

    rng = np.random.default_rng(4)
    P, anchors = grid_layout(5, 0.4, seed=4)
    poses = np.column_stack([rng.uniform(-1, 1, (800, 2)), rng.uniform(-np.pi, np.pi, 800)])
    rel = P[:, None] - poses[None, :, :2]
    V = (np.hypot(rel[..., 0], rel[..., 1]) < 0.55).astype(float)
    th = np.arctan2(rel[..., 1], rel[..., 0]) - poses[None, :, 2]
    B = np.stack([np.cos(th), np.sin(th)], -1).reshape(len(P), -1)
    X, fix = {"visibility": V, "bearing": B}, dict(anchor_ids=anchors, anchor_positions=P[anchors])
    est = VisibilityBearingSMACOF(bearing_share=0.3, random_state=0).fit(X, **fix)
    alone = CalibratedSMACOF(random_state=0).fit_transform(
        B / np.linalg.norm(B, axis=1, keepdims=True), **fix)
    np.testing.assert_allclose(est.bearing_embedding_, alone)
    np.testing.assert_allclose(est.blend_embedding_, 0.7 * est.fused_embedding_ + 0.3 * alone)
    plain = VisibilityBearingSMACOF(bearing_share=0.0, random_state=0).fit(X, **fix)
    assert plain.bearing_embedding_ is None
    np.testing.assert_array_equal(plain.blend_embedding_, est.fused_embedding_)
    np.testing.assert_allclose(est.blend_embedding_[anchors], P[anchors], atol=1e-9)  # both fixed
    np.testing.assert_allclose(est.embedding_[anchors], P[anchors], atol=1e-9)  # and refined
    paper = VisibilityBearingSMACOF(bearing_share=0.3, refine=False, random_state=0).fit(X, **fix)
    np.testing.assert_array_equal(paper.embedding_, est.blend_embedding_)  # the blend alone
    m = build_map(X, anchors, P[anchors])
    assert m.params["bearing_share"] == 0.3 and m.params["refine"] is True
    np.testing.assert_allclose(m.positions, est.embedding_, atol=1e-9)
    for bad in (1.0, -0.1):
        with pytest.raises(ValueError, match="bearing_share"):
            build_map(X, anchors, P[anchors], bearing_share=bad)
    empty = {"visibility": V, "bearing": np.where(np.arange(len(P))[:, None] == 7, 0.0, B)}
    with pytest.raises(ValueError, match="bearing-only map, which needs every object's bearing"):
        build_map(empty, anchors, P[anchors])
