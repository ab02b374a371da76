"""covis-consensus (mappers/covis_consensus.py): two anchored maps that check each other."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from threadpoolctl import threadpool_limits

import lfmdr_gym  # noqa: F401 - registers the envs
from lfmdr_gym.policies import RandomWalkPolicy
from lfmdr_gym.recording import collect
from mappers import build_map, mean_position_error
from mappers.covis_consensus import CovisConsensus


@pytest.fixture(autouse=True)
def _one_blas_thread():
    with threadpool_limits(limits=1):
        yield


@pytest.fixture(scope="module")
def camera():
    """A 90-degree visibility camera's masked history (N = 2000)."""
    env = gym.make("LFMDR-Visibility-v0", max_episode_steps=2000, fov_deg=90)
    return collect(env, RandomWalkPolicy.for_env(env), 2000, seed=22)


def _fit(h, **kw):
    est = CovisConsensus(**kw)
    Y = est.fit_transform(h.matrix, h.mask, sensor="visibility", anchor_ids=list(h.anchor_ids),
                          anchor_positions=h.anchor_positions)
    return est, Y


def test_it_returns_the_member_the_disagreement_chooses(camera):
    est, Y = _fit(camera)
    assert est.disagreement_ > 0
    assert np.array_equal(Y, est.maps_[est.choice_], equal_nan=True)
    strict, Ys = _fit(camera, max_disagreement=1e-9)   # any disagreement: the robust member
    assert strict.choice_ == "covis-cal" and np.array_equal(Ys, strict.maps_["covis-cal"])
    loose, Yl = _fit(camera, max_disagreement=100.0)   # never: the precise member
    assert loose.choice_ == "covis-power" and np.array_equal(Yl, loose.maps_["covis-power"])
    assert strict.disagreement_ == pytest.approx(loose.disagreement_)


def test_a_limited_view_map_through_build_map(camera):
    h = camera
    assert h.mask is not None and not h.mask.all()
    m = build_map(h, h.anchor_ids, h.anchor_positions, "covis-consensus")
    keep = np.setdiff1d(np.arange(h.n_objects), [*h.anchor_ids, *m.unmapped])
    err = mean_position_error(m.positions[keep], h.object_positions[keep])
    cal = build_map(h, h.anchor_ids, h.anchor_positions, "covis-cal")
    assert err < 0.07  # the two agree here (0.057 m); covis-cal alone: 0.071 m
    assert err < mean_position_error(cal.positions[keep], h.object_positions[keep])
    assert np.allclose(m.positions[list(h.anchor_ids)], h.anchor_positions, atol=1e-6)


def test_it_refuses_bad_settings_and_missing_anchors(camera):
    for bad in (0, -1.0, "0.1"):
        with pytest.raises(ValueError, match="max_disagreement"):
            CovisConsensus(max_disagreement=bad)
    with pytest.raises(ValueError, match="anchors"):
        CovisConsensus().fit_transform(camera.matrix, camera.mask, sensor="visibility")
