"""The one binning of logged sightings (lfmdr_gym/histories/binning.py) and MRCLAM's bin_run on it.

The reference below is the per-cell loop ``bin_run`` used before the binning was vectorised
(np.add.at sums, np.median per cell): the vectorised code must give the same bits.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from lfmdr_gym.datasets.mrclam import MRCLAMReport, MRCLAMRun, bin_run
from lfmdr_gym.histories.binning import assemble, cell_values, tick_steps, time_steps


def _reference(obs: np.ndarray, robots: list[int], m: int, sensor: str, bw: float, drop: bool):
    """bin_run as it was written before (dense np.add.at and a median per cell)."""
    t0 = obs[:, 1].min()
    n_per = int(np.floor((obs[:, 1].max() - t0) / bw)) + 1
    pos = np.array([robots.index(int(r)) for r in obs[:, 0]])
    col = pos * n_per + np.floor((obs[:, 1] - t0) / bw).astype(np.int64)
    used, inv = (np.unique(col, return_inverse=True) if drop
                 else (np.arange(len(robots) * n_per), col))
    li = obs[:, 2].astype(np.int64)
    seen = np.zeros((m, len(used)))
    np.add.at(seen, (li, inv), 1.0)
    seen = seen > 0
    n = seen.shape[1]
    if sensor == "visibility":
        matrix, mask = seen.astype(float), seen.copy()
    elif sensor == "bearing":
        c, s = np.zeros((m, n)), np.zeros((m, n))
        np.add.at(c, (li, inv), np.cos(obs[:, 4]))
        np.add.at(s, (li, inv), np.sin(obs[:, 4]))
        norm = np.hypot(c, s)
        ok = seen & (norm > 1e-12)
        matrix = np.empty((m, 2 * n))
        matrix[:, 0::2] = np.where(ok, c / np.where(ok, norm, 1), 0.0)
        matrix[:, 1::2] = np.where(ok, s / np.where(ok, norm, 1), 0.0)
        mask = np.repeat(ok, 2, axis=1)
    else:
        matrix = np.zeros((m, n))
        for i in range(m):
            for j in range(n):
                sel = (li == i) & (inv == j)
                if sel.any():
                    matrix[i, j] = np.median(obs[sel, 3])
        mask = seen.copy()
    timeline = np.column_stack([used // n_per, used % n_per]).astype(np.int64)
    return matrix, mask, timeline


def _synthetic_run(seed: int, robots=(2, 1)) -> MRCLAMRun:
    """A small run: bins with one, two (an even median) and many readings, and a bin whose two
    bearings cancel exactly (no mean bearing: unobserved)."""
    rng = np.random.default_rng(seed)
    rows = []
    for r in robots:
        for t in np.sort(rng.uniform(10.0, 40.0, 60)):
            for lm in rng.choice(6, size=rng.integers(1, 4), replace=False):
                rows.append((r, t, lm, rng.uniform(0.3, 5.0), rng.uniform(-0.6, 0.6)))
    rows += [(robots[0], 41.0, 0, 1.0, 0.5), (robots[0], 41.01, 0, 2.0, 0.5 - np.pi)]
    obs = np.array(rows, dtype=float)
    obs = obs[np.lexsort((obs[:, 1], [list(robots).index(int(r)) for r in obs[:, 0]]))]
    report = MRCLAMReport(run="synthetic", robots=tuple(robots), rows=len(obs), robot_rows=0,
                          unknown_barcode_rows=0, repeat_rows=0, landmark_rows=len(obs),
                          per_robot_landmark_rows={}, groundtruth_fix="none")
    return MRCLAMRun("synthetic", np.arange(10, 16), rng.uniform(-3, 3, (6, 2)), obs,
                     np.zeros(len(obs), np.int64), report)


@pytest.mark.parametrize("sensor", ["visibility", "bearing", "range"])
@pytest.mark.parametrize(("bw", "drop"), [(0.7, True), (2.0, False), (0.05, True)])
def test_bin_run_matches_the_per_cell_loop_bit_for_bit(sensor, bw, drop):
    run = _synthetic_run(3)
    matrix, mask, info, timeline = bin_run(run, sensor, bw, drop_empty_bins=drop)
    ref = _reference(run.obs, list(run.report.robots), 6, sensor, bw, drop)
    for got, want in zip((matrix, mask, timeline), ref, strict=True):
        assert got.dtype == want.dtype and got.shape == want.shape
        assert got.tobytes() == want.tobytes()
    assert info["n_bins"] == timeline.shape[0] == matrix.shape[1] // (2 if sensor == "bearing" else 1)
    assert sum(info["bins_per_robot"].values()) == info["n_bins"]


def test_cancelling_bearings_leave_the_cell_unobserved():
    cells = cell_values(("bearing",), np.array([0, 0]), np.array([0, 0]), (1, 1),
                        bearing=np.array([0.5, 0.5 - np.pi]))
    assert not cells.observed["bearing"][0]
    matrix, mask = assemble(cells, "bearing")
    assert not mask.any() and not matrix.any()


def test_a_single_unit_vector_is_kept_exactly_and_several_are_averaged():
    unit = np.array([[0.6, 0.8], [1.0, 0.0], [0.0, 1.0]])
    cells = cell_values(("bearing",), np.array([0, 1, 1]), np.array([0, 0, 0]), (2, 1),
                        bearing_unit=unit)
    np.testing.assert_array_equal(cells.values["bearing"][0], [0.6, 0.8])
    np.testing.assert_allclose(cells.values["bearing"][1], [np.sqrt(0.5), np.sqrt(0.5)], atol=1e-15)


def test_median_of_an_even_count_is_the_mean_of_the_middle_two():
    cells = cell_values(("range",), np.zeros(4, np.int64), np.zeros(4, np.int64), (1, 1),
                        range_=np.array([4.0, 1.0, 3.0, 10.0]))
    assert cells.values["range"][0] == 3.5


def test_visible_column_gives_observed_zeros():
    cells = cell_values(("visibility",), np.array([0, 1, 1]), np.array([0, 0, 0]), (2, 1),
                        visible=np.array([False, False, True]))
    matrix, mask = assemble(cells, "visibility")
    np.testing.assert_array_equal(matrix, [[0.0], [1.0]])
    np.testing.assert_array_equal(mask, [[True], [True]])


def test_sparse_and_dense_assembly_agree():
    rng = np.random.default_rng(0)
    lm, st = rng.integers(0, 5, 40), rng.integers(0, 9, 40)
    cells = cell_values(("visibility", "bearing", "range"), lm, st, (5, 9),
                        bearing=rng.uniform(-3, 3, 40), range_=rng.uniform(0, 4, 40))
    for sensor in ("visibility", "bearing", "range"):
        dense, dmask = assemble(cells, sensor, sparse=False)
        sparse, smask = assemble(cells, sensor, sparse=True)
        assert sp.issparse(sparse) and sp.issparse(smask)
        np.testing.assert_array_equal(sparse.toarray(), dense)
        np.testing.assert_array_equal(smask.toarray(), dmask)
        unmasked = assemble(cells, sensor, masked=False)[1]
        assert unmasked is None


def test_tick_steps_orders_by_robot_then_tick_and_keeps_extra_steps():
    steps = tick_steps(np.array([1, 0, 1, 0]), np.array([5, 7, 2, 7]), 2,
                       extra=np.array([[0, 3]]))
    np.testing.assert_array_equal(steps.timeline, [[0, 3], [0, 7], [1, 2], [1, 5]])
    np.testing.assert_array_equal(steps.step, [3, 1, 2, 1])


def test_tick_steps_with_huge_ticks_sorts_pairs():
    big = np.array([2**61, 5, 2**61, 2**40])
    steps = tick_steps(np.array([0, 1, 1, 1]), big, 2)
    np.testing.assert_array_equal(steps.timeline, [[0, 2**61], [1, 5], [1, 2**40], [1, 2**61]])
    np.testing.assert_array_equal(steps.step, [0, 1, 3, 2])


def test_bad_binning_input_is_refused():
    with pytest.raises(ValueError, match="bin_width"):
        time_steps(np.zeros(2, np.int64), np.array([0.0, 1.0]), 1, 0.0)
    with pytest.raises(ValueError, match="robot positions"):
        time_steps(np.array([0, 2]), np.array([0.0, 1.0]), 2, 1.0)
    with pytest.raises(ValueError, match=">= 0"):
        tick_steps(np.zeros(2, np.int64), np.array([-1, 3]), 1)
