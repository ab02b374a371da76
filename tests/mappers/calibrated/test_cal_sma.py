"""Tests of the calibrated anchored SMACOF mapper (CAL-SMA, issue 6)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from paths import EXAMPLES

from mappers import METHODS, build_map, mean_orientation_error, mean_position_error
from mappers.calibrated.cal_sma import (
    CalibratedSMACOF,
    FoldWarning,
    fold_score,
    history_dissimilarity,
)

HALF = 1.25


def _layout(rng: np.random.Generator, m: int = 40, spacing: float = 0.2) -> np.ndarray:
    pts: list[np.ndarray] = []
    while len(pts) < m:
        p = rng.uniform(-HALF + 0.15, HALF - 0.15, 2)
        if all(np.hypot(*(p - q)) >= spacing for q in pts):
            pts.append(p)
    return np.array(pts)


def _corner_anchors(pts: np.ndarray) -> np.ndarray:
    ids: list[int] = []
    for c in ([-HALF, -HALF], [HALF, -HALF], [HALF, HALF], [-HALF, HALF]):
        d = np.hypot(*(pts - np.array(c)).T)
        d[ids] = np.inf
        ids.append(int(np.argmin(d)))
    return np.array(ids)


def _histories(pts: np.ndarray, sensor: str, n: int, rng: np.random.Generator) -> np.ndarray:
    """Synthetic histories from known points: robot at uniform random poses, a smooth sensor.

    Visibility: seen within 0.55 m (the paper's 5-degree rule for 48 mm cylinders, no
    occlusion). Bearing: (cos, sin) of the angle to the object relative to a random heading.
    """
    robot = rng.uniform(-HALF + 0.05, HALF - 0.05, size=(n, 2))
    rel = pts[None, :, :] - robot[:, None, :]
    if sensor == "visibility":
        return (np.hypot(rel[..., 0], rel[..., 1]) < 0.55).T.astype(float)
    heading = rng.uniform(-np.pi, np.pi, size=(n, 1))
    theta = np.arctan2(rel[..., 1], rel[..., 0]) - heading
    out = np.empty((pts.shape[0], 2 * n))
    out[:, 0::2] = np.cos(theta).T
    out[:, 1::2] = np.sin(theta).T
    return out


@pytest.fixture(scope="module")
def world():
    rng = np.random.default_rng(7)
    pts = _layout(rng)
    return pts, _corner_anchors(pts), rng


@pytest.mark.parametrize(("sensor", "tol_mpe", "tol_moe"), [("visibility", 0.07, 2.5),
                                                             ("bearing", 0.05, 1.5)])
def test_recovers_known_layout(world, sensor, tol_mpe, tol_moe):
    pts, ids, _ = world
    X = _histories(pts, sensor, 1500, np.random.default_rng(1))
    est = CalibratedSMACOF()
    Y = est.fit_transform(X, anchor_ids=ids, anchor_positions=pts[ids])
    assert Y.shape == pts.shape
    assert mean_position_error(Y, pts, exclude=ids) < tol_mpe
    assert mean_orientation_error(Y, pts) < tol_moe
    assert est.fold_score_ <= est.fold_threshold and not est.folded_
    assert est.anchored_ and est.dissimilarity_kind_ == (
        "cosine" if sensor == "visibility" else "euclidean")


def test_meets_anchors_exactly(world):
    pts, ids, _ = world
    X = _histories(pts, "visibility", 1000, np.random.default_rng(2))
    # anchors anywhere (not collinear): the map must put them exactly there
    target = pts[ids] + np.array([[0.05, -0.02], [0.0, 0.03], [-0.04, 0.0], [0.01, 0.01]])
    Y = CalibratedSMACOF().fit_transform(X, anchor_ids=ids, anchor_positions=target)
    np.testing.assert_allclose(Y[ids], target, rtol=0, atol=1e-12)


def test_better_than_unweighted_cosine_smacof(world):
    """The calibration must improve on plain SMACOF of the same dissimilarity + affine fit."""
    from mappers import apply_affine, fit_affine, weighted_smacof
    from mappers.smacof.weighted import classical_mds

    pts, ids, _ = world
    X = _histories(pts, "visibility", 1500, np.random.default_rng(3))
    D, _ = history_dissimilarity(X)
    S, _, _ = weighted_smacof(D, 1.0 - np.eye(len(D)), classical_mds(D))
    S = apply_affine(S, fit_affine(S[ids], pts[ids]))
    Y = CalibratedSMACOF().fit_transform(X, anchor_ids=ids, anchor_positions=pts[ids])
    assert mean_position_error(Y, pts, exclude=ids) < 0.7 * mean_position_error(S, pts, exclude=ids)


def _planted_fold(pts: np.ndarray) -> np.ndarray:
    """Mirror the right part of the layout onto the left (a fold along x = 0.2)."""
    F = pts.copy()
    right = F[:, 0] > 0.2
    F[right, 0] = 0.4 - F[right, 0]
    return F


@pytest.mark.parametrize("sensor", ["visibility", "bearing"])
def test_detects_and_recovers_planted_fold(world, sensor):
    pts, ids, _ = world
    X = _histories(pts, sensor, 1500, np.random.default_rng(4))
    D, _ = history_dissimilarity(X)
    folded = _planted_fold(pts)
    # the detector: quiet on the truth, fires on the fold
    assert fold_score(pts, D, 10) == 0.0
    assert fold_score(folded, D, 10) > 0.05
    # started from the fold, the mapper sees it, tries its own starts, and keeps an unfolded map
    with warnings.catch_warnings():
        warnings.simplefilter("error", FoldWarning)
        est = CalibratedSMACOF(init=folded).fit(X, anchor_ids=ids, anchor_positions=pts[ids])
    names = [s[0] for s in est.starts_]
    assert names[0] == "init" and est.starts_[0][2] > est.fold_threshold
    assert len(names) > 1
    assert est.fold_score_ <= est.fold_threshold
    assert mean_position_error(est.embedding_, pts, exclude=ids) < 0.08


def test_collapse_scores_as_fold(world):
    pts, _, _ = world
    X = _histories(pts, "visibility", 800, np.random.default_rng(5))
    D, _ = history_dissimilarity(X)
    assert fold_score(np.zeros_like(pts), D, 10) > 1.0


def test_warns_on_structureless_histories(world):
    """Histories with no spatial structure: no map can be trusted, and the mapper says so."""
    pts, ids, _ = world
    X = (np.random.default_rng(6).random((len(pts), 1500)) < 0.1).astype(float)
    with pytest.warns(FoldWarning, match="folded"):
        est = CalibratedSMACOF(n_init=1).fit(X, anchor_ids=ids, anchor_positions=pts[ids])
    assert est.folded_ and est.fold_score_ > est.fold_threshold
    # both deterministic starts looked folded, so the random start was tried too
    assert [s[0] for s in est.starts_] == ["unweighted", "geodesic", "random0"]


def test_without_anchors_embeds_in_own_units(world):
    pts, ids, _ = world
    X = _histories(pts, "bearing", 800, np.random.default_rng(8))
    est = CalibratedSMACOF().fit(X)
    assert est.embedding_.shape == pts.shape and not est.anchored_
    assert np.all(np.isfinite(est.embedding_))


def test_build_map_uses_it_by_default_with_anchors_fixed(world):
    pts, ids, _ = world
    X = _histories(pts, "visibility", 1200, np.random.default_rng(9))
    X[5] = 0.0  # never sensed: unmapped, the rest still mapped
    assert METHODS["CAL-SMA"].uses_anchors
    m = build_map(X, ids, pts[ids])
    assert m.method == "CAL-SMA" and m.unmapped == (5,)
    np.testing.assert_allclose(m.affine, [[1, 0], [0, 1], [0, 0]], atol=1e-9)
    np.testing.assert_allclose(m.positions[ids], pts[ids], atol=1e-9)
    keep = np.setdiff1d(np.arange(len(pts)), [5, *ids])
    assert mean_position_error(m.positions[keep], pts[keep]) < 0.08


def test_precomputed_dissimilarity(world):
    pts, ids, _ = world
    X = _histories(pts, "visibility", 1000, np.random.default_rng(10))
    D, _ = history_dissimilarity(X, "cosine")
    a = CalibratedSMACOF(n_neighbors=12).fit_transform(X, anchor_ids=ids, anchor_positions=pts[ids])
    b = CalibratedSMACOF(n_neighbors=12, dissimilarity="precomputed").fit_transform(
        D, anchor_ids=ids, anchor_positions=pts[ids])
    np.testing.assert_allclose(a, b, atol=1e-9)


def test_duplicate_objects_map_to_one_place_and_the_rest_stay_accurate(world):
    """Identical and near-identical rows (delta 0 and ~1e-16) must not poison the log-linear
    calibration (one floor of log delta for every fit): finite map, duplicates together."""
    pts, ids, _ = world
    X = _histories(pts, "bearing", 1500, np.random.default_rng(12))
    free = [k for k in range(len(pts)) if k not in set(ids.tolist())]
    a, b = free[0], free[1]
    near = X[b].copy()
    near[0] += 1e-13  # delta ~ 1e-15: below the 1e-12 floor
    X2 = np.vstack([X, X[a], near])
    truth = np.vstack([pts, pts[a], pts[b]])
    Y = CalibratedSMACOF().fit_transform(X2, anchor_ids=ids, anchor_positions=pts[ids])
    assert np.all(np.isfinite(Y))
    assert np.hypot(*(Y[-2] - Y[a])) < 0.05 and np.hypot(*(Y[-1] - Y[b])) < 0.05
    assert mean_position_error(Y, truth, exclude=ids) < 0.06


def test_deterministic(world):
    pts, ids, _ = world
    X = _histories(pts, "bearing", 600, np.random.default_rng(11))
    a = CalibratedSMACOF().fit_transform(X, anchor_ids=ids, anchor_positions=pts[ids])
    b = CalibratedSMACOF().fit_transform(X, anchor_ids=ids, anchor_positions=pts[ids])
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"anchor_ids": [0, 1], "anchor_positions": [[0, 0], [1, 0]]}, "at least 3 anchors"),
        ({"anchor_ids": [0, 1, 2], "anchor_positions": [[0, 0], [1, 0], [2, 0]]}, "collinear"),
        ({"anchor_ids": [0, 1, 99], "anchor_positions": [[0, 0], [1, 0], [0, 1]]}, "anchor_ids"),
        ({"anchor_ids": [0, 1, 1], "anchor_positions": [[0, 0], [1, 0], [0, 1]]}, "distinct"),
        ({"anchor_ids": [0, 1, 2], "anchor_positions": [[0, 0], [1, 0]]}, "anchor_positions"),
        ({"anchor_ids": [0, 1, 2]}, "together"),
        ({"anchor_ids": [0.0, 1.0, 2.0], "anchor_positions": [[0, 0], [1, 0], [0, 1]]}, "integer"),
        ({"anchor_ids": [0, 1, 2], "anchor_positions": [[0, 0], [1, 0], [0, np.nan]]}, "NaN"),
    ],
)
def test_rejects_bad_anchors(world, kwargs, match):
    pts, _, _ = world
    X = _histories(pts, "visibility", 300, np.random.default_rng(12))
    with pytest.raises(ValueError, match=match):
        CalibratedSMACOF().fit(X, **kwargs)


def test_rejects_bad_histories(world):
    pts, ids, _ = world
    X = _histories(pts, "visibility", 300, np.random.default_rng(13))
    kw = {"anchor_ids": ids, "anchor_positions": pts[ids]}
    bad = X.copy()
    bad[3, 4] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        CalibratedSMACOF().fit(bad, **kw)
    bad = X.copy()
    bad[2] = 0.0
    with pytest.raises(ValueError, match="empty"):
        CalibratedSMACOF().fit(bad, **kw)
    with pytest.raises(ValueError):
        CalibratedSMACOF().fit(X[0], **kw)  # 1-D
    with pytest.raises(ValueError, match="init"):
        CalibratedSMACOF(init=np.zeros((3, 2))).fit(X, **kw)
    with pytest.raises(ValueError, match="n_neighbors"):
        CalibratedSMACOF(n_neighbors=1).fit(X, **kw)
    with pytest.raises(ValueError, match="dissimilarity"):
        CalibratedSMACOF(dissimilarity="manhattan").fit(X, **kw)
    with pytest.raises(ValueError, match="square"):
        CalibratedSMACOF(dissimilarity="precomputed").fit(X, **kw)
    with pytest.raises(ValueError, match="unknown parameter"):
        build_map(X, ids, pts[ids], method="CAL-SMA", sigma2=0.5)


def test_example_runs(capsys):
    import runpy
    import sys

    path = EXAMPLES / "calibrated_map.py"
    old = sys.argv
    sys.argv = [str(path), "--steps", "800"]
    try:
        runpy.run_path(str(path), run_name="__main__")
    finally:
        sys.argv = old
    rows = [line.split() for line in capsys.readouterr().out.splitlines()[1:]
            if not line.lstrip().startswith("warning:")]  # a map's warnings, printed under its row
    err = {(r[0], r[1]): float(r[2]) for r in rows}
    assert set(err) == {(s, m) for s in ("visibility", "bearing") for m in ("CAL-SMA", "SMA(WGT)")}
    for sensor in ("visibility", "bearing"):
        assert err[(sensor, "CAL-SMA")] < err[(sensor, "SMA(WGT)")]
