"""VIEW-BA, the view-cone adjustment of masked visibility maps (mappers/viewpoints/view_cone.py and
its compiled loops, mappers/viewpoints/view_cone_kernels.py)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import lfmdr_gym  # noqa: F401 - registers the envs
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from lfmdr_gym.histories.recording import collect
from mappers import build_map, mean_position_error
from mappers.viewpoints import view_cone_kernels as view_kernels
from mappers.viewpoints.view_cone import (
    ViewAdjustment,
    ViewAdjustmentWarning,
    estimate_fov,
    view_cone_score,
)

ANCHORS = np.array([0, 1, 2, 3])


pytestmark = pytest.mark.usefixtures("one_blas_thread")


def _camera(fov_deg: float, n_steps: int = 600, m: int = 30, seed: int = 0, radius: float = 0.6):
    """Objects in a 2.5 m square (the anchors at its corners) seen from random poses inside it:
    ``(objects (M, 2), poses (N, 3), X (M, N) visibility bits, mask (M, N))``; observed =
    inside the view cone at any distance, visible = observed and nearer than ``radius``."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(-1.25, 1.25, (m, 2))
    P[:4] = [[-1.2, -1.2], [1.2, -1.2], [1.2, 1.2], [-1.2, 1.2]]
    C = np.column_stack([rng.uniform(-1.1, 1.1, (n_steps, 2)),
                         rng.uniform(-math.pi, math.pi, n_steps)])
    rel = P[None] - C[:, None, :2]
    off = np.angle(np.exp(1j * (np.arctan2(rel[..., 1], rel[..., 0]) - C[:, 2:3])))
    mask = np.abs(off) <= math.radians(fov_deg) / 2
    X = (mask & (np.hypot(rel[..., 0], rel[..., 1]) < radius)).astype(float)
    return P, C, X.T, mask.T


def _mpe(Q, P):
    keep = np.setdiff1d(np.arange(len(P)), ANCHORS)
    return mean_position_error(Q[keep], P[keep])


def test_the_compiled_blocks_hold_the_gradient_of_the_compiled_loss():
    P, C, X, mask = _camera(90, n_steps=40, m=8, seed=1)
    rng = np.random.default_rng(2)
    P = P + rng.normal(0, 0.05, P.shape)
    C = C + rng.normal(0, 0.05, C.shape)
    obs, seen = np.ascontiguousarray(mask.T), np.ascontiguousarray((X.T > 0.5) & mask.T)
    free = np.array([-1, -1, -1, -1, 0, 1, 2, 3], dtype=np.int64)
    args = (math.cos(math.radians(45)), 0.6, 0.2, 0.1, 0.1)  # soft, for the differences

    def cost(P, C):
        return view_kernels.cone_cost(P, C, obs, seen, *args)

    U, g, V, h, W = (np.zeros((40, 3, 3)), np.zeros((40, 3)), np.zeros((4, 2, 2)),
                     np.zeros((4, 2)), np.zeros((40, 3, 8)))
    loss, _ = view_kernels.cone_blocks(P, C, obs, seen, free, *args, U, V, W, g, h)
    assert loss == pytest.approx(cost(P, C))
    eps = 1e-6
    for t, k in [(0, 0), (5, 1), (17, 2), (39, 2)]:
        dC = np.zeros_like(C)
        dC[t, k] = eps
        assert g[t, k] == pytest.approx((cost(P, C + dC) - cost(P, C - dC)) / (2 * eps),
                                        rel=1e-4, abs=1e-6)
    for f, j in enumerate(range(4, 8)):
        for k in range(2):
            dP = np.zeros_like(P)
            dP[j, k] = eps
            assert h[f, k] == pytest.approx((cost(P + dP, C) - cost(P - dP, C)) / (2 * eps),
                                            rel=1e-4, abs=1e-6)
    assert np.allclose(U, U.transpose(0, 2, 1))
    assert np.all(np.linalg.eigvalsh(U) > -1e-9) and np.all(np.linalg.eigvalsh(V) > -1e-9)


def test_the_true_map_explains_the_view_better_than_wrong_ones():
    P, _, _, mask = _camera(90, m=40)
    obs, half = mask.T, math.radians(45)
    swapped = P.copy()
    swapped[[4, 5, 6, 7]] = P[[8, 9, 10, 11]]
    swapped[[8, 9, 10, 11]] = P[[4, 5, 6, 7]]
    true = view_cone_score(P, obs, half)
    assert true > view_cone_score(swapped, obs, half)
    folded = P.copy()  # the right half mirrored onto itself (a mirror of all of it would tie)
    folded[P[:, 0] > 0, 1] *= -1.0
    assert true > view_cone_score(folded, obs, half)
    assert true > view_cone_score(P + np.random.default_rng(1).normal(0, 0.1, P.shape), obs,
                                  half)
    halves = np.radians([20.0, 45.0, 70.0])
    assert np.allclose(view_cone_score(P, obs, halves),
                       [view_cone_score(P, obs, a) for a in halves])


