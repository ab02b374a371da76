"""MRCLAM: the loader (lfmdr_gym/datasets/mrclam.py) and mapping a run
(lfmdr_gym/experiments/mrclam.py).

Synthetic runs are written by the tests into tmp_path in the MRCLAM layout (4-line ``#``
header, CRLF, tabs); the real runs are used when ``<repo>/../shared/data/mrclam`` exists.
"""

from __future__ import annotations

import csv
import warnings
from pathlib import Path

import numpy as np
import pytest
from paths import EXAMPLES, SHARED_DATA

from lfmdr_gym.datasets import (
    MRCLAMDataWarning,
    MRCLAMReport,
    check_groundtruth,
    corner_anchors,
    load_mrclam,
    read_run,
)
from lfmdr_gym.experiments.mrclam import map_mrclam_run

DATA = SHARED_DATA / "mrclam"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason=f"MRCLAM data not found at {DATA}")

HEADER = (
    "# UTIAS Multi-Robot Cooperative Localization and Mapping Dataset\r\n"
    "# produced by a test\r\n"
    "# {what} Data Fomat:\r\n"
    "# {cols}\r\n"
)


def _write(path: Path, what: str, cols: str, rows) -> None:
    text = HEADER.format(what=what, cols=cols)
    for row in rows:
        text += " \t".join(f"{v}" for v in row) + " \r\n"
    path.write_bytes(text.encode())


def _barcode(subject: int) -> int:
    return 100 + 3 * subject  # deliberately not the subject number


def _write_run(
    root: Path,
    gt: dict[int, tuple[float, float]],
    measurements: dict[int, list[tuple[float, int, float, float]]],
    extra_barcodes: dict[int, int] | None = None,
) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    bc = {s: _barcode(s) for s in [1, 2, 3, 4, 5, *gt]}
    bc.update(extra_barcodes or {})
    _write(root / "Barcodes.dat", "Barcode", "Subject #    Barcode #", sorted(bc.items()))
    _write(root / "Landmark_Groundtruth.dat", "Landmark Groundtruth",
           "Subject #    x [m]    y [m]    x std-dev [m]    y std-dev [m]",
           [(s, f"{x:.8f}", f"{y:.8f}", 0.0001, 0.0001) for s, (x, y) in sorted(gt.items())])
    for r, rows in measurements.items():
        _write(root / f"Robot{r}_Measurement.dat", "Measurement",
               "Time [s]    Subject #    range [m]    bearing [rad]",
               [(f"{t:.3f}", b, f"{rg:.3f}", f"{br:.3f}") for t, b, rg, br in rows])
    return root


def _simulate_rows(truth: dict[int, tuple[float, float]], robots=(1, 2, 3), n_images=1500,
                   fov=0.6, max_range=7.0, seed=0):
    """Measurement rows of robots on random walks (0.08 m and up to 0.3 rad per image,
    4 images/s, reflected at the landmarks' bounding box + 1 m) seeing ``truth``."""
    rng = np.random.default_rng(seed)
    subj = np.array(sorted(truth))
    P = np.array([truth[s] for s in subj])
    lo, hi = P.min(0) - 1, P.max(0) + 1
    out = {}
    for r in robots:
        rows = []
        xy = rng.uniform(lo, hi)
        th = rng.uniform(-np.pi, np.pi)
        for k in range(n_images):
            th += rng.uniform(-0.3, 0.3)
            xy = xy + 0.08 * np.array([np.cos(th), np.sin(th)])
            if np.any(xy < lo) or np.any(xy > hi):
                xy = np.clip(xy, lo, hi)
                th += np.pi
            d = P - xy
            rg = np.hypot(d[:, 0], d[:, 1])
            br = np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - th)))
            t = 1.0e9 + 0.25 * k
            for i in np.flatnonzero((np.abs(br) < fov) & (rg < max_range) & (rg > 0.5)):
                rows.append((t, _barcode(int(subj[i])), rg[i] + rng.normal(0, 0.01),
                             br[i] + rng.normal(0, 0.003)))
        out[r] = rows
    return out


