"""Tests of the online mapper (mappers.online.mapper and mappers.online.cal_sma, issue 14)."""

from __future__ import annotations

import numpy as np
import pytest

from mappers import OnlineMapper, build_map, mean_position_error
from mappers.calibrated.cal_sma import CalibratedSMACOF, history_dissimilarity
from mappers.online.cal_sma import _OnlineCalSMA, gram_dissimilarity

HALF = 1.25


def _world(seed: int, m: int = 30):
    rng = np.random.default_rng(seed)
    pts = []
    while len(pts) < m:
        p = rng.uniform(-HALF + 0.15, HALF - 0.15, 2)
        if all(np.hypot(*(p - q)) >= 0.25 for q in pts):
            pts.append(p)
    pts = np.array(pts)
    ids = []
    for c in ([-HALF, -HALF], [HALF, -HALF], [HALF, HALF], [-HALF, HALF]):
        d = np.hypot(*(pts - np.array(c)).T)
        d[ids] = np.inf
        ids.append(int(np.argmin(d)))
    return pts, np.array(ids), rng


def _histories(pts, sensor, n, rng):
    """A robot at random poses; visibility within 0.6 m, or the bearing relative to the heading."""
    robot = rng.uniform(-HALF, HALF, (n, 2))
    d = pts[:, None, :] - robot[None, :, :]
    if sensor == "visibility":
        return (np.hypot(d[..., 0], d[..., 1]) < 0.6).astype(float)
    ang = np.arctan2(d[..., 1], d[..., 0]) - rng.uniform(-np.pi, np.pi, n)[None, :]
    X = np.empty((len(pts), 2 * n))
    X[:, 0::2], X[:, 1::2] = np.cos(ang), np.sin(ang)
    return X


@pytest.mark.parametrize("sensor", ["visibility", "bearing"])
def test_gram_dissimilarity_matches_history_dissimilarity(sensor):
    pts, _, rng = _world(1)
    X = _histories(pts, sensor, 300, rng)
    X = X[np.any(X != 0, axis=1)]
    Y = X / np.linalg.norm(X, axis=1, keepdims=True)
    ref, kind = history_dissimilarity(Y)
    assert np.allclose(gram_dissimilarity(X @ X.T, X.shape[1], kind), ref, atol=1e-10)


@pytest.mark.parametrize("sensor", ["visibility", "bearing"])
def test_one_update_is_build_map(sensor):
    pts, ids, rng = _world(2)
    X = _histories(pts, sensor, 400, rng)
    online = OnlineMapper(ids, pts[ids], sensor=sensor).update(X)
    # the online default is build_map's: CAL-SMA, and BEARING-BA from it for bearing
    offline = build_map(X, ids, pts[ids], sensor=sensor)
    assert online.method == offline.method == ("CAL-SMA" if sensor == "visibility" else "BEARING-BA")
    assert online.unmapped == offline.unmapped
    assert np.allclose(online.positions, offline.positions, atol=1e-8, equal_nan=True)


@pytest.mark.parametrize("sensor", ["visibility", "bearing"])
def test_batches_track_build_map(sensor):
    pts, ids, rng = _world(3)
    X = _histories(pts, sensor, 600, rng)
    cols = 1 if sensor == "visibility" else 2
    om = OnlineMapper(ids, pts[ids], sensor=sensor, method="CAL-SMA")
    for s in range(0, 600, 20):
        current = om.update(X[:, s * cols:(s + 20) * cols])
    assert om.n_steps == 600 and om.n_full_fits >= 1
    keep = np.setdiff1d(np.arange(len(pts)), ids)
    offline = build_map(X, ids, pts[ids], "CAL-SMA", sensor=sensor)  # what the online map tracks
    err_on = mean_position_error(current.positions[keep], pts[keep])
    err_off = mean_position_error(offline.positions[keep], pts[keep])
    assert err_on <= 1.25 * err_off + 0.01
    assert np.allclose(current.positions[ids], pts[ids])


