"""Dropouts read from the data: the flicker rate (mappers/core/flicker.py), DROPOUT-BLEND
(mappers/masked/dropout_blend.py) and build_map's routing of flickering visibility histories (to
VIS-BA-WALK, mappers/viewpoints/visibility.py)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from map_errors import map_error

import lfmdr_gym  # noqa: F401 - registers the envs
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from lfmdr_gym.histories.recording import collect
from mappers import build_map, default_method, mean_position_error
from mappers.core.flicker import (
    FLICKER_THRESHOLD,
    MIN_PERSISTENCE,
    flicker_rate,
    persistence,
    step_runs,
)
from mappers.masked.dropout_blend import DropoutBlend, smooth_steps

pytestmark = pytest.mark.usefixtures("one_blas_thread")


def _episode(seed: int, steps: int = 2000, **sensing):
    env = gym.make("LFMDR-Visibility-v0", max_episode_steps=steps, **sensing)
    return collect(env, RandomWalkPolicy.for_env(env), steps, seed=seed)


def test_flicker_rate_by_hand():
    X = np.array([[1, 0, 1, 1, 1],    # both sides visible at steps 1 (a flicker) and 3 (seen)
                  [1, 1, 0, 0, 1],    # a two-step gap: no step has both sides visible
                  [0, 1, 0, 1, 0]])   # both sides visible at step 2: a flicker
    assert flicker_rate(X) == pytest.approx(2 / 3)
    assert np.isnan(flicker_rate(np.zeros((2, 5))))
    with pytest.raises(ValueError, match="2-D"):
        flicker_rate(np.ones(4))


def test_flicker_rate_follows_the_timeline():
    """Steps of two robots interleaved: a 0 between two 1s of *other* robots' steps is no
    flicker; each robot's own run is read in tick order."""
    X = np.array([[1, 0, 1, 0, 1, 1]])
    tl = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [0, 2], [1, 2]])
    # robot 0: steps 0, 2, 4 -> 1, 1, 1 (no flicker); robot 1: steps 1, 3, 5 -> 0, 0, 1
    assert flicker_rate(X, tl) == 0.0
    assert flicker_rate(X) == 1.0  # read as one robot: steps 1 and 3 are flickers
    runs = step_runs(6, tl)
    assert [r.tolist() for r in runs] == [[0, 2, 4], [1, 3, 5]]
    gap = np.array([[0, 0], [0, 1], [0, 5], [0, 6]])  # a tick gap breaks the run
    assert [r.tolist() for r in step_runs(4, gap)] == [[0, 1], [2, 3]]


def test_flicker_rate_reads_the_miss_rate_and_not_perfect_sensing():
    perfect = _episode(3, 1000)
    rate = flicker_rate(perfect.matrix)
    assert rate < FLICKER_THRESHOLD / 2
    for miss in (0.2, 0.5):
        h = _episode(3, 1000, miss_rate=miss)
        assert h.mask is None or h.mask.all()  # a miss is measured: the history is complete
        assert flicker_rate(h.matrix) == pytest.approx(miss + rate * (1 - miss), abs=0.04)


def test_unordered_viewpoints_are_not_read_as_dropouts():
    """Viewpoints drawn at random (no walk): steps two apart are unrelated, so a 0 between two
    1s says nothing about misses; persistence tells, and build_map keeps CAL-SMA."""
    rng = np.random.default_rng(0)
    P = rng.uniform(-1.2, 1.2, size=(30, 2))
    robot = rng.uniform(-1.2, 1.2, size=(1500, 2))
    X = (np.linalg.norm(P[:, None] - robot[None], axis=2) < 0.55).astype(float)
    assert flicker_rate(X) > FLICKER_THRESHOLD  # it would be read as dropouts
    assert persistence(X) < 1.3 < MIN_PERSISTENCE
    walk = _episode(3, 1000, miss_rate=0.5)
    assert persistence(walk.matrix) > 2 * MIN_PERSISTENCE
    anchors = [int(np.argmin(np.linalg.norm(P - c, axis=1))) for c in ((-1, -1), (1, -1), (1, 1))]
    assert build_map(X, anchors, P[anchors]).method == "CAL-SMA"
    with pytest.raises(ValueError, match="2-D"):
        persistence(np.ones(3))


def test_smooth_steps_averages_within_each_run():
    X = np.array([[0.0, 3.0, 0.0, 3.0]])
    assert smooth_steps(X, 3).tolist() == [[1.0, 1.0, 2.0, 2.0]]  # ends repeat the edge step
    assert smooth_steps(X, 1).tolist() == X.tolist()
    tl = np.array([[0, 0], [1, 0], [0, 1], [1, 1]])  # robot 0: 0, 0; robot 1: 3, 3
    assert smooth_steps(X, 3, tl).tolist() == [[0.0, 3.0, 0.0, 3.0]]
    for bad in (0, 2.5, True):
        with pytest.raises(ValueError, match="window"):
            smooth_steps(X, bad)