def _tiny_run(tmp_path: Path) -> Path:
    gt = {s: (float(s), float(s % 3)) for s in range(6, 12)}
    b = _barcode
    r1 = [
        (1000.00, b(6), 2.0, 0.1), (1000.00, b(7), 3.0, -0.2),   # one image, bin 0
        (1000.25, b(6), 2.0, 0.1),                               # exact repeat of 6 -> dropped
        (1000.50, b(2), 1.5, 0.0),                               # robot 2 sighted -> dropped
        (1001.20, 999, 2.2, 0.0),                                # unknown barcode -> dropped
        (1001.50, b(8), 4.0, 0.3), (1001.70, b(8), 5.0, 0.5),    # bin 1: median 4.5, mean 0.4
    ]
    r2 = [(1000.10, b(6), 1.0, 0.0), (1002.30, b(9), 2.5, 0.2)]
    return _write_run(tmp_path / "TinyRun", gt, {1: r1, 2: r2})


def test_synthetic_files_have_crlf_and_header(tmp_path):
    run = _tiny_run(tmp_path)
    raw = (run / "Robot1_Measurement.dat").read_bytes()
    assert raw.count(b"\r\n") == 4 + 7 and raw.startswith(b"#")


def test_loader_filters_and_counts(tmp_path):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        h = load_mrclam(_tiny_run(tmp_path), "visibility", robots=(1, 2), bin_width=1.0,
                        anchors=(6, 8, 9))
    rep = MRCLAMReport.from_meta(h.meta)
    said = [str(w.message) for w in caught if w.category is MRCLAMDataWarning]
    assert any("[10, 11] were never observed" in m for m in said)
    assert any("falls apart" in m for m in said)
    assert h.meta["warnings"] == said
    from lfmdr_gym.histories.history import History

    back = History.load(h.save(tmp_path / "tiny.npz"))
    assert back.meta == h.meta and np.array_equal(back.matrix, h.matrix)
    assert (rep.rows, rep.robot_rows, rep.unknown_barcode_rows, rep.repeat_rows) == (9, 1, 1, 1)
    assert rep.landmark_rows == 6 and rep.per_robot_landmark_rows == {1: 4, 2: 2}
    for key in ("robot_rows", "unknown_barcode_rows", "repeat_rows", "landmark_rows"):
        assert h.meta[key] == getattr(rep, key)
    assert h.meta["subjects"] == [6, 7, 8, 9, 10, 11]
    assert h.meta["bins_per_robot"] == {"1": 2, "2": 2} and h.n_steps == 4
    # barcodes mapped to subjects; per-robot bins concatenated: R1 bin0, R1 bin1, R2 bin0, R2 bin2
    expected = np.array([[1, 0, 1, 0], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 1],
                         [0, 0, 0, 0], [0, 0, 0, 0]], float)
    assert np.array_equal(h.matrix, expected)
    assert np.array_equal(h.mask, expected > 0)  # a camera log knows what was seen, not what was not
    assert h.timeline.tolist() == [[0, 0], [0, 1], [1, 0], [1, 2]]  # (robot, bin) of each step
    assert h.anchor_ids.tolist() == [0, 2, 3]
    assert np.allclose(h.anchor_positions, [[6, 0], [8, 2], [9, 0]])
    assert np.allclose(h.object_positions[1], [7.0, 1.0])


def test_loader_bearing_and_range_with_masks(tmp_path):
    run = _tiny_run(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MRCLAMDataWarning)
        hb = load_mrclam(run, "bearing", robots=(1, 2), bin_width=1.0, anchors=(6, 8, 9))
        hr = load_mrclam(run, "range", robots=(1, 2), bin_width=1.0, anchors=(6, 8, 9))
    assert hb.matrix.shape == (6, 8) and hb.mask.shape == (6, 8)
    assert hb.mask[2].tolist() == [False, False, True, True, False, False, False, False]
    assert np.allclose(hb.matrix[2, 2:4], [np.cos(0.4), np.sin(0.4)])
    assert np.allclose(hb.matrix[1, 0:2], [np.cos(-0.2), np.sin(-0.2)])
    assert not hb.mask[4].any() and np.all(hb.matrix[~hb.mask] == 0)
    assert hr.matrix[2, 1] == pytest.approx(4.5) and hr.matrix[0, 2] == pytest.approx(1.0)
    assert hr.mask.sum() == 5 and np.all(hr.matrix[~hr.mask] == 0)