@pytest.mark.parametrize("noise_deg", [0.0, 2.0])
def test_online_bearing_tracks_bearing_ba(noise_deg):
    """The online bearing default (BEARING-BA updated incrementally: new poses resected, a joint
    round every few updates, refits with CAL-SMA's) tracks build_map's BEARING-BA of the same
    steps: on perfect bearings both are exact to numerical precision (1e-6 m leaves room for
    LM's stopping rule); with 2 degrees of noise the online map's error stays within 10% of the
    offline one's (the goal's checkpoint margin) at every tenth update."""
    pts, ids, rng = _world(10)
    X = _histories(pts, "bearing", 400, rng)
    if noise_deg:
        ang = np.arctan2(X[:, 1::2], X[:, 0::2]) + np.radians(noise_deg) * rng.standard_normal((30, 400))
        X[:, 0::2], X[:, 1::2] = np.cos(ang), np.sin(ang)
    keep = np.setdiff1d(np.arange(len(pts)), ids)
    om = OnlineMapper(ids, pts[ids], sensor="bearing")
    for s in range(0, 400, 10):
        current = om.update(X[:, 2 * s:2 * s + 20])
        if (s + 10) % 100:
            continue
        offline = build_map(X[:, :2 * s + 20], ids, pts[ids], sensor="bearing")
        assert current.method == offline.method == "BEARING-BA"
        assert np.allclose(current.positions[ids], pts[ids])
        err_on = mean_position_error(current.positions[keep], pts[keep])
        err_off = mean_position_error(offline.positions[keep], pts[keep])
        if noise_deg:
            assert err_on <= 1.1 * err_off
        else:
            assert np.abs(current.positions - offline.positions).max() < 1e-6
    bundle = om._bundle
    assert bundle.n_refits >= 2 and bundle.n_rounds >= 5 and bundle.state is not None


def test_online_bearing_keeps_cal_sma_when_refinement_fails(monkeypatch):
    """BEARING-BA's guard: a refit that is not kept leaves the CAL-SMA map, with the warning."""
    from mappers.viewpoints.bearing import BearingAdjustment

    real = BearingAdjustment._refine

    def refuse(self, obs, n, m, P0, ids):
        real(self, obs, n, m, P0, ids)
        self.refined_ = False
        return P0

    monkeypatch.setattr(BearingAdjustment, "_refine", refuse)
    pts, ids, rng = _world(10)
    X = _histories(pts, "bearing", 200, rng)
    om = OnlineMapper(ids, pts[ids], sensor="bearing")
    first = om.update(X[:, :200])
    cal = OnlineMapper(ids, pts[ids], sensor="bearing", method="CAL-SMA").update(X[:, :200])
    assert first.method == "BEARING-BA" and om._bundle.state is None
    assert np.array_equal(first.positions, cal.positions)
    later = om.update(X[:, 200:400])  # no state: no joint round, the CAL-SMA map again
    assert om._bundle.n_rounds == 0 and np.all(np.isfinite(later.positions))


@pytest.mark.parametrize("sensor", ["visibility", "bearing"])
@pytest.mark.parametrize("params", [{}, {"position_degree": 3, "n_rounds": 5}, {"n_neighbors": 6}])
def test_online_cal_sma_is_cal_sma_to_rounding(sensor, params):
    """The online estimator's lean rounds (one Guttman solve per graph, the calibration summed
    term by term) give CalibratedSMACOF's map to rounding."""
    pts, ids, rng = _world(9)
    X = _histories(pts, sensor, 300, rng)
    kw = dict(params, dissimilarity="cosine" if sensor == "visibility" else "euclidean")
    ref = CalibratedSMACOF(**kw).fit(X, anchor_ids=ids, anchor_positions=pts[ids])
    lean = _OnlineCalSMA(**kw).fit(X, anchor_ids=ids, anchor_positions=pts[ids])
    assert lean.starts_[0][0] == ref.starts_[0][0] and lean.n_iter_ == ref.n_iter_
    assert np.allclose(lean.embedding_, ref.embedding_, atol=1e-9)


@pytest.mark.parametrize("every", [1, 3, 10])
def test_fold_check_every_k_updates_tracks_build_map(every):
    pts, ids, rng = _world(3)
    X = _histories(pts, "visibility", 600, rng)
    om = OnlineMapper(ids, pts[ids], sensor="visibility", fold_check_every=every)
    for s in range(0, 600, 20):
        current = om.update(X[:, s:s + 20])
    keep = np.setdiff1d(np.arange(len(pts)), ids)
    offline = build_map(X, ids, pts[ids], sensor="visibility")
    err_on = mean_position_error(current.positions[keep], pts[keep])
    err_off = mean_position_error(offline.positions[keep], pts[keep])
    assert err_on <= 1.25 * err_off + 0.01


def _fold(om, ids):
    """Plant a fold in the mapper's last map: the objects right of the centre line mirrored
    onto the left half."""
    folded = om._Y.copy()
    right = np.setdiff1d(np.flatnonzero(folded[:, 0] > 0), ids)
    folded[right, 0] *= -1
    om._Y = folded


