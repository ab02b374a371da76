"""The online map of masked visibility histories: VIEW-BA carried on between its refits
(mappers/online/view_cone.py, mappers/online/mapper.py)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from map_errors import map_error
from paths import ROOT

import lfmdr_gym  # noqa: F401 - registers the envs
import mappers.online.mapper as online
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from lfmdr_gym.histories.recording import collect
from mappers import OnlineMapper, build_map

pytestmark = pytest.mark.usefixtures("one_blas_thread")


@pytest.fixture(scope="module")
def walk():
    """A random walk of 700 steps through a 90-degree view: (history, X, mask)."""
    env = gym.make("LFMDR-Visibility-v0", max_episode_steps=700, fov_deg=90)
    h = collect(env, RandomWalkPolicy.for_env(env), 700, seed=5)
    return h, np.asarray(h.matrix, dtype=float), np.asarray(h.mask, dtype=bool)


def test_one_update_is_build_maps_view_adjustment(walk):
    h, X, mask = walk
    om = OnlineMapper(h.anchor_ids, h.anchor_positions, sensor="visibility")
    m = om.update(X, mask)
    offline = build_map(h, h.anchor_ids, h.anchor_positions)
    assert m.method == offline.method == "VIEW-BA"
    assert om.incremental and om.refit_growth == 1.25  # VIEW-BA's own schedule
    assert np.allclose(m.positions, offline.positions, atol=1e-9, equal_nan=True)
    assert OnlineMapper(h.anchor_ids, h.anchor_positions, refit_growth=3).refit_growth == 3.0


def test_new_steps_move_the_map_between_refits(walk):
    h, X, mask = walk
    # refits every 2x (the default is 1.25x): a long stretch of warm updates between two
    om = OnlineMapper(h.anchor_ids, h.anchor_positions, sensor="visibility", refit_growth=2)
    maps, fits, viewpoints = [], [], []
    for s in range(0, 700, 10):
        maps.append(om.update(X[:, s:s + 10], mask[:, s:s + 10]))
        fits.append(om.n_full_fits)
        state = om._view.state
        viewpoints.append(0 if state is None else len(state["C"]))
    first = fits.index(1)  # the first map (DROPOUT-BLEND, VIEW-BA's start, fails before)
    assert 200 <= 10 * (first + 1) <= 400 and fits[-1] == 1  # the next one at 2x its steps
    warm = [i for i in range(first + 1, len(fits)) if fits[i] == fits[i - 1]]
    assert len(warm) >= 25
    # between refits every new step that observed a mapped object gets a viewpoint ...
    assert all(viewpoints[i] > viewpoints[i - 1] for i in warm)
    # ... and the objects move (joint rounds, and a refinement at 1.25x the steps)
    moved = [i for i in warm if not np.array_equal(maps[i].positions, maps[i - 1].positions)]
    assert len(moved) >= len(warm) // 6
    assert not any("online map of the first" in w for m in maps[first:] for w in m.warnings)
    offline = build_map(h.head(690), h.anchor_ids, h.anchor_positions)
    assert map_error(maps[-2], h) < 1.5 * map_error(offline, h) and map_error(maps[-2], h) < 0.15


def test_an_object_seen_for_the_first_time_is_refitted_into_the_map(walk):
    h, X, mask = walk
    j = next(i for i in range(h.n_objects) if i not in h.anchor_ids)
    X = X.copy()
    X[j, :550] = 0.0  # object j not visible before step 550 (observed, but hidden)
    om = OnlineMapper(h.anchor_ids, h.anchor_positions, sensor="visibility")
    before = None
    for s in range(0, 600, 10):
        m = om.update(X[:, s:s + 10], mask[:, s:s + 10])
        if s + 10 == 550:
            before = (om.n_full_fits, m.unmapped)
    assert j in before[1]
    first_seen = int(np.flatnonzero(X[j] != 0)[0])
    assert first_seen >= 550 and om.n_full_fits == before[0] + 1
    assert j not in m.unmapped and np.isfinite(m.positions[j]).all()
    assert om._last_scheduled < om._last_full  # the schedule is left where it was


def test_a_first_map_that_fails_is_tried_again_after_growth(walk, monkeypatch):
    h, X, mask = walk
    calls = []
    real = online._fit_map

    def counted(*args, **kwargs):
        calls.append(args[0].shape[1])
        return real(*args, **kwargs)

    monkeypatch.setattr(online, "_fit_map", counted)
    om = OnlineMapper(h.anchor_ids, h.anchor_positions, sensor="visibility")
    notes = [om.update(X[:, s:s + 2], mask[:, s:s + 2]).warnings for s in range(0, 200, 2)]
    assert om.map is not None and not np.isfinite(om.map.positions).any()  # too few steps
    assert 3 <= len(calls) < 40  # not at each of the 100 updates
    assert all(b >= 1.1 * a for a, b in zip(calls, calls[1:], strict=False))
    assert any("tried again at" in w for ws in notes for w in ws)


def test_the_online_example_maps_a_limited_view_and_refuses_a_bad_keyword():
    import os
    import subprocess
    import sys

    root = ROOT
    script = [sys.executable, str(root / "examples" / "online_map.py")]
    env = {**os.environ, "PYTHONPATH": str(root)}
    # 400 steps: its first map, 46 of 46 at an MPE of 0.08 m (the maps that follow:
    # test_new_steps_move_the_map_between_refits)
    out = subprocess.run([*script, "--env-kw", "fov_deg=90", "--steps", "400"], cwd=root, env=env,
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    lines = [line for line in out.stdout.splitlines() if not line.startswith("warning:")]
    assert "no map yet" in lines[0]  # a 90-degree view's first 100 steps place nothing
    assert lines[-1].startswith("  400 steps: 46 of 46") and lines[-1].endswith("(VIEW-BA)")
    assert float(lines[-1].split("MPE ")[1].split(" m")[0]) < 0.2
    bad = subprocess.run([*script, "--env-kw", "fov=90"], cwd=root, env=env,
                         capture_output=True, text=True, timeout=600)
    assert bad.returncode == 2 and "'fov'" in bad.stderr