def test_loader_returns_a_history_and_fuses_range_and_bearing(tmp_path):
    from lfmdr_gym.histories.history import History

    run = _tiny_run(tmp_path)
    kw = {"robots": (1, 2), "bin_width": 1.0, "anchors": (6, 8, 9)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MRCLAMDataWarning)
        single = {s: load_mrclam(run, s, **kw) for s in ("range", "bearing")}
        fused = load_mrclam(run, "range-bearing", **kw)  # as lfmdr mrclam --sensor range-bearing
    assert all(isinstance(h, History) for h in (*single.values(), fused))
    assert fused.sensor == "range-bearing" and fused.fused and fused.meta["sensor"] == "range-bearing"
    for s, h in single.items():
        part = fused.parts[s]
        assert np.array_equal(part.matrix, h.matrix) and np.array_equal(part.mask, h.mask)
        assert np.array_equal(fused.timeline, h.timeline)
    assert {k: v for k, v in fused.meta.items() if k != "sensor"} == {
        k: v for k, v in single["range"].meta.items() if k != "sensor"}
    report = MRCLAMReport.from_meta(fused.meta)
    assert report.as_dict() == {k: fused.meta[k] for k in report.as_dict()}
    assert report.per_robot_landmark_rows == {1: 4, 2: 2}
    with pytest.raises(ValueError, match="bin width"):  # no default width for this set
        load_mrclam(run, "visibility-bearing", robots=(1, 2))


def test_map_warnings_name_landmark_subjects_not_rows(tmp_path):
    from lfmdr_gym.experiments.object_names import name_rows as _in_subjects

    subjects = np.arange(6, 21)
    every = np.arange(15)
    note = ("LOC-SMA: RigidityWarning: the measured pairs fall apart into 2 groups "
            "[[0, 1, 2], [3, 14]] (a clustered layout?); 2 pair distance(s) [(3, 14), (4, 14)] "
            "dropped; objects [5] not placed; sizes [8, 7] of 2 components")
    said = _in_subjects(note, subjects, every)
    assert "groups of landmarks [[6, 7, 8], [9, 20]]" in said
    assert "pair distance(s) between landmarks [(9, 20), (10, 20)]" in said
    assert "landmarks [11] not placed" in said
    assert "sizes [8, 7] of 2 components" in said and "fall apart into 2 groups" in said
    # a method's rows are those of the landmarks with data (here subject 6 had none)
    assert "landmarks [8]" in _in_subjects("objects [1] x", subjects, every[1:])
    # on a clustered run, the fused map's warning names the two groups of subjects
    rng = np.random.default_rng(4)
    truth = {}
    for k, s in enumerate(range(6, 18)):
        cx, cy = (0.0, 0.0) if k < 6 else (0.0, 12.0)
        truth[s] = (cx + rng.uniform(-1, 1), cy + rng.uniform(-1, 1))
    run = _write_run(tmp_path / "Clustered", truth,
                     _simulate_rows(truth, n_images=1200, max_range=4.0, seed=5))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MRCLAMDataWarning)
        res = map_mrclam_run(run, "range-bearing", robots=(1, 2, 3))
    groups = "groups of landmarks [[6, 7, 8, 9, 10, 11], [12, 13, 14, 15, 16, 17]]"
    assert any("LOC-SMA" in w and groups in w for w in res.warnings), res.warnings


def test_map_png_keeps_its_title_and_every_warning_inside_the_figure(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from lfmdr_gym.experiments import figures

    drawn = {}
    real = figures.atomic_savefig

    def keep(fig, path, **kwargs):
        drawn["fig"] = fig
        return real(fig, path, **kwargs)

    monkeypatch.setattr(figures, "atomic_savefig", keep)
    rng = np.random.default_rng(4)
    truth = {s: ((0.0, 0.0) if k < 6 else (0.0, 12.0)) + rng.uniform(-1, 1, 2)
             for k, s in enumerate(range(6, 18))}
    run = _write_run(tmp_path / "Clustered", truth,
                     _simulate_rows(truth, n_images=1200, max_range=4.0, seed=5))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MRCLAMDataWarning)
        res = map_mrclam_run(run, "visibility", robots=(1, 2, 3), out=tmp_path / "o")
    assert len(res.warnings) >= 2 and res.png_path.is_file()
    fig = drawn["fig"]
    renderer = fig.canvas.get_renderer()
    box = fig.bbox
    title = fig.axes[0].title
    notes = [t for t in fig.findobj(lambda a: hasattr(a, "get_text"))
             if str(t.get_text()).startswith("warning: ")]
    assert title.get_text().startswith("Clustered visibility") and len(notes) == 1
    shown = " ".join(notes[0].get_text().replace("warning: ", "").split())
    for w in res.warnings:  # every warning in full, not its first 80 characters
        assert " ".join(w.split()) in shown, w
    for t in (title, notes[0]):
        ext = t.get_window_extent(renderer)
        assert box.x0 - 1 <= ext.x0 and ext.x1 <= box.x1 + 1, t.get_text()[:60]
        assert box.y0 - 1 <= ext.y0 and ext.y1 <= box.y1 + 1, t.get_text()[:60]
    assert not fig.axes[0].get_window_extent(renderer).overlaps(notes[0].get_window_extent(renderer))