def test_perfect_histories_keep_the_complete_default_exactly():
    h = _episode(4, 600)
    default = build_map(h, h.anchor_ids, h.anchor_positions)
    named = build_map(h, h.anchor_ids, h.anchor_positions, "CAL-SMA")
    assert default.method == "CAL-SMA" and not default.warnings
    assert np.array_equal(default.positions, named.positions)


def test_default_method_names_what_build_map_picks():
    assert default_method(_episode(4, 300)) == "CAL-SMA"
    assert default_method(_episode(4, 300, miss_rate=0.5)) == "VIS-BA-WALK"
    assert default_method(_episode(4, 300, fov_deg=90)) == "VIEW-BA"  # masked


def test_a_flickering_history_is_mapped_by_vis_ba_walk_and_better():
    """miss_rate 0.5 on two layouts: the default reads the flicker, says so (and what it
    assumes), and its maps beat CAL-SMA's and DROPOUT-BLEND's on the same histories."""
    walk, blend, cal = [], [], []
    for seed in (11, 12):
        h = _episode(seed, 2000, miss_rate=0.5)
        m = build_map(h, h.anchor_ids, h.anchor_positions)
        assert m.method == "VIS-BA-WALK"
        assert any("flickers" in w and "VIS-BA-WALK" in w and "walk" in w for w in m.warnings)
        walk.append(map_error(m, h))
        blend.append(map_error(build_map(h, h.anchor_ids, h.anchor_positions, "DROPOUT-BLEND"), h))
        cal.append(map_error(build_map(h, h.anchor_ids, h.anchor_positions, "CAL-SMA"), h))
    assert np.mean(blend) < 0.95 * np.mean(cal)
    assert np.mean(walk) < 0.9 * np.mean(blend)
    assert max(walk) < 0.08


def test_dropout_blend_is_the_mean_of_its_two_anchored_maps():
    h = _episode(5, 800, miss_rate=0.3)
    est = DropoutBlend()
    Y = est.fit_transform(h.matrix, sensor="visibility", anchor_ids=np.array(h.anchor_ids),
                          anchor_positions=h.anchor_positions)
    a, b = est.maps_.values()
    assert np.allclose(Y, 0.5 * (a + b))
    assert est.blended_ and est.disagreement_ < est.max_disagreement
    for member in (a, b):  # both hold the anchors at their positions
        assert np.allclose(member[list(h.anchor_ids)], h.anchor_positions, atol=1e-6)


def test_dropout_blend_refuses_what_it_cannot_map():
    X = np.ones((5, 10))
    with pytest.raises(ValueError, match="visibility"):
        DropoutBlend().fit_transform(X, sensor="bearing", anchor_ids=[0, 1, 2],
                                     anchor_positions=np.eye(3, 2))
    with pytest.raises(ValueError, match="anchors"):
        DropoutBlend().fit_transform(X, sensor="visibility")
    fit = dict(sensor="visibility", anchor_ids=[0, 1, 2], anchor_positions=np.eye(3, 2))
    with pytest.raises(ValueError, match="window"):  # parameters are checked when fitting
        DropoutBlend(window=0).fit(X, **fit)
    for bad in (0, -0.1, True, "0.1", float("nan")):
        with pytest.raises(ValueError, match="max_disagreement"):
            DropoutBlend(max_disagreement=bad).fit(X, **fit)


def test_an_object_flung_away_by_one_member_keeps_the_cal_sma_position(monkeypatch):
    """covis-nonmetric can fling a weakly tied object kilometres away on very sparse data; the
    blend then keeps CAL-SMA's position for it, and says so."""
    import mappers.masked.dropout_blend as db

    h = _episode(5, 600, miss_rate=0.3)
    ids = list(h.anchor_ids)
    far = int(np.setdiff1d(np.arange(h.n_objects), ids)[0])

    class Flung:
        def __init__(self, *args, **kwargs):
            pass

        def fit_transform(self, X, mask=None, **kw):
            Y = h.object_positions.copy()
            Y[far] += 1000.0
            return Y

    monkeypatch.setattr(db, "MaskedMapper", Flung)
    est = DropoutBlend()
    with pytest.warns(UserWarning, match=rf"objects \[{far}\].*CAL-SMA"):
        Y = est.fit_transform(h.matrix, sensor="visibility", anchor_ids=ids,
                              anchor_positions=h.anchor_positions)
    assert np.array_equal(Y[far], est.maps_["CAL-SMA"][far])
    others = np.setdiff1d(np.arange(h.n_objects), [far])
    assert np.allclose(Y[others], 0.5 * (est.maps_["CAL-SMA"][others] + h.object_positions[others]))


def _covis_member(monkeypatch, positions):
    """Replace dropout-blend's covis-nonmetric member by one returning ``positions``."""
    import mappers.masked.dropout_blend as db

    class Given:
        def __init__(self, *args, **kwargs):
            pass

        def fit_transform(self, X, mask=None, **kw):
            return positions.copy()

    monkeypatch.setattr(db, "MaskedMapper", Given)