@pytest.mark.parametrize("fov", [60.0, 90.0, 150.0])
def test_the_view_width_is_read_from_the_observed_sets(fov):
    P, _, _, mask = _camera(fov, n_steps=1600, m=40)
    assert abs(estimate_fov(P, mask.T) - fov) <= 15.0


def test_view_ba_moves_a_perturbed_map_towards_the_truth_and_finds_the_viewpoints():
    P, C, X, mask = _camera(90, n_steps=800, m=30, seed=3)
    start = P + np.random.default_rng(4).normal(0, 0.08, P.shape)
    va = ViewAdjustment(fov_deg=90)
    Q = va.fit_transform(X, mask=mask, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS],
                         start_positions=start)
    assert va.refined_ and va.loss_ < va.start_loss_ and va.start_method_ == "given"
    assert np.array_equal(Q[ANCHORS], P[ANCHORS])
    assert _mpe(Q, P) < 0.5 * _mpe(start, P)
    err = np.hypot(*(va.poses_[:, :2] - C[:, :2]).T)
    assert np.nanmedian(err) < 0.3  # 30 objects pin a viewpoint loosely (random: ~1 m)
    assert 0.4 < va.radius_ < 0.8  # the bits' radius, 0.6


def test_a_second_pass_is_one_more_adjustment_from_the_first_pass_map():
    """passes=2 runs a second adjustment from the first's map (viewpoints found
    afresh) and keeps it if it lowers the loss of its own start; else the first's map stands."""
    P, _, X, mask = _camera(90, n_steps=500, m=24, seed=8)
    start = P + np.random.default_rng(9).normal(0, 0.1, P.shape)
    fit = dict(mask=mask, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS], start_positions=start)
    one = ViewAdjustment(fov_deg=90, passes=1).fit(X, **fit)
    two = ViewAdjustment(fov_deg=90, passes=2).fit(X, **fit)
    assert one.refined_ and two.refined_
    assert np.array_equal(two.start_, one.start_)  # the start map is the first pass's
    again = ViewAdjustment(fov_deg=90, passes=1).fit(X, **{**fit, "start_positions": one.embedding_})
    if again.refined_:  # the second pass is one more adjustment from the first's map
        assert np.allclose(two.embedding_, again.embedding_)
    else:  # it did not lower the loss: the first pass's map stands
        assert np.array_equal(two.embedding_, one.embedding_)
    with pytest.raises(ValueError, match="passes"):
        ViewAdjustment(passes=0).fit(X, **fit)


def test_three_passes_are_the_default():
    """The default is three passes (chosen on two simulators, docs/dead-ends.md): with no count
    given the map is ``passes=3``'s, not the one pass's of before."""
    P, _, X, mask = _camera(90, n_steps=500, m=24, seed=8)
    start = P + np.random.default_rng(9).normal(0, 0.1, P.shape)
    fit = dict(mask=mask, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS], start_positions=start)
    default = ViewAdjustment(fov_deg=90).fit(X, **fit)
    three = ViewAdjustment(fov_deg=90, passes=3).fit(X, **fit)
    one = ViewAdjustment(fov_deg=90, passes=1).fit(X, **fit)
    assert ViewAdjustment().passes == 3
    assert np.array_equal(default.embedding_, three.embedding_)
    assert not np.allclose(default.embedding_, one.embedding_)


def test_a_wide_view_keeps_the_start_map():
    P, _, X, mask = _camera(90, n_steps=200, seed=5)
    start = P + 0.01
    va = ViewAdjustment(fov_deg=200)
    with pytest.warns(ViewAdjustmentWarning, match="200-degree view"):
        Q = va.fit_transform(X, mask=mask, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS],
                             start_positions=start)
    start[ANCHORS] = P[ANCHORS]
    assert not va.refined_ and np.array_equal(Q, start)


@pytest.mark.parametrize("kwargs, match", [
    (dict(mask=None), "needs the mask of a limited view"),
    (dict(all_true=True), "needs the mask of a limited view"),
    (dict(sensor="bearing"), "maps visibility histories"),
    (dict(short_mask=True), "mask must have the history's shape"),
    (dict(fov_deg=0), "fov_deg"),
    (dict(fov_deg=360), "fov_deg"),
    (dict(start="view-ba"), "another method than 'VIEW-BA'"),
    (dict(no_anchors=True), "needs anchor_ids"),
    (dict(all_anchors=True), "every placed object is an anchor"),
])
def test_bad_input_is_refused_with_its_name(kwargs, match):
    P, _, X, mask = _camera(90, n_steps=50)
    if kwargs.pop("all_true", False):
        kwargs["mask"] = np.ones_like(mask)
    if kwargs.pop("short_mask", False):
        kwargs["mask"] = mask[:, :-1]
    fit = dict(mask=mask, sensor="visibility", anchor_ids=ANCHORS, anchor_positions=P[ANCHORS])
    if kwargs.pop("no_anchors", False):
        fit.update(anchor_ids=None, anchor_positions=None)
    if kwargs.pop("all_anchors", False):
        fit.update(anchor_ids=np.arange(len(P)), anchor_positions=P, start_positions=P)
    init = {k: kwargs.pop(k) for k in ("fov_deg", "start") if k in kwargs}
    fit.update(kwargs)
    with pytest.raises(ValueError, match=match):
        ViewAdjustment(**init).fit(X, **fit)