def test_loader_robot_subset_and_bad_arguments(tmp_path):
    run = _tiny_run(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MRCLAMDataWarning)
        h = load_mrclam(run, "visibility", robots=(2,), bin_width=1.0, anchors=(6, 8, 9))
    assert MRCLAMReport.from_meta(h.meta).rows == 2 and h.n_steps == 2 and h.meta["robots"] == [2]
    with pytest.raises(ValueError, match="sensor must be one of"):
        load_mrclam(run, "sonar")
    with pytest.raises(ValueError, match="bin_width"):
        load_mrclam(run, "visibility", robots=(1, 2), bin_width=0)
    with pytest.raises(ValueError, match="Robot3_Measurement"):
        load_mrclam(run, "visibility", robots=(1, 3))
    with pytest.raises(ValueError, match="anchors"):
        load_mrclam(run, "visibility", robots=(1, 2), anchors=(6, 8, 42))
    with pytest.raises(ValueError, match="groundtruth_fixes"):
        read_run(run, (1,), groundtruth_fixes="maybe")
    with pytest.raises(FileNotFoundError):
        read_run(tmp_path / "nowhere")


def _ds1_like_truth():
    rng = np.random.default_rng(11)
    truth = {s: tuple(rng.uniform([0, -5.5], [5.7, 5.5])) for s in range(6, 21)}
    # the file lists DS1's values for 11 and 17; the *true* positions are swapped
    truth[17] = (3.15071999, 2.38294871)
    truth[11] = (0.03596156, -2.84396626)
    file_gt = dict(truth)
    file_gt[11], file_gt[17] = truth[17], truth[11]
    return truth, file_gt


def test_known_ds1_swap_is_an_option_with_a_warning(tmp_path):
    truth, file_gt = _ds1_like_truth()
    run = _write_run(tmp_path / "renamed_run", file_gt, _simulate_rows(truth, seed=1))
    with pytest.warns(MRCLAMDataWarning, match="swapping them back"):
        fixed = read_run(run, (1, 2, 3))
    assert np.allclose(fixed.truth[fixed.subjects.tolist().index(11)], truth[11])
    assert "11 and 17" in fixed.report.groundtruth_fix
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        raw = read_run(run, (1, 2, 3), groundtruth_fixes="none")
    text = " ".join(str(w.message) for w in caught)
    assert "known to be swapped" in text and "disagrees" in text
    assert np.allclose(raw.truth[raw.subjects.tolist().index(11)], file_gt[11])
    assert check_groundtruth(raw)[0] == [(11, 17)]


def test_undocumented_swap_is_detected(tmp_path):
    rng = np.random.default_rng(3)
    truth = {s: tuple(rng.uniform([0, 0], [5, 10])) for s in range(6, 18)}
    file_gt = dict(truth)
    file_gt[8], file_gt[14] = truth[14], truth[8]
    run = _write_run(tmp_path / "Run", file_gt, _simulate_rows(truth, seed=2))
    with pytest.warns(MRCLAMDataWarning, match="disagrees"):
        r = read_run(run, (1, 2, 3))
    assert r.report.groundtruth_fix == "none"
    with pytest.warns(MRCLAMDataWarning, match="detect"):
        r = read_run(run, (1, 2, 3), groundtruth_fixes="detect")
    assert np.allclose(r.truth[r.subjects.tolist().index(8)], truth[8])
    # a consistent file raises no ground-truth warning
    ok = _write_run(tmp_path / "Ok", truth, _simulate_rows(truth, seed=2))
    with warnings.catch_warnings():
        warnings.simplefilter("error", MRCLAMDataWarning)
        read_run(ok, (1, 2, 3))


