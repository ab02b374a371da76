"""lfmdr_gym.experiments.map_files: map.csv, the tag map (JSON/YAML), scores, written as a set."""

import csv
import json
from types import SimpleNamespace

import numpy as np
import pytest

from lfmdr_gym.experiments import map_files
from lfmdr_gym.experiments.map_files import score_against_truth, write_map_files

IDS = ["tag_a", "tag_b", "7", "tag_d", "tag_e"]
POSITIONS = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1e-5], [np.nan, np.nan], [1.0, 1.0]])
ANCHORS = [0, 1, 4]
ANCHOR_POS = np.array([[0.0, 0.0], [2.0, 0.0], [1.0, 1.0]])


def _map(**extra):
    return SimpleNamespace(positions=POSITIONS, warnings=("a warning",), **extra)


def _read_csv(path):
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_map_csv_keeps_ids_and_marks_anchors_and_unmapped(tmp_path):
    files = write_map_files(tmp_path, _map(), IDS, ANCHORS, ANCHOR_POS, plot=False)
    assert sorted(p.name for p in files.files) == ["map.csv", "map.json", "map.yaml"]
    rows = _read_csv(tmp_path / "map.csv")
    assert list(rows[0]) == ["landmark", "x", "y", "anchor", "mapped"]
    assert [r["landmark"] for r in rows] == IDS
    assert [r["anchor"] for r in rows] == ["1", "1", "0", "0", "1"]
    assert [r["mapped"] for r in rows] == ["1", "1", "1", "0", "1"]
    assert rows[3]["x"] == rows[3]["y"] == ""
    assert float(rows[2]["y"]) == 1e-5  # exact: shortest repr of the float
    assert files.scores is None and not (tmp_path / "scores.json").exists()


def test_integer_ids_stay_integers_in_the_tag_map(tmp_path):
    ids = np.array([11, 12, 13, 14, 15])
    write_map_files(tmp_path, _map(), ids, ANCHORS, ANCHOR_POS, plot=False)
    doc = json.loads((tmp_path / "map.json").read_text())
    assert [e["id"] for e in doc["landmarks"]] == [11, 12, 13, 15]
    assert doc["unmapped"] == [14]
    assert doc["frame"] == "map" and doc["units"] == "m" and doc["dimensions"] == 2


def test_yaml_reads_back_as_the_json(tmp_path):
    yaml = pytest.importorskip("yaml")
    cov = np.zeros((5, 2, 2))
    cov[2] = [[1e-6, 2e-7], [2e-7, 3e-6]]
    cov[3] = np.nan
    write_map_files(tmp_path, _map(covariances=cov), IDS, ANCHORS, ANCHOR_POS, plot=False,
                    frame="world")
    doc = json.loads((tmp_path / "map.json").read_text())
    assert yaml.safe_load((tmp_path / "map.yaml").read_text()) == doc
    entry = next(e for e in doc["landmarks"] if e["id"] == "7")
    assert entry["covariance"] == [[1e-6, 2e-7], [2e-7, 3e-6]]
    assert doc["frame"] == "world"


def test_covariance_columns_when_the_map_has_them(tmp_path):
    cov = np.tile(np.array([[4.0, 0.5], [0.5, 9.0]]), (5, 1, 1))
    cov[3] = np.nan
    write_map_files(tmp_path, _map(covariances=cov), IDS, ANCHORS, ANCHOR_POS, plot=False)
    rows = _read_csv(tmp_path / "map.csv")
    assert list(rows[0])[-3:] == ["cov_xx", "cov_xy", "cov_yy"]
    assert [float(rows[2][c]) for c in ("cov_xx", "cov_xy", "cov_yy")] == [4.0, 0.5, 9.0]
    assert rows[3]["cov_xx"] == ""


def test_covariance_columns_of_a_3d_map(tmp_path):
    pos = np.column_stack([POSITIONS, [0.0, 0.0, 0.5, np.nan, 1.0]])
    cov = np.tile(np.array([[4.0, 0.5, 0.1], [0.5, 9.0, 0.2], [0.1, 0.2, 1.0]]), (5, 1, 1))
    cov[3] = np.nan
    m = SimpleNamespace(positions=pos, warnings=(), covariances=cov)
    write_map_files(tmp_path, m, IDS, ANCHORS, np.column_stack([ANCHOR_POS, [0.0, 0.0, 1.0]]),
                    plot=False)
    rows = _read_csv(tmp_path / "map.csv")
    names = ["cov_xx", "cov_xy", "cov_xz", "cov_yy", "cov_yz", "cov_zz"]
    assert sorted(list(rows[0])[-6:]) == sorted(names)
    assert [float(rows[2][c]) for c in names] == [4.0, 0.5, 0.1, 9.0, 0.2, 1.0]
    assert rows[3]["cov_zz"] == ""


def test_covariances_of_the_wrong_shape_are_refused(tmp_path):
    with pytest.raises(ValueError, match="covariances have shape"):
        write_map_files(tmp_path, _map(covariances=np.zeros((4, 2, 2))), IDS, ANCHORS,
                        ANCHOR_POS, plot=False)
    assert list(tmp_path.iterdir()) == []


