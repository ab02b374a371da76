"""The scores the protocol and the benchmarks report (lfmdr_gym/experiments/scoring.py)."""

from __future__ import annotations

import numpy as np

from lfmdr_gym.experiments.scoring import mpe_nonanchor, score_map
from lfmdr_gym.histories.history import History


def _history(truth):
    m = len(truth)
    return History(sensor="visibility", matrix=np.ones((m, 3)), anchor_ids=(0, 1, 2),
                   anchor_positions=truth[:3], object_positions=truth)


def test_mpe_nonanchor_skips_anchors_and_unmapped_objects():
    truth = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.5, 0.5], [0.2, 0.8], [0.9, 0.9]])
    est = truth.copy()
    est[0] += 5.0  # an anchor's error is not scored
    est[3] += [0.3, 0.4]  # 0.5 m off
    est[4] = np.nan  # unmapped
    est[5] += [0.0, 0.1]  # 0.1 m off
    h = _history(truth)
    assert np.isclose(mpe_nonanchor(est, [4], h), 0.3)
    assert score_map(est, [4], h)["mpe_nonanchor"] == mpe_nonanchor(est, [4], h)
    # nothing mapped but the anchors: no figure rather than an error
    assert np.isnan(mpe_nonanchor(est, [3, 4, 5], h))


def test_map_history_file_without_a_method_takes_build_maps_default(tmp_path):
    """``lfmdr map`` chooses as ``build_map`` does: a flickering visibility history (a camera's
    dropouts) gets the table's dropout default, not the plain visibility one."""
    import gymnasium as gym

    import mappers
    from lfmdr_gym import RandomWalkPolicy, collect
    from lfmdr_gym.experiments.mapping import map_history_file

    # 300 steps: the flicker is read as at 600 (VIS-BA-WALK chosen), at 2/3 of the CPU
    env = gym.make("LFMDR-Visibility-v0", max_episode_steps=300, miss_rate=0.5)
    history = collect(env, RandomWalkPolicy.for_env(env), 300, seed=3)
    path = tmp_path / "flicker.npz"
    history.save(path)
    chosen = mappers.default_method(history)
    assert chosen == "VIS-BA-WALK"
    info = map_history_file(path, out=tmp_path / "out")
    assert info["method"] == chosen == info["map"].method