def test_clustered_layout_warns_and_map_says_so(tmp_path):
    rng = np.random.default_rng(4)
    truth = {}
    for k, s in enumerate(range(6, 18)):
        cx, cy = (0.0, 0.0) if k < 6 else (0.0, 12.0)
        truth[s] = (cx + rng.uniform(-1, 1), cy + rng.uniform(-1, 1))
    rows = _simulate_rows(truth, n_images=1200, max_range=4.0, seed=5)
    run = _write_run(tmp_path / "Clustered", truth, rows)
    with pytest.warns(MRCLAMDataWarning, match="falls apart"):
        h = load_mrclam(run, "visibility", robots=(1, 2, 3))
    assert len(h.meta["co_observation_groups"]) == 2
    # anchors 3 + 1: the group held by one anchor is unmapped (empty in map.csv), not guessed;
    # the map's warnings say that the layout falls apart
    anchors = [6, 7, 8, 12]
    with pytest.warns(MRCLAMDataWarning, match="unmapped"):
        res = map_mrclam_run(run, "visibility", robots=(1, 2, 3), anchors=anchors, out=tmp_path / "o",
                             plot=False)
    assert any("falls apart" in w for w in res.warnings)
    lost = [s for s in range(13, 18)]
    assert np.isnan(res.positions[np.isin(res.subjects, lost)]).all()
    assert np.isfinite(res.positions[~np.isin(res.subjects, lost)]).all()
    assert np.isfinite(res.mpe)
    rows = (tmp_path / "o" / "map.csv").read_text().splitlines()[1:]
    assert {int(r.split(",")[0]) for r in rows if r.endswith(",,")} == set(lost)


def test_map_synthetic_run_writes_csv_and_png(tmp_path):
    rng = np.random.default_rng(6)
    truth = {s: tuple(rng.uniform([0, 0], [5, 10])) for s in range(6, 21)}
    run = _write_run(tmp_path / "Synth", truth, _simulate_rows(truth, n_images=2000, seed=7))
    res = map_mrclam_run(run, "range", robots=(1, 2, 3), out=tmp_path / "out")
    P = np.array([truth[s] for s in sorted(truth)])
    assert res.method == "RANGE-QUANTILE" and res.mpe < 0.2 and res.mpe < res.centroid_mpe / 5
    assert res.anchor_subjects == tuple(int(s) for s in np.array(sorted(truth))[corner_anchors(P)])
    with open(res.csv_path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["subject"] for r in rows] == [str(s) for s in sorted(truth)]
    assert set(rows[0]) == {"subject", "x", "y"}
    est = np.array([[float(r["x"]), float(r["y"])] for r in rows])
    assert np.allclose(est, res.positions, atol=1e-5)
    anchors = np.isin(res.subjects, res.anchor_subjects)
    assert np.allclose(est[anchors], P[anchors], atol=1e-5)
    assert res.png_path.is_file() and res.png_path.read_bytes()[:4] == b"\x89PNG"
    vis = map_mrclam_run(run, "visibility", robots=(1, 2, 3), anchors=(6, 7, 8, 9))
    assert vis.anchor_subjects == (6, 7, 8, 9) and vis.mpe < vis.centroid_mpe
    assert vis.method == "COVIS-ENSEMBLE" and vis.params["min_co"] == [3, 5]
    with pytest.raises(ValueError, match="method"):
        map_mrclam_run(run, "range", robots=(1, 2, 3), method="LLE?")


# ------------------------------------------------------------------------------- real data
@needs_data
def test_real_counts_match_the_dataset_readme():
    with pytest.warns(MRCLAMDataWarning, match="11 and 17"):
        r = read_run(DATA / "MRCLAM_Dataset1")
    assert (r.report.robot_rows, r.report.unknown_barcode_rows) == (6453, 3)
    assert r.report.landmark_rows + r.report.repeat_rows == 27491
    assert 0.03 < r.report.repeat_rows / 27491 < 0.05
    r2 = read_run(DATA / "MRCLAM_Dataset2")
    assert (r2.report.robot_rows, r2.report.unknown_barcode_rows) == (9138, 11)
    assert r2.report.groundtruth_fix == "none" and not r2.report.warnings


@needs_data
def test_real_run_end_to_end(tmp_path):
    res = map_mrclam_run(DATA / "MRCLAM_Dataset2", "range", out=tmp_path)
    assert res.mpe < 0.5 and res.centroid_mpe > 2.5
    assert (tmp_path / "map.csv").is_file() and (tmp_path / "map.png").is_file()
    vis = map_mrclam_run(DATA / "MRCLAM_Dataset3", "visibility")
    assert vis.mpe < 1.2


@needs_data
def test_real_clustered_run_warns():
    with pytest.warns(MRCLAMDataWarning, match="falls apart"):
        res = map_mrclam_run(DATA / "MRCLAM_Dataset6", "visibility")
    assert any("falls apart" in w for w in res.warnings)