def test_fold_check_runs_every_k_warm_updates(monkeypatch):
    import mappers.online.mapper

    calls = []
    real = mappers.online.mapper.fold_score
    monkeypatch.setattr(mappers.online.mapper, "fold_score",
                        lambda *a, **k: calls.append(1) or real(*a, **k))
    pts, ids, rng = _world(3)
    X = _histories(pts, "visibility", 600, rng)
    om = OnlineMapper(ids, pts[ids], sensor="visibility", fold_check_every=3)
    om.update(X[:, :20])  # the first map: young until 16 x 20 steps
    om.update(X[:, 20:40])
    assert om._first_map == 20 and len(calls) == 1  # a young map is checked at every update
    om.update(X[:, 40:400])  # a scheduled refit (400 >= 4 x 20), past youth
    assert om._last_full == om._last_scheduled == 400
    fits = om.n_full_fits
    calls.clear()
    checked = []
    for s in range(400, 600, 20):
        om.update(X[:, s:s + 20])
        checked.append(len(calls))
    assert om.n_full_fits == fits and checked == [0, 0, 1, 1, 1, 2, 2, 2, 3, 3]


def _folded(n_steps: int, first: int):
    """``(pts, ids, X, om)``: world 3's visibility history of ``n_steps`` steps, and an online
    mapper checking folds at every update whose map of the first ``first`` steps is folded by
    hand."""
    pts, ids, rng = _world(3)
    X = _histories(pts, "visibility", n_steps, rng)
    om = OnlineMapper(ids, pts[ids], sensor="visibility", fold_check_every=1)
    om.update(X[:, :first])
    _fold(om, ids)
    return pts, ids, X, om


def test_folded_warm_map_is_refitted_from_scratch():
    pts, ids, X, om = _folded(300, 200)
    result = om.update(X[:, 200:300])  # 300 >= 1.5 x 200 steps: refitted at once
    assert om.n_fold_refits == 1 and om.n_full_fits == 2 and om._last_full == 300
    offline = build_map(X, ids, pts[ids], sensor="visibility")
    # the refit is CAL-SMA's fit from its deterministic starts, its rounds capped at 30 Guttman
    # updates (online._FULL_FIT_MAX_ITER; CAL-SMA's own cap is 100): here 1e-5 m from build_map's
    assert np.allclose(result.positions, offline.positions, atol=1e-4)


def test_folded_warm_map_waits_for_growth_before_a_refit():
    _, _, X, om = _folded(400, 300)
    result = om.update(X[:, 300:320])  # 320 < 1.5 x 300 steps: kept, with a note
    assert om.n_fold_refits == 0 and om.n_full_fits == 1
    assert any("looks folded" in w and "450 steps" in w for w in result.warnings)


def test_early_updates_map_nothing_and_say_why():
    pts, ids, _ = _world(4)
    om = OnlineMapper(ids, pts[ids], sensor="visibility")
    result = om.update(np.zeros((len(pts), 5)))
    assert len(result.unmapped) == len(pts) and np.isnan(result.positions).all()
    assert "sensed" in result.warnings[0]


def test_sensor_inferred_once_something_is_sensed():
    pts, ids, rng = _world(5)
    X = _histories(pts, "bearing", 300, rng)
    om = OnlineMapper(ids, pts[ids])
    om.update(np.zeros((len(pts), 4)))  # two steps with nothing sensed: held back
    result = om.update(X)
    assert om.sensor == "bearing" and om.n_steps == 302
    assert not result.unmapped


@pytest.mark.slow
def test_masked_histories_refit_with_their_method():
    pts, ids, rng = _world(6)
    X = _histories(pts, "visibility", 400, rng)
    mask = rng.random(X.shape) < 0.7
    om = OnlineMapper(ids, pts[ids], sensor="visibility", refit_growth=1.5)
    maps = [om.update(X[:, s:s + 50], mask[:, s:s + 50]) for s in range(0, 400, 50)]
    offline = build_map(X, ids, pts[ids], sensor="visibility", mask=mask)
    # build_map's default for masked visibility (VIEW-BA): a random mask is not a view cone, so
    # VIEW-BA keeps its start map and leaves no state to carry on between refits
    assert maps[-1].method == offline.method == "VIEW-BA" and om._view.state is None
    assert om.n_full_fits >= 3 and om._last_full == om.n_steps == 400
    assert np.allclose(maps[-1].positions, offline.positions, equal_nan=True)
    stale = [m for m in maps if any("online map of the first" in w for w in m.warnings)]
    assert stale  # between refits the last map is returned, and says so


@pytest.mark.parametrize("bad, match", [
    (np.zeros(30), "2-D"),
    (np.zeros((30, 0)), "at least one column"),
    (np.zeros((29, 4)), "30 rows"),
    (np.zeros((30, 3)), "groups of 2"),
    (np.full((30, 2), np.nan), "NaN"),
])
def test_bad_column_shapes_refused(bad, match):
    pts, ids, rng = _world(7)
    om = OnlineMapper(ids, pts[ids], sensor="bearing")
    om.update(_histories(pts, "bearing", 10, rng))
    with pytest.raises(ValueError, match=match):
        om.update(bad)


