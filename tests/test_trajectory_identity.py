"""Speed work must not move a trajectory: histories recorded today equal those of before it.

``data/trajectory_digests.json`` holds SHA-256 digests of histories collected with the code of
commit cd9afe2 (before the per-step speed work of issue #13), by :func:`digest` below, for three
seeds of each case: both mapping sensors and range, the sensing keywords of issue #11 on, and a
500-object world (the cell grid). Each history (sensor matrix, mask, robot poses, blocked moves,
layout) must hash the same today.

The digest rounds every float to 1e-9 first. Bit for bit, the noisy bearing case depends on the
platform's libm: on one machine with numpy 2.4 its bearings differ in the last bit from those the
digests were first written with, while cd9afe2's code and today's give the same bits there. Any
change to a trajectory (a move, a turn, a reading) moves values by far more than 1e-9.
"""

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from lfmdr_gym.policies import RandomWalkPolicy
from lfmdr_gym.recording import collect

DIGESTS = json.loads((Path(__file__).parent / "data" / "trajectory_digests.json").read_text())

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
    """SHA-256 of a history's matrix, robot poses, blocked-move count, layout and mask, its floats
    rounded to 1e-9 (a negative zero made positive, so that the sign of a rounded-away difference
    cannot change the bytes)."""
    parts = [history.matrix.astype(np.float64), history.robot_poses,
             np.array([history.meta["blocked_moves"]]), history.object_positions]
    if history.mask is not None:
        parts.append(history.mask)
    h = hashlib.sha256()
    for part in parts:
        part = np.asarray(part)
        if part.dtype.kind == "f":
            part = np.round(part.astype(np.float64), 9) + 0.0
        h.update(np.ascontiguousarray(part).tobytes())
    return h.hexdigest()


@pytest.mark.parametrize("case", sorted(CASES))
def test_histories_are_bit_identical_to_those_before_the_speed_work(case):
    env_id, kwargs = CASES[case]
    for seed in SEEDS:
        history = collect(env_id, RandomWalkPolicy(seed=seed), 1000, seed=seed,
                          make_kwargs=kwargs)
        assert digest(history) == DIGESTS[f"{case}/{seed}"], (case, seed)
        if history.mask is not None:  # the compact (sparse) recording of a masked history too
            small = collect(env_id, RandomWalkPolicy(seed=seed), 1000, seed=seed,
                            make_kwargs=kwargs, compact=True)
            assert small.sparse_mask is not None
            assert digest(small) == DIGESTS[f"{case}/{seed}"], (case, seed, "compact")
