"""Speed work must not move a trajectory: histories recorded today equal those of before it.

``data/trajectory_digests.json`` holds SHA-256 digests of histories collected with the code of
commit cd9afe2 (before the per-step speed work of issue #13), by :func:`digest` below, for three
seeds of each case: both mapping sensors and range, the sensing keywords of issue #11 on, and a
500-object world (the cell grid). Each history (sensor matrix, mask, robot poses, blocked moves,
layout) must hash the same today.

The matrix is compared by three sums, to a relative 1e-9, not by its bytes: bit for bit, the
noisy bearing case's readings depend on the platform's libm (on a machine with numpy 2.4.6 a few
of its float32 readings differ in the last bit from those the digests were first written with,
while cd9afe2's code and today's give the same bits there). Everything else (the robot's poses,
the blocked moves, the layout, the mask, and where the matrix is NaN) is hashed bit for bit. Any
change to a trajectory moves many readings by far more than the tolerance.
"""

import hashlib
import json

import numpy as np
import pytest
from paths import TEST_DATA

from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from lfmdr_gym.histories.recording import collect

DIGESTS = json.loads((TEST_DATA / "trajectory_digests.json").read_text())

CASES = {
    "visibility": ("LFMDR-Visibility-v0", {}),
    "bearing": ("LFMDR-Bearing-v0", {}),
    "range": ("LFMDR-Range-v0", {}),
    "visibility-limits": ("LFMDR-Visibility-v0", {"fov_deg": 120.0, "max_range": 1.0,
                                                  "miss_rate": 0.1, "false_rate": 0.01}),
    "bearing-limits": ("LFMDR-Bearing-v0", {"max_range": 1.5, "bearing_noise_deg": 2.0,
                                            "line_of_sight": True}),
    "visibility-M500": ("LFMDR-Visibility-v0", {"n_objects": 500,
                                                "arena_size": 7.905694150420948,
                                                "anchors": "random", "n_anchors": 40}),
}
SEEDS = (0, 7, 123)


def digest(history) -> str:
    """SHA-256 of a history's robot poses, blocked-move count, layout, mask and NaN pattern."""
    parts = [np.isnan(history.matrix), history.robot_poses,
             np.array([history.meta["blocked_moves"]]), history.object_positions]
    if history.mask is not None:
        parts.append(history.mask)
    h = hashlib.sha256()
    for part in parts:
        h.update(np.ascontiguousarray(part).tobytes())
    return h.hexdigest()


def matrix_sums(history) -> list[float]:
    """The sum, absolute sum and an index-weighted sum of the matrix's readings (NaN as 0)."""
    m = np.nan_to_num(np.asarray(history.matrix, dtype=np.float64))
    weights = (np.arange(m.size, dtype=np.float64) % 997).reshape(m.shape) / 997.0
    return [float(m.sum()), float(np.abs(m).sum()), float((m * weights).sum())]


def check(history, case: str, seed: int, what: str = "") -> None:
    expected = DIGESTS[f"{case}/{seed}"]
    assert digest(history) == expected["digest"], (case, seed, what)
    np.testing.assert_allclose(matrix_sums(history), expected["matrix_sums"], rtol=1e-9,
                               atol=1e-9, err_msg=f"{case}/{seed} {what}")


@pytest.mark.parametrize("case", sorted(CASES))
def test_histories_match_those_before_the_speed_work(case):
    env_id, kwargs = CASES[case]
    for seed in SEEDS:
        history = collect(env_id, RandomWalkPolicy(seed=seed), 1000, seed=seed,
                          make_kwargs=kwargs)
        check(history, case, seed)
        if history.mask is not None:  # the compact (sparse) recording of a masked history too
            small = collect(env_id, RandomWalkPolicy(seed=seed), 1000, seed=seed,
                            make_kwargs=kwargs, compact=True)
            assert small.sparse_mask is not None
            check(small, case, seed, "compact")