@pytest.mark.parametrize("kwargs, match", [
    (dict(positions=np.zeros((4, 3))), r"positions must have shape \(M, 2\)"),
    (dict(observed=np.zeros((10, 5), bool)), r"observed must have shape \(N, 4\)"),
    (dict(half_angle=0.0), "half_angle must be in"),
    (dict(half_angle=4.0), "half_angle must be in"),
    (dict(grid=1), "need grid >= 2"),
    (dict(positions=np.full((4, 2), np.nan)), "at least 2 placed objects"),
])
def test_bad_input_to_the_score_is_refused(kwargs, match):
    args = dict(positions=np.eye(4, 2), observed=np.ones((10, 4), bool), half_angle=0.5)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        view_cone_score(**args)


def test_view_ba_maps_an_env_history_through_build_map():
    env = gym.make("LFMDR-Visibility-v0", max_episode_steps=1000, fov_deg=90)
    h = collect(env, RandomWalkPolicy.for_env(env), 1000, seed=5)
    m = build_map(h, h.anchor_ids, h.anchor_positions, "VIEW-BA")
    assert m.method == "VIEW-BA"
    keep = np.setdiff1d(np.arange(h.n_objects), h.anchor_ids)
    blend = build_map(h, h.anchor_ids, h.anchor_positions, "DROPOUT-BLEND")
    err = mean_position_error(m.positions[keep], h.object_positions[keep])
    before = mean_position_error(blend.positions[keep], h.object_positions[keep])
    assert err < 0.8 * before and err < 0.07  # 0.059 against DROPOUT-BLEND's 0.090
    va = ViewAdjustment(start="CAL-SMA")  # a method for complete histories: 0 = not seen
    Q = va.fit_transform(h.matrix, mask=h.mask, anchor_ids=h.anchor_ids,
                         anchor_positions=h.anchor_positions, timeline=h.timeline)
    zero_filled = build_map(np.where(h.mask, h.matrix, 0.0), h.anchor_ids, h.anchor_positions,
                            "CAL-SMA", sensor="visibility")
    assert va.start_method_ == "CAL-SMA" and np.allclose(va.start_, zero_filled.positions)
    assert mean_position_error(Q[keep], h.object_positions[keep]) < before


def test_a_mask_that_is_not_a_view_cone_keeps_the_start_map():
    """A 360-degree view with a range limit: the mask is a disc around the viewpoint, which no
    cone explains; the adjustment says so and keeps its start."""
    P, C, X, _ = _camera(90, n_steps=400, seed=6)
    rel = P[None] - C[:, None, :2]
    mask = (np.hypot(rel[..., 0], rel[..., 1]) < 1.0).T
    X = X * 0 + (mask & (np.hypot(rel[..., 0], rel[..., 1]) < 0.6).T)
    start = P + np.random.default_rng(7).normal(0, 0.03, P.shape)
    va = ViewAdjustment(fov_deg=90)
    with pytest.warns(ViewAdjustmentWarning, match="do not look like a view cone"):
        Q = va.fit_transform(X, mask=mask, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS],
                             start_positions=start)
    assert not va.refined_ and va.start_loss_ > va.max_start_loss
    start[ANCHORS] = P[ANCHORS]
    assert np.array_equal(Q, start)


def test_many_objects_go_to_dropout_blend_and_view_ba_refuses_too_many(monkeypatch):
    from mappers.catalog import resolve_method
    from mappers.defaults import SCALABLE_ABOVE_OBJECTS
    from mappers.viewpoints import view_cone as view_adjustment

    assert resolve_method(None, "visibility", masked=True).label == "VIEW-BA"
    assert resolve_method(None, "visibility", masked=True,
                          n_objects=SCALABLE_ABOVE_OBJECTS + 1).label == "DROPOUT-BLEND"
    P, _, X, mask = _camera(90, n_steps=100)
    monkeypatch.setattr(view_adjustment, "MAX_FREE_OBJECTS", 10)
    with pytest.raises(ValueError, match="26 is above 10: map this history with DROPOUT-BLEND"):
        ViewAdjustment(fov_deg=90).fit(X, mask=mask, anchor_ids=ANCHORS,
                                       anchor_positions=P[ANCHORS], start_positions=P)