def test_scores_over_the_landmarks_the_truth_has():
    truth = {"tag_a": (0.0, 0.0), "tag_b": (2.0, 0.0), "tag_d": (5.0, 5.0), "tag_e": (1.0, 1.5),
             "elsewhere": (9.0, 9.0)}  # "7" missing from the truth
    s = score_against_truth(POSITIONS, IDS, ANCHORS, truth)
    assert s["missing_from_truth"] == ["7"]
    assert s["unmapped"] == ["tag_d"]
    assert s["truth_not_in_log"] == ["elsewhere"]
    assert s["n_scored"] == 3 and s["n_scored_nonanchor"] == 0
    assert s["mpe"] == pytest.approx(0.5 / 3, rel=1e-12)
    assert s["mpe_nonanchor"] is None
    assert s["moe"] == pytest.approx(0.0, abs=1e-12)


def test_scores_json_and_figure_written(tmp_path):
    pytest.importorskip("matplotlib")
    truth = {k: v for k, v in zip(IDS, [(0, 0), (2, 0), (2, 0.5), (1, 3), (1, 1)], strict=True)}
    files = write_map_files(tmp_path, _map(), IDS, ANCHORS, ANCHOR_POS, truth=truth, title="t")
    scores = json.loads((tmp_path / "scores.json").read_text())
    assert scores == files.scores
    assert scores["mpe_nonanchor"] == pytest.approx(0.5 - 1e-5, rel=1e-9)
    assert (tmp_path / "map.png").read_bytes()[:4] == b"\x89PNG"


def test_a_failure_leaves_the_folder_as_it_was(tmp_path, monkeypatch):
    (tmp_path / "map.csv").write_text("an older map")
    (tmp_path / "notes.txt").write_text("mine")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}

    def broken_plot(*args, **kwargs):
        raise RuntimeError("no figure today")

    monkeypatch.setattr(map_files, "_plot", broken_plot)
    with pytest.raises(RuntimeError, match="no figure today"):
        write_map_files(tmp_path, _map(), IDS, ANCHORS, ANCHOR_POS, truth={"tag_a": (0, 0)})
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_figure_draws_the_95_percent_ellipses(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from lfmdr_gym import render

    drawn = []
    real = render.draw_ellipses
    monkeypatch.setattr(render, "draw_ellipses",
                        lambda ax, pos, cov, **kw: drawn.append(real(ax, pos, cov, **kw)))
    cov = np.tile(np.eye(2) * 0.01, (5, 1, 1))
    cov[ANCHORS] = 0.0
    cov[3] = np.nan
    write_map_files(tmp_path, _map(covariances=cov), IDS, ANCHORS, ANCHOR_POS)
    assert drawn == [1]  # the one mapped non-anchor landmark
    assert (tmp_path / "map.png").read_bytes()[:4] == b"\x89PNG"


def test_a_3d_map_is_drawn_in_three_views_with_its_heights(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from matplotlib.image import imread

    from lfmdr_gym.experiments import figures

    drawn = {}
    real = figures.plot_views_3d

    def spy(est, true, anchors, path, **kw):
        drawn.update(est=est, true=true, anchors=anchors)
        return real(est, true, anchors, path, **kw)

    monkeypatch.setattr(figures, "plot_views_3d", spy)
    z = np.array([0.0, 0.0, 0.5, np.nan, 1.0])
    pos = np.column_stack([POSITIONS, z])
    truth = {"tag_a": (0.0, 0.0, 0.0), "tag_b": (2.0, 0.0, 0.0), "7": (2.0, 0.1, 0.4)}
    m = SimpleNamespace(positions=pos, warnings=("a warning",))
    write_map_files(tmp_path, m, IDS, ANCHORS, np.column_stack([ANCHOR_POS, [0.0, 0.0, 1.0]]),
                    truth=truth)
    np.testing.assert_array_equal(drawn["est"][:, 2], z)
    np.testing.assert_array_equal(drawn["true"][2], [2.0, 0.1, 0.4])  # from the truth
    np.testing.assert_array_equal(drawn["true"][4], [1.0, 1.0, 1.0])  # an anchor without truth
    assert np.isnan(drawn["true"][3]).all() and drawn["anchors"] == ANCHORS
    height, width = imread(tmp_path / "map.png").shape[:2]
    assert width > 2.5 * height  # three views side by side


def test_the_three_views_refuse_a_2d_map(tmp_path):
    pytest.importorskip("matplotlib")
    from lfmdr_gym.experiments.figures import plot_views_3d

    with pytest.raises(ValueError, match=r"\(M, 3\) positions"):
        plot_views_3d(POSITIONS, POSITIONS, ANCHORS, tmp_path / "m.png")
    assert not (tmp_path / "m.png").exists()


def test_each_view_of_a_3d_map_draws_the_ellipses_of_its_plane(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    import lfmdr_gym.render

    planes = []
    monkeypatch.setattr(lfmdr_gym.render, "draw_ellipses",
                        lambda ax, pos, cov: planes.append((np.array(pos), np.array(cov))))
    pos = np.column_stack([POSITIONS, [0.0, 0.0, 0.5, np.nan, 1.0]])
    cov = np.tile(np.array([[4.0, 0.5, 0.1], [0.5, 9.0, 0.2], [0.1, 0.2, 1.0]]), (5, 1, 1))
    m = SimpleNamespace(positions=pos, warnings=(), covariances=cov)
    write_map_files(tmp_path, m, IDS, ANCHORS, np.column_stack([ANCHOR_POS, [0.0, 0.0, 1.0]]))
    assert len(planes) == 3  # top (x, y), front (x, z), side (y, z)
    for (p, c), (a, b) in zip(planes, [(0, 1), (0, 2), (1, 2)], strict=True):
        np.testing.assert_array_equal(p[2], pos[2, [a, b]])
        np.testing.assert_array_equal(c[0], cov[0][np.ix_([a, b], [a, b])])
