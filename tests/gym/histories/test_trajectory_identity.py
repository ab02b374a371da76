"""Speed work must not move a trajectory: histories recorded today equal those of before it.

``data/trajectory_digests.json`` holds SHA-256 digests of histories collected with the code of
commit cd9afe2 (before the per-step speed work of issue #13), by :func:`digest` below, for three
seeds of each case: both mapping sensors and range, the sensing keywords of issue #11 on, and a
500-object world (the cell grid), and three sums of each matrix. Today's histories must hash the
same, and their matrices sum the same.

The matrix is compared by three sums (:func:`matrix_sums`), not by its bytes. A visibility
matrix holds 0/1 readings: its sum and absolute sum are counts of ones, compared exactly. A
bearing or range matrix holds float32 readings, which depend on the CPU, not only on the code:
the bearing noise goes through numpy's vectorised ``arctan2`` / ``cos`` / ``sin``, whose SIMD
paths (and the libm underneath) differ by a few float32 units in the last place from machine to
machine (on one machine the noisy bearing case's sums moved by 6.5e-7 relative: a sum of
readings of both signs cancels, the error of the readings does not). Those sums are compared
within :data:`FLOAT_READINGS_RTOL` of the absolute sum (see there). Everything else (the robot's
poses, the blocked moves, the layout, the mask, and where the matrix is NaN) is hashed bit for
bit: a trajectory that moves changes those.
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


# Each float32 reading may differ across CPUs by a few units in its last place (2**-23 ~ 1.2e-7
# at 1; the bearings' angles pass through SIMD arctan2/cos/sin): each of the three sums then
# moves by at most sum_i |dx_i|, a few 1e-7 times the absolute sum of the readings even if every
# reading moved the same way. 1e-6 of the absolute sum covers ~8 units in the last place on every
# reading (the 6.5e-7-relative move of the noisy bearing case is 2.5e-8 of its absolute sum, 0.0007
# of a tolerance of 0.029). A change to what is sensed or to the noise moves the sums by far more:
# another 2 degrees of noise on that case's 45,000 readings moves the absolute sum by 1.7 and the
# weighted sum by 0.57 (20 to 60 times the tolerance); a moved trajectory changes the digest.
FLOAT_READINGS_RTOL = 1e-6


def check(history, case: str, seed: int, what: str = "") -> None:
    expected = DIGESTS[f"{case}/{seed}"]
    label = f"{case}/{seed} {what}"
    assert digest(history) == expected["digest"], label
    got, want = matrix_sums(history), expected["matrix_sums"]
    if history.sensor == "visibility":
        # 0/1 readings: the sum and the absolute sum count the ones, exactly; the weighted sum is
        # float summation alone (no transcendental function), within its rounding
        assert got[:2] == want[:2], label
        np.testing.assert_allclose(got[2], want[2], rtol=1e-12, err_msg=label)
    else:
        np.testing.assert_allclose(got, want, rtol=0, atol=FLOAT_READINGS_RTOL * want[1],
                                   err_msg=label)


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
