"""benchmarks/bench_exploration.py: per-run results saved and merged back (policies run apart)."""

from __future__ import annotations

import importlib.util
import sys

import numpy as np
from paths import ROOT


def _bench():
    spec = importlib.util.spec_from_file_location("bench_exploration",
                                                  ROOT / "benchmarks" / "bench_exploration.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_results_round_trip_through_csv_and_merge(tmp_path):
    bench = _bench()
    rng = np.random.default_rng(0)
    a = {"visibility": {"random-walk": rng.random((3, 4))}, "bearing": {"random-walk": rng.random((3, 4))}}
    b = {"visibility": {"rl": rng.random((3, 4))}}
    bench.save_csv(a, tmp_path / "a.csv", seed=1)
    bench.save_csv(b, tmp_path / "b.csv", seed=1)
    merged = bench.load_csv([tmp_path / "a.csv", tmp_path / "b.csv"])
    assert set(merged) == {"visibility", "bearing"}
    np.testing.assert_array_equal(merged["visibility"]["random-walk"], a["visibility"]["random-walk"])
    np.testing.assert_array_equal(merged["visibility"]["rl"], b["visibility"]["rl"])
    np.testing.assert_array_equal(merged["bearing"]["random-walk"], a["bearing"]["random-walk"])


def test_csv_records_the_mapping_method_and_old_files_still_load(tmp_path):
    bench = _bench()
    rows = np.random.default_rng(1).random((2, 4))
    bench.save_csv({"bearing": {"even": rows}}, tmp_path / "a.csv", seed=3,
                   methods={"bearing": "CAL-SMA"})
    bench.save_csv({"visibility": {"even": rows}}, tmp_path / "b.csv", seed=3)
    methods: dict = {}
    bench.load_csv([tmp_path / "a.csv", tmp_path / "b.csv"], methods)
    assert methods == {"bearing": "CAL-SMA"}
    old = tmp_path / "old.csv"  # written before the method column
    old.write_text("sensor,policy,seed,layout,steps,mpe\n"
                   + "".join(f"bearing,rl,3,0,{n},0.5\n" for n in bench.STEPS))
    methods = {}
    assert bench.load_csv([old], methods)["bearing"]["rl"].shape == (1, 4)
    assert methods == {}
    # every shipped CSV (the README's figure and tables) says, per sensor, which method mapped it
    shipped = sorted((ROOT / "docs" / "exploration").glob("*.csv"))
    assert shipped
    for path in shipped:
        methods = {}
        sensors = set(bench.load_csv([path], methods))
        assert set(methods) == sensors, path.name


def test_run_refuses_an_unknown_policy():
    import pytest

    with pytest.raises(ValueError, match="no-such"):
        _bench().run("visibility", 1, 0, ["no-such"])


def test_run_passes_env_keywords_to_every_env(monkeypatch):
    bench = _bench()
    seen = []
    real = bench.make_env

    def spy(env_id, steps, env_kwargs=None):
        seen.append(env_kwargs)
        return real(env_id, steps, env_kwargs)

    monkeypatch.setattr(bench, "make_env", spy)
    monkeypatch.setattr(bench, "STEPS", (30, 60))
    labels = set()
    noisy = bench.run("bearing", 1, 0, ["random-walk"], env_kwargs={"bearing_noise_deg": 2.0},
                      labels=labels)
    exact = bench.run("bearing", 1, 0, ["random-walk"])
    assert seen == [{"bearing_noise_deg": 2.0}, None]
    assert labels == {"BEARING-BA"}  # the bearing default made the maps
    assert noisy["random-walk"].shape == (1, 2)
    # perfect bearings map exactly (BEARING-BA); 2 degrees of noise leave a real error
    assert np.all(exact["random-walk"] < 1e-6)
    assert np.all(noisy["random-walk"] > 1e-3)


def test_a_history_the_method_cannot_map_scores_nan_not_a_crash(monkeypatch):
    import mappers

    bench = _bench()

    def refuse(*args, **kwargs):
        raise mappers.MappingError("the graph of usable pairs falls apart")

    class Hist:
        anchor_ids, anchor_positions = [0, 1, 2], None

        def head(self, n):
            return self

    monkeypatch.setattr(bench.mappers, "build_map", refuse)
    value, label = bench._mpe(Hist(), 10)
    assert np.isnan(value) and label is None


def test_column_means_skip_layouts_without_a_map_and_keep_an_empty_column_nan(recwarn):
    """Through a limited view no layout has a map at 250 steps: that column's mean is NaN, and
    numpy's 'Mean of empty slice' warning is not printed into the benchmark's table."""
    rows = np.array([[np.nan, 0.1, 0.05, 0.04],
                     [np.nan, np.nan, 0.07, 0.02]])
    means = _bench().column_means(rows)
    assert np.isnan(means[0])
    assert np.allclose(means[1:], [0.1, 0.06, 0.03])
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]