def test_a_member_that_fails_as_a_whole_leaves_the_map_to_cal_sma(monkeypatch):
    """When the two maps disagree as a whole (a fold, or a map flung far on sparse data: through
    a 90-degree view covis-nonmetric's did so on a third of our tuning histories), their mean is
    no map: DROPOUT-BLEND returns CAL-SMA's and says so; max_disagreement=None blends anyway."""
    h = _episode(5, 600, miss_rate=0.3)
    ids = list(h.anchor_ids)
    folded = h.object_positions.copy()
    free = np.setdiff1d(np.arange(h.n_objects), ids)
    folded[free, 0] *= -1.0  # every free object mirrored across the arena's axis: a fold
    _covis_member(monkeypatch, folded)
    est = DropoutBlend()
    with pytest.warns(UserWarning, match=r"disagree by .* the map is CAL-SMA's"):
        Y = est.fit_transform(h.matrix, sensor="visibility", anchor_ids=ids,
                              anchor_positions=h.anchor_positions)
    assert not est.blended_ and est.disagreement_ > est.max_disagreement
    assert np.array_equal(Y, est.maps_["CAL-SMA"])
    loose = DropoutBlend(max_disagreement=None)
    with pytest.warns(UserWarning, match="farther apart"):  # the per-object guard, still on
        Y2 = loose.fit_transform(h.matrix, sensor="visibility", anchor_ids=ids,
                                 anchor_positions=h.anchor_positions)
    assert loose.blended_
    cal = loose.maps_["CAL-SMA"]
    pos = h.anchor_positions
    spread = np.sqrt(np.mean(np.sum((pos - pos.mean(axis=0)) ** 2, axis=1)))
    mean = np.linalg.norm(cal - folded, axis=1) <= spread  # the others: the per-object guard's
    assert mean.sum() > len(ids)
    assert np.allclose(Y2[mean], 0.5 * (cal[mean] + folded[mean]))
    assert np.array_equal(Y2[~mean], cal[~mean])


def test_the_median_disagreement_ignores_one_flung_object(monkeypatch):
    """One object flung far is the per-object guard's: the rest is still blended."""
    h = _episode(5, 600, miss_rate=0.3)
    near = h.object_positions + 0.01  # agrees with CAL-SMA to a few centimetres
    far = int(np.setdiff1d(np.arange(h.n_objects), h.anchor_ids)[0])
    near[far] += 1000.0
    _covis_member(monkeypatch, near)
    est = DropoutBlend()
    with pytest.warns(UserWarning, match=rf"objects \[{far}\]"):
        est.fit_transform(h.matrix, sensor="visibility", anchor_ids=list(h.anchor_ids),
                          anchor_positions=h.anchor_positions)
    assert est.blended_ and est.disagreement_ < 0.1


def test_unordered_viewpoints_are_blended_even_when_the_members_disagree():
    """On viewpoints drawn at random CAL-SMA's window mixes unrelated steps and it is the member
    that fails: the disagreement check applies to walk-ordered steps only."""
    rng = np.random.default_rng(0)  # tests/mappers/test_pipeline.py's world: a jittered grid
    g = np.linspace(-1.0, 1.0, 7)
    grid = np.array([(x, y) for x in g for y in g])
    idx = np.concatenate([[0, 6, 42, 48], rng.choice(np.arange(1, 42), 36, replace=False)])
    P = grid[idx] + rng.uniform(-0.05, 0.05, (40, 2))
    R = rng.uniform(-1.25, 1.25, (1200, 2))
    X = (np.linalg.norm(P[:, None] - R[None], axis=2) < 0.55).astype(float)
    est = DropoutBlend()
    with pytest.warns(UserWarning, match="folded"):  # CAL-SMA's own fold guard says so too
        Y = est.fit_transform(X, mask=X > 0, sensor="visibility", anchor_ids=[0, 1, 2, 3],
                              anchor_positions=P[:4])
    assert not est.walk_ordered_ and est.blended_
    assert est.disagreement_ > est.max_disagreement  # the check would have fired on a walk
    cal, covis = est.maps_.values()
    assert mean_position_error(covis[4:], P[4:]) < mean_position_error(cal[4:], P[4:])
    assert mean_position_error(Y[4:], P[4:]) < mean_position_error(cal[4:], P[4:])


def test_a_member_flung_to_infinity_counts_as_disagreeing(monkeypatch):
    """A member whose free objects lie at infinity (an overflowed solve) is as far off as a map
    can be: the check keeps CAL-SMA's map, it does not drop those objects from the median."""
    h = _episode(5, 600, miss_rate=0.3)
    ids = list(h.anchor_ids)
    flung = h.object_positions.copy()
    flung[np.setdiff1d(np.arange(h.n_objects), ids)] = np.inf
    _covis_member(monkeypatch, flung)
    est = DropoutBlend()
    with pytest.warns(UserWarning, match="the map is CAL-SMA's"):
        Y = est.fit_transform(h.matrix, sensor="visibility", anchor_ids=ids,
                              anchor_positions=h.anchor_positions)
    assert not est.blended_ and est.disagreement_ == np.inf
    assert np.array_equal(Y, est.maps_["CAL-SMA"]) and np.all(np.isfinite(Y))