def test_covis_ensemble_is_the_visibility_default_and_checks_its_arguments(tmp_path):
    rng = np.random.default_rng(8)
    truth = {s: tuple(rng.uniform([0, 0], [5, 10])) for s in range(6, 18)}
    run = _write_run(tmp_path / "Ens", truth, _simulate_rows(truth, n_images=1200, seed=9))
    small = {"bin_widths": (1.0, 2.0), "min_co": (3,)}
    ens = map_mrclam_run(run, "bearing", robots=(1, 2, 3), plot=False, **small)
    assert ens.method == "COVIS-ENSEMBLE"
    assert ens.params == {"bin_widths": [1.0, 2.0], "min_co": [3], "member": "covis-power",
                          "power": 0.5, "combine": "mean", "max_spread": None}
    # each member alone: the ensemble of one bin width (covis-power at that width)
    singles = [map_mrclam_run(run, "bearing", robots=(1, 2, 3), method="COVIS-ENSEMBLE",
                              bin_widths=(w,), min_co=3) for w in (1.0, 2.0)]
    assert all(s.history_meta["bin_width"] == w for s, w in zip(singles, (1.0, 2.0), strict=True))
    assert np.allclose(ens.positions, np.mean([s.positions for s in singles], axis=0))
    assert ens.mpe < ens.centroid_mpe / 2
    with pytest.raises(ValueError, match="bin_width"):
        map_mrclam_run(run, "visibility", robots=(1, 2, 3), method="COVIS-ENSEMBLE", bin_width=2.0)
    one = map_mrclam_run(run, "visibility", robots=(1, 2, 3), bin_width=2.0)  # one width asked
    assert one.method == "COVIS-ENSEMBLE" and one.history_meta["bin_width"] == 2.0
    assert one.params["bin_widths"] == [2.0] and one.params["min_co"] == [3]
    same = map_mrclam_run(run, "visibility", robots=(1, 2, 3), method="COVIS-ENSEMBLE",
                          bin_widths=(2.0,), min_co=3)
    np.testing.assert_array_equal(one.positions, same.positions)
    with pytest.raises(ValueError, match="unknown parameter"):
        map_mrclam_run(run, "visibility", robots=(1, 2, 3), method="COVIS-ENSEMBLE", quantile=0.9)
    with pytest.raises(ValueError, match="member"):
        map_mrclam_run(run, "visibility", robots=(1, 2, 3), member="covis-range")
    with pytest.raises(ValueError, match="power"):
        map_mrclam_run(run, "visibility", robots=(1, 2, 3), member="covis-nonmetric", power=0.5)
    # any registered method that maps the run's masked histories; an old label: its new one
    with pytest.warns(FutureWarning, match="'covis-ensemble' is now spelled 'COVIS-ENSEMBLE'"):
        old = map_mrclam_run(run, "bearing", robots=(1, 2, 3), method="covis-ensemble", **small)
    np.testing.assert_array_equal(old.positions, ens.positions)
    with pytest.raises(ValueError, match=r"'covis-power' is no longer a label.*COVIS-ENSEMBLE"):
        map_mrclam_run(run, "visibility", robots=(1, 2, 3), method="covis-power")
    with pytest.raises(ValueError, match=r"'CAL-SMA' does not map masked visibility.*COVIS-ENSEMBLE"):
        map_mrclam_run(run, "visibility", robots=(1, 2, 3), method="cal-sma")
    # zero-filled, methods for complete histories apply ("naive" is SMA(UNWGT) zero-filled)
    zf = map_mrclam_run(run, "visibility", robots=(1, 2, 3), method="SMA(UNWGT)", zero_fill=True)
    naive = map_mrclam_run(run, "visibility", robots=(1, 2, 3), method="naive")
    assert naive.method == "naive" and np.array_equal(zf.positions, naive.positions)


@needs_data
def test_the_mrclam_example_maps_a_real_run(capsys):
    import runpy
    import sys

    script = EXAMPLES / "mrclam_map.py"
    argv = sys.argv
    sys.argv = [str(script), str(DATA / "MRCLAM_Dataset2"), "--sensor", "range"]
    try:
        runpy.run_path(str(script), run_name="__main__")
    finally:
        sys.argv = argv
    out = capsys.readouterr().out
    assert "range / RANGE-QUANTILE" in out
    mpe = float(out.split("MPE ")[1].split()[0])
    assert 0 < mpe < 0.5  # README: 0.23 m leave-one-run-out on DS2