def test_bad_arguments_refused():
    pts, ids, rng = _world(8)
    with pytest.raises(ValueError, match="refit_growth"):
        OnlineMapper(ids, pts[ids], refit_growth=1.0)
    with pytest.raises(ValueError, match="warm_rounds"):
        OnlineMapper(ids, pts[ids], warm_rounds=0)
    for bad in (-1e-4, 1.0, float("nan"), "1e-4", True):
        with pytest.raises(ValueError, match="warm_tol"):
            OnlineMapper(ids, pts[ids], warm_tol=bad)
    for bad in (0, -2, 2.5, True, "5"):
        with pytest.raises(ValueError, match="fold_check_every"):
            OnlineMapper(ids, pts[ids], fold_check_every=bad)
        with pytest.raises(ValueError, match="bundle_every"):
            OnlineMapper(ids, pts[ids], bundle_every=bad)
        with pytest.raises(ValueError, match="bundle_rounds"):
            OnlineMapper(ids, pts[ids], bundle_rounds=bad)
    om = OnlineMapper(ids, pts[ids], sensor="bearing")
    om.update(_histories(pts, "bearing", 20, rng))
    with pytest.raises(ValueError, match="unit"):  # a visibility history fed as bearing
        om.update(np.ones((len(pts), 4)))
    assert om.n_steps == 20
    with pytest.raises(ValueError, match="anchor_positions"):
        OnlineMapper(ids, pts[ids][:2])
    om = OnlineMapper(ids, pts[ids], sensor="visibility")
    X = _histories(pts, "visibility", 50, rng)
    with pytest.raises(ValueError, match="mask"):
        om.update(X, np.ones(X.shape, dtype=int))
    om.update(X)
    with pytest.raises(ValueError, match="first update"):
        om.update(X, rng.random(X.shape) < 0.5)
    with pytest.raises(ValueError, match="unknown parameter"):
        OnlineMapper(ids, pts[ids], sensor="visibility", bogus=1).update(X)
    with pytest.raises(ValueError, match="anchor"):
        OnlineMapper([0, 1, 99], pts[[0, 1, 2]], sensor="visibility").update(X)


# ----------------------------------------------------------------------------- live maps
def test_online_episode_frames_and_gif(tmp_path):
    pytest.importorskip("matplotlib")
    from PIL import Image

    from lfmdr_gym.experiments.live import online_episode, save_gif

    frames, rows, final = online_episode("LFMDR-Bearing-v0", 60, seed=2, every=10,
                                         frame_every=20, size=96)
    assert [t for t, _ in frames] == [20, 40, 60]
    assert frames[0][1].shape == (96, 192, 3) and frames[0][1].dtype == np.uint8
    assert [r["n_steps"] for r in rows] == [10, 20, 30, 40, 50, 60]
    assert rows[-1]["mapped"] == 50 and 0 < rows[-1]["mpe"] < 1.0
    assert final.method == "BEARING-BA"  # the online bearing default, as build_map's
    path = save_gif(frames, rows, tmp_path / "live.gif")
    with Image.open(path) as im:
        assert im.n_frames == 3
    with pytest.raises(ValueError, match="gif"):
        save_gif(frames, rows, tmp_path / "live.mp4")
    with pytest.raises(ValueError, match="every"):
        online_episode("LFMDR-Bearing-v0", 60, every=0)


@pytest.mark.slow
def test_cli_run_online(tmp_path, capsys):
    """Slow (5 s of CPU, most of it the GIF): the default run checks the same command, and
    more, in tests/gym/test_cli.py::test_run_online_writes_every_file_its_help_promises."""
    pytest.importorskip("matplotlib")
    from lfmdr_gym.cli import main

    assert main(["run", "--online", "--env", "LFMDR-Bearing-v0", "--steps", "40", "--every",
                 "20", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "online BEARING-BA" in out and (tmp_path / "live.gif").exists()


def test_an_online_range_history_with_a_negative_value_is_refused_by_name():
    """Every batch of an explicit ``sensor="range"`` is checked as build_map checks a history,
    the later ones too: a range is >= 0."""
    rng = np.random.default_rng(0)
    P = rng.uniform(0, 2, (8, 2))
    C = np.linalg.norm(P[:, None, :] - rng.uniform(0, 2, (1, 40, 2)), axis=2)
    online = OnlineMapper(np.arange(4), P[:4], sensor="range")
    online.update(C[:, :30])
    bad = C[:, 30:].copy()
    bad[2, 3] = -0.5
    with pytest.raises(ValueError, match=">= 0"):
        online.update(bad)
