"""The protocol: its plan of units, seeding, resumable runs, parallel and Dask engines, figures."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfmdr_gym.experiments import figures
from lfmdr_gym.experiments.protocol import (
    ProtocolConfig,
    collect_episode,
    default_params,
    grid_params,
    param_label,
    parse_params,
    run_protocol,
)
from lfmdr_gym.experiments.store import SettingsMismatchError, read_results

METHODS = ("LPCA", "SMA(WGT)", "ISOMAP")
SMALL = dict(sensor="visibility", layouts=1, poses=2, steps=200, every=100, methods=METHODS)


def _without_seconds(rows):
    return [{k: v for k, v in r.items() if k != "seconds"} for r in rows]


def _same_rows(a, b):
    """Rows equal up to wall time (NaN scores of failed units compare equal)."""
    a, b = _without_seconds(a), _without_seconds(b)
    assert len(a) == len(b)
    for ra, rb in zip(a, b, strict=True):
        for k in ra:
            if isinstance(ra[k], float) and math.isnan(ra[k]):
                assert math.isnan(rb[k]), (k, ra, rb)
            else:
                assert ra[k] == rb[k], (k, ra, rb)


@pytest.fixture(scope="module")
def clean_run(tmp_path_factory):
    """One uninterrupted small protocol run, shared by the comparisons below."""
    out = tmp_path_factory.mktemp("clean")
    summary = run_protocol(ProtocolConfig(**SMALL), out, progress=False)
    return out, summary, read_results(out / "results.csv")


# ------------------------------------------------------------------ configuration and plan
def test_config_defaults_follow_the_paper():
    vis = ProtocolConfig(sensor="visibility", methods=["lpca"])
    bea = ProtocolConfig(mode="bearing", methods=["lpca"])  # "mode": the older name of sensor
    assert bea.sensor == "bearing"
    assert (vis.layouts, vis.poses, vis.steps, vis.every) == (5, 5, 2000, 500)
    assert bea.every == 200 and bea.checkpoints[-1] == 2000 and len(bea.checkpoints) == 10
    assert vis.methods == ("LPCA",)  # labels matched case-insensitively
    from mappers import METHODS as ALL

    # by default every method made for complete histories of the sensor, in table order (UNFOLD:
    # range only; the masked-history methods, the sparse ones for large M and the fused ones are
    # not in the paper's tables), each with its own defaults (CAL-SMA dense: sparse=False)
    complete = tuple(m for m in ALL if m != "UNFOLD" and not ALL[m].takes_masks
                     and not ALL[m].sparse and not ALL[m].fused)
    assert ProtocolConfig().methods == complete == ProtocolConfig(sensor="bearing").methods
    assert complete[-1] == "CAL-SMA" and len(complete) == 11
    assert ALL["CAL-SMA"].resolved_params()["sparse"] is False
    # an old label that stands for a label with parameters is refused: the protocol runs labels
    with pytest.warns(FutureWarning), pytest.raises(ValueError, match="'CAL-SMA' with sparse=True"):
        ProtocolConfig(methods=["CAL-SMA-SPARSE"])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"layouts": 0}, "layouts must be >= 1, got 0"),
        ({"poses": -1}, "poses must be >= 1"),
        ({"layouts": True}, "layouts must be an integer, got True"),
        ({"every": 2.0}, "every must be an integer"),
        ({"steps": 250, "every": 100}, r"steps \(250\) must be a multiple of every \(100\)"),
        ({"methods": ["LPCA", "NOPE"]}, "unknown method 'NOPE'"),
        ({"sensor": "smell"}, "sensor must be one of"),
        ({"methods": ["UNFOLD"]}, "UNFOLD. maps range histories only: it does not map visibility"),
    ],
)
def test_bad_config_is_a_value_error(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ProtocolConfig(**{**SMALL, **kwargs})


def test_units_cover_the_grid_at_n_and_the_default_everywhere():
    config = ProtocolConfig(**SMALL)
    units = config.units()
    keys = [config.key(u) for u in units]
    assert len(keys) == len(set(keys)), "a unit is planned twice"
    for method in METHODS:
        grid = {param_label(p) for p in grid_params(method)}
        at_n = {u.param for u in units if u.method == method and u.n_steps == 200}
        assert at_n == grid | {param_label(default_params(method))}
        early = {u.param for u in units if u.method == method and u.n_steps == 100}
        assert early == {param_label(default_params(method))}
    per_episode = sum(len(grid_params(m)) + 1 for m in METHODS)  # grid at N, default at N=100
    assert len(units) == 2 * per_episode


def test_param_labels_round_trip():
    assert param_label({}) == "-"
    assert param_label({"sigma2": 0.5, "K": 5}) == "K=5,sigma2=0.5"
    assert parse_params(["K=5,sigma2=0.5"]) == {"K": 5, "sigma2": 0.5}
    assert parse_params(["-"]) == {}
    assert parse_params(["sparse=true", "refine=False"]) == {"sparse": True, "refine": False}
    with pytest.raises(ValueError, match="NAME=VALUE"):
        parse_params(["K5"])


def test_poses_share_their_layout_and_layouts_differ():
    config = ProtocolConfig(sensor="visibility", layouts=2, poses=2, steps=20, every=10,
                            methods=["LPCA"])
    eps = config.episodes()
    hs = {(e.layout, e.pose): collect_episode(e) for e in eps}
    np.testing.assert_array_equal(hs[0, 0].object_positions, hs[0, 1].object_positions)
    np.testing.assert_array_equal(hs[0, 0].anchor_ids, hs[0, 1].anchor_ids)
    assert not np.array_equal(hs[0, 0].robot_poses, hs[0, 1].robot_poses)
    assert not np.array_equal(hs[0, 0].object_positions, hs[1, 0].object_positions)
    again = collect_episode(eps[1])
    np.testing.assert_array_equal(again.matrix, hs[0, 1].matrix)  # deterministic
    assert hs[0, 1].meta["layout"] == 0 and hs[0, 1].meta["pose"] == 1


# ------------------------------------------------------------------ running
@pytest.mark.xdist_group("protocol-clean-run")
def test_small_protocol_writes_every_row_table_and_figures(clean_run):
    out, summary, rows = clean_run
    config = ProtocolConfig(**SMALL)
    assert summary.total_units == len(config.units()) == len(rows) == summary.computed
    assert {(r["layout"], r["pose"]) for r in rows} == {(0, 0), (0, 1)}
    assert all(r["sensor"] == "visibility" for r in rows)
    assert (out / "environment.json").is_file()
    ok = [r for r in rows if not r["error"]]
    assert ok and all(0 <= r["mpe"] < 3 and 0 <= r["moe"] <= 100 for r in ok)
    assert (out / "histories" / "L0_P0.npz").is_file()
    table = (out / "table.md").read_text()
    for method in METHODS:
        assert f"| {method} |" in table
    assert "1.055" in table  # the paper's LPCA figure beside ours
    for name in ("mpe_vs_n.png", "map_lpca.png"):
        png = out / name
        assert png.stat().st_size > 10_000
        from matplotlib.image import imread

        assert imread(png).std() > 0.01  # not a blank canvas
    assert len(list(out.glob("map_*.png"))) == 2  # LPCA and the best method


@pytest.mark.xdist_group("protocol-clean-run")
def test_rerun_resumes_without_recomputing(clean_run, tmp_path):
    out, _, rows = clean_run
    summary = run_protocol(ProtocolConfig(**SMALL), out, progress=False, report=False)
    assert summary.computed == 0 and summary.resumed == len(rows)
    _same_rows(read_results(out / "results.csv"), rows)


@pytest.mark.xdist_group("protocol-clean-run")
def test_other_settings_on_the_same_directory_are_refused(clean_run):
    out, _, _ = clean_run
    with pytest.raises(SettingsMismatchError, match="steps: 200 in the directory, 400 now"):
        run_protocol(ProtocolConfig(**{**SMALL, "steps": 400}), out, progress=False)


@pytest.mark.xdist_group("protocol-clean-run")
def test_partial_journal_is_completed_to_the_same_rows(clean_run, tmp_path):
    """A run stopped after some units resumes to exactly the rows of a clean run."""
    _, _, rows = clean_run
    config = ProtocolConfig(**SMALL)
    from lfmdr_gym.experiments.store import ResultStore

    with ResultStore(tmp_path, config.settings()) as store:
        store.add(rows[::3])  # as if a third of the units had finished before a crash
    summary = run_protocol(config, tmp_path, progress=False, report=False)
    assert summary.resumed == len(rows[::3])
    assert summary.computed == len(rows) - len(rows[::3])
    _same_rows(read_results(tmp_path / "results.csv"), rows)


@pytest.mark.xdist_group("protocol-clean-run")
def test_two_worker_processes_give_the_same_rows(clean_run, tmp_path):
    _, _, rows = clean_run
    run_protocol(ProtocolConfig(**SMALL), tmp_path, jobs=2, progress=False, report=False)
    _same_rows(read_results(tmp_path / "results.csv"), rows)


@pytest.mark.xdist_group("protocol-clean-run")
def test_dask_cluster_gives_the_same_rows(clean_run, tmp_path):
    distributed = pytest.importorskip("distributed")
    _, _, rows = clean_run
    # Thread workers start in a fraction of the time of processes; the tasks still go through
    # the scheduler and joblib's dask backend (process pickling is covered by the loky test).
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=":0") as cluster:
        summary = run_protocol(ProtocolConfig(**SMALL), tmp_path,
                               scheduler=cluster.scheduler_address, progress=False, report=False)
    assert summary.computed == len(rows)
    _same_rows(read_results(tmp_path / "results.csv"), rows)


def test_unreachable_scheduler_is_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match="cannot reach the Dask scheduler"):
        run_protocol(ProtocolConfig(**SMALL), tmp_path, scheduler="tcp://127.0.0.1:1",
                     scheduler_timeout=1.0, progress=False)


def test_bad_jobs_is_refused(tmp_path):
    with pytest.raises(ValueError, match="jobs must be"):
        run_protocol(ProtocolConfig(**SMALL), tmp_path, jobs=0)


# ------------------------------------------------------------------ tables
def _rows(values):
    return [
        {"sensor": "visibility", "layout": 0, "pose": i, "method": m, "param": p, "n_steps": 100,
         "mpe": v, "moe": 1.0, "mpe_nonanchor": v, "unmapped": 0, "seconds": 0.0,
         "error": "" if math.isfinite(v) else "boom"}
        for m, p, vs in values for i, v in enumerate(vs)
    ]


def test_best_param_is_lowest_mean_mpe_and_penalises_failures():
    rows = _rows([("X", "K=4", [0.3, 0.5]), ("X", "K=5", [0.2, 0.4]), ("X", "K=6", [0.1, math.nan])])
    best = figures.best_params(rows, n_steps=100)["X"]
    assert best["param"] == "K=5"  # K=6 is lower but failed on a run
    assert best["mpe_mean"] == pytest.approx(0.3)
    assert best["mpe_std"] == pytest.approx(np.std([0.2, 0.4], ddof=1))
    assert (best["runs"], best["failed"]) == (2, 0)


# in the group of the two-worker test, which runs first: loky's worker processes are reused
# (about 5 s of starting and importing spared)
@pytest.mark.xdist_group("protocol-clean-run")
def test_a_method_registered_in_this_process_reaches_the_worker_processes(tmp_path):
    """register_method in the user's script (the registry is per process): the protocol ships
    the spec to its workers, so jobs=2 gives the rows of jobs=1, not 'unknown method' errors."""
    from mappers import MethodSpec, WeightedSMACOF, register_method
    from mappers.catalog import _METHODS

    def knn_smacof(*, n_neighbors: int = 6):  # a local function: workers cannot import it
        return WeightedSMACOF(n_neighbors=n_neighbors)

    spec = MethodSpec("TEST-KNN", knn_smacof, defaults={}, grid={"n_neighbors": [5, 7]})
    register_method(spec)
    try:
        cfg = dict(SMALL, methods=("TEST-KNN",))
        one = run_protocol(ProtocolConfig(**cfg), tmp_path / "one", jobs=1, progress=False,
                           report=False)
        two = run_protocol(ProtocolConfig(**cfg), tmp_path / "two", jobs=2, progress=False,
                           report=False)
        assert one.failed == two.failed == 0
        _same_rows(read_results(one.out / "results.csv"), read_results(two.out / "results.csv"))
    finally:
        _METHODS.pop(spec.label)


def test_range_mode_runs_the_same_protocol_with_unfold_and_a_table_of_our_own(tmp_path):
    cfg = ProtocolConfig(sensor="range", layouts=1, poses=2, steps=200, every=100,
                         methods=("SMA(WGT)", "UNFOLD"))
    assert cfg.env_id == "LFMDR-Range-v0"
    summary = run_protocol(cfg, tmp_path, progress=False)
    rows = read_results(tmp_path / "results.csv")
    assert summary.failed == 0 and len(rows) == summary.total_units
    unfold = [r for r in rows if r["method"] == "UNFOLD"]
    assert unfold and max(r["mpe"] for r in unfold) < 1e-5  # exact ranges, exact map
    assert min(r["mpe"] for r in rows if r["method"] == "SMA(WGT)") > 0.01
    table = (tmp_path / "table.md").read_text()
    assert "paper MPE" not in table and "no range sensor" in table
    assert (tmp_path / "map_unfold.png").is_file()