def _failing_first_start(monkeypatch, bad_labels=("DROPOUT-BLEND",)):
    """Make the start maps of ``bad_labels`` objects scattered at random (a start that has
    failed as a whole, drawn without running the method); the other labels draw their real
    maps."""
    from mappers.viewpoints import view_cone as view_adjustment

    real = view_adjustment.fit_start

    def fit_start(label, X, ids, pos, **kw):
        if label in bad_labels:
            return np.random.default_rng(1).uniform(-1.2, 1.2, (X.shape[0], 2)), label
        return real(label, X, ids, pos, **kw)

    monkeypatch.setattr(view_adjustment, "fit_start", fit_start)


def _fallback_case():
    P, _, X, mask = _camera(90, n_steps=800, seed=3, radius=1.0)
    return P, X, {"mask": mask, "anchor_ids": ANCHORS, "anchor_positions": P[ANCHORS]}


def test_a_start_that_is_no_view_cone_is_retried_from_the_fallback_start(monkeypatch):
    """The first start's map explains no cone (scattered objects); COVIS-SPARSE's does: the
    map is adjusted from it, with a warning naming both, and it is better than the start kept."""
    P, X, fit = _fallback_case()
    _failing_first_start(monkeypatch)
    alone = ViewAdjustment(fov_deg=90, fallback_starts=None)
    with pytest.warns(ViewAdjustmentWarning, match="do not look like a view cone"):
        alone.fit(X, **fit)
    assert alone.cone_rejected_ and not alone.refined_ and alone.starts_tried_ == ["DROPOUT-BLEND"]
    va = ViewAdjustment(fov_deg=90)
    assert va.fallback_starts == ("COVIS-SPARSE",)
    with pytest.warns(ViewAdjustmentWarning, match="from COVIS-SPARSE's they do"):
        va.fit(X, **fit)
    assert va.starts_tried_ == ["DROPOUT-BLEND", "COVIS-SPARSE"]
    assert va.start_method_ == "COVIS-SPARSE" and va.refined_ and not va.cone_rejected_
    assert va.start_loss_ <= va.max_start_loss < alone.start_loss_
    assert _mpe(va.embedding_, P) < 0.3 * _mpe(alone.embedding_, P)  # 0.13 against 0.86 m


def test_when_no_fallback_start_looks_like_a_cone_the_first_verdict_stands(monkeypatch):
    P, X, fit = _fallback_case()
    _failing_first_start(monkeypatch, ("DROPOUT-BLEND", "COVIS-SPARSE"))
    va = ViewAdjustment(fov_deg=90, fallback_starts=("dropout-blend", "COVIS-SPARSE"))
    with pytest.warns(ViewAdjustmentWarning, match="no fallback start map looked like a view "
                                                   "cone either: COVIS-SPARSE"):
        Q = va.fit_transform(X, **fit)
    assert va.starts_tried_ == ["DROPOUT-BLEND", "COVIS-SPARSE"]  # the first start not again
    assert va.start_method_ == "DROPOUT-BLEND" and va.cone_rejected_ and not va.refined_
    assert np.array_equal(Q, va.start_)


def test_a_given_start_and_a_start_that_is_a_cone_draw_no_fallback(monkeypatch):
    """Fallbacks are for drawn starts judged no cone: a good drawn start adjusts as without
    fallbacks (bit for bit), and a given start map's verdict stands."""
    P, X, fit = _fallback_case()
    with_fb = ViewAdjustment(fov_deg=90, start="COVIS-SPARSE",
                             fallback_starts=("DROPOUT-BLEND",)).fit(X, **fit)
    without = ViewAdjustment(fov_deg=90, start="COVIS-SPARSE", fallback_starts=()).fit(X, **fit)
    assert with_fb.starts_tried_ == ["COVIS-SPARSE"] and with_fb.refined_
    assert np.array_equal(with_fb.embedding_, without.embedding_)
    scattered = np.random.default_rng(1).uniform(-1.2, 1.2, P.shape)
    va = ViewAdjustment(fov_deg=90)
    with pytest.warns(ViewAdjustmentWarning, match="do not look like a view cone"):
        va.fit(X, **fit, start_positions=scattered)
    assert va.starts_tried_ == ["given"] and va.cone_rejected_


@pytest.mark.parametrize("bad", [("VIEW-BA",), (3,), "COVIS-SPARSE"])
def test_bad_fallback_starts_are_refused(bad):
    P, _, X, mask = _camera(90, n_steps=100)
    with pytest.raises(ValueError, match="fallback_starts"):
        ViewAdjustment(fallback_starts=bad).fit(X, mask=mask, anchor_ids=ANCHORS,
                                                anchor_positions=P[ANCHORS])
