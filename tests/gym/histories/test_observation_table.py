"""The observation table's files and checks (lfmdr_gym/histories/observation_table.py)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lfmdr_gym.histories.observation_table import (
    ObservationTableError,
    check_landmarks,
    check_observations,
    read_landmarks,
    read_observations,
    write_landmarks,
    write_observations,
)


def _table(n: int = 5, **extra) -> pd.DataFrame:
    rng = np.random.default_rng(0)
    out = pd.DataFrame({"time": np.arange(n) * 0.25, "robot": [1, 1, 2, 2, 2][:n],
                        "landmark": [6, 7, 6, 8, 9][:n], "range": rng.uniform(0.5, 4, n),
                        "bearing": rng.uniform(-0.5, 0.5, n)})
    for key, value in extra.items():
        out[key] = value
    return out


@pytest.mark.parametrize("suffix", [".csv", ".parquet", ".tsv"])
def test_write_then_read_gives_the_same_table_and_attrs(tmp_path, suffix):
    table = _table()
    table.attrs = {"source": "test", "bin_width": 0.25, "robots": [2, 1]}
    path = write_observations(table, tmp_path / f"obs{suffix}")
    back = read_observations(path)
    assert back.attrs == table.attrs
    assert list(back.columns) == list(table.columns)
    for col in table.columns:
        assert back[col].to_numpy().tobytes() == table[col].to_numpy().tobytes(), col


def test_csv_metadata_is_leading_comment_lines(tmp_path):
    table = _table()
    table.attrs = {"sensor": "range-bearing", "note": "a: b"}
    text = write_observations(table, tmp_path / "o.csv").read_text().splitlines()
    assert text[0] == '# sensor: "range-bearing"' and text[1] == '# note: "a: b"'
    assert text[2].startswith("time,robot,landmark")


def test_string_ids_stay_strings_and_integer_ids_become_integers(tmp_path):
    path = tmp_path / "o.csv"
    path.write_text("time,landmark,robot\n0.0,tag36h11:3,alpha\n0.5,007,beta\n")
    back = read_observations(path)
    assert back["landmark"].tolist() == ["tag36h11:3", "007"]  # "007" is no integer's spelling
    assert back["robot"].tolist() == ["alpha", "beta"]
    path.write_text("time,landmark\n0.0,12\n0.5,-3\n")
    back = read_observations(path)
    assert back["landmark"].dtype == np.int64 and back["landmark"].tolist() == [12, -3]


def test_parquet_keeps_string_ids(tmp_path):
    table = pd.DataFrame({"time": [0.0, 1.0], "landmark": ["a", "b"]})
    back = read_observations(write_observations(table, tmp_path / "o.parquet"))
    assert back["landmark"].tolist() == ["a", "b"]


def test_missing_column_lists_the_columns_found(tmp_path):
    path = tmp_path / "o.csv"
    path.write_text("t,landmark,bearing\n0,1,0.1\n")
    with pytest.raises(ObservationTableError, match=r"missing required column\(s\) \['time'\]; "
                                                    r"columns found: \['t', 'landmark', 'bearing'\]"):
        read_observations(path)


@pytest.mark.parametrize(("cell", "what"), [("abc", "not a number"), ("", "missing"),
                                            ("inf", "not finite"), ("nan", "missing")])
def test_a_bad_measurement_names_the_file_line_and_column(tmp_path, cell, what):
    path = tmp_path / "o.csv"
    path.write_text(f"# source: \"x\"\ntime,landmark,range\n0,1,2.0\n1,1,{cell}\n2,1,3.0\n")
    with pytest.raises(ObservationTableError, match=rf"o.csv line 4, column 'range': .*{what}"):
        read_observations(path)


def test_negative_range_is_refused():
    with pytest.raises(ObservationTableError, match=r"row 2, column 'range': negative range"):
        check_observations(_table(range=[1.0, 2.0, -0.5, 1.0, 1.0]))


def test_degrees_are_suspected():
    with pytest.raises(ObservationTableError, match="radians expected; degrees suspected"):
        check_observations(_table(bearing=[10.0, 20.0, 45.0, -30.0, 5.0]))
    check_observations(_table(bearing=[2 * math.pi, -2 * math.pi, 0, 1, -1]))  # the bounds: fine


def test_zero_length_ray_and_partial_rays_are_refused():
    rays = {"ray_x": [0.1, 0.0, 0, 0, 0], "ray_y": [0.0, 0.0, 0, 0, 0], "ray_z": [1.0, 0.0, 1, 1, 1]}
    t = _table().drop(columns="bearing")
    with pytest.raises(ObservationTableError, match=r"row 1, column 'ray_x': zero-length ray"):
        check_observations(t.assign(**rays))
    with pytest.raises(ObservationTableError, match=r"come together; found \['ray_x', 'ray_z'\]"):
        check_observations(t.assign(ray_x=1.0, ray_z=1.0))


def test_unit_vector_bearings_must_be_unit_and_agree_with_the_angle():
    b = _table()["bearing"].to_numpy()
    good = _table(bearing_cos=np.cos(b), bearing_sin=np.sin(b))
    check_observations(good)
    with pytest.raises(ObservationTableError, match="not a unit vector"):
        check_observations(good.assign(bearing_cos=2 * np.cos(b)))
    with pytest.raises(ObservationTableError, match="disagrees with 'bearing'"):
        check_observations(good.assign(bearing=b + 0.1))


def test_a_ray_that_disagrees_with_the_bearing_is_refused():
    b = np.array([0.2, -0.3, 0.1, 0.0, 0.4])
    t = _table(bearing=b, ray_x=-np.sin(b), ray_y=0.3, ray_z=np.cos(b))
    check_observations(t)
    with pytest.raises(ObservationTableError, match="'ray_x' disagrees"):
        check_observations(t.assign(ray_x=np.sin(b)))


def test_misspelt_columns_frames_and_visible_are_checked():
    with pytest.raises(ObservationTableError, match="did you mean 'range'"):
        check_observations(_table().rename(columns={"range": "Range"}))
    with pytest.raises(ObservationTableError, match="frames are integers"):
        check_observations(_table(frame=[0.5, 1, 2, 3, 4]))
    with pytest.raises(ObservationTableError, match="visible is 0 or 1"):
        check_observations(_table(visible=[0, 1, 2, 1, 1]))
    with pytest.raises(ObservationTableError, match="missing landmark id"):
        check_observations(_table(landmark=[1, None, 2, 3, 4]))
    check_observations(_table(frame=[0, 0, 1, 1, 2], visible=[1, 0, 1, 1, 1], extra_note="kept"))


def test_not_a_dataframe_and_unknown_formats_are_refused(tmp_path):
    with pytest.raises(ObservationTableError, match="pandas DataFrame"):
        check_observations({"time": [0.0], "landmark": [1]})
    with pytest.raises(ObservationTableError, match="unknown table format"):
        write_observations(_table(), tmp_path / "o.xlsx")
    bad = tmp_path / "o.csv"
    bad.write_text("# no separator here\ntime,landmark\n0,1\n")
    with pytest.raises(ObservationTableError, match="line 1: a comment line holds metadata"):
        read_observations(bad)
    with pytest.raises(FileNotFoundError):
        read_observations(tmp_path / "absent.csv")


def test_a_table_that_fails_its_check_leaves_the_file_as_it_was(tmp_path):
    path = write_observations(_table(), tmp_path / "o.csv")
    before = path.read_bytes()
    with pytest.raises(ObservationTableError):
        write_observations(_table(range=[-1.0] * 5), path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["o.csv"]  # no temporary file left


def test_landmark_tables(tmp_path):
    path = tmp_path / "a.csv"
    path.write_text("landmark,x,y\n6,0.0,0.0\n7,1.0,0.0\n8,0.0,1.5\n")
    anchors = read_landmarks(path, what="anchors")
    assert anchors["landmark"].tolist() == [6, 7, 8] and anchors["y"].tolist() == [0, 0, 1.5]
    back = read_landmarks(write_landmarks(anchors, tmp_path / "a.parquet"))
    pd.testing.assert_frame_equal(back, anchors)
    path.write_text("landmark,x\n6,0.0\n")
    with pytest.raises(ObservationTableError, match=r"lacks column\(s\) \['y'\]; columns found"):
        read_landmarks(path, what="anchors")
    path.write_text("landmark,x,y\n6,0.0,0.0\n6,1.0,0.0\n")
    with pytest.raises(ObservationTableError, match="line 3, column 'landmark': landmark 6 is "
                                                    "listed twice"):
        read_landmarks(path)
    with pytest.raises(ObservationTableError, match="column 'x'"):
        check_landmarks(pd.DataFrame({"landmark": ["a"], "x": [np.nan], "y": [0.0]}))


_floats = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_property_any_valid_table_survives_csv_and_parquet_bit_for_bit(tmp_path, data):
    n = data.draw(st.integers(1, 12))
    ids = data.draw(st.one_of(
        st.lists(st.integers(-10**12, 10**12), min_size=n, max_size=n),
        # strings that spell no integer (those read back as integers: tested above)
        st.lists(st.from_regex(r"[A-Za-z_][A-Za-z0-9_:.\- ]{0,7}[A-Za-z0-9_]", fullmatch=True)
                 .filter(lambda s: s not in ("NaN", "nan", "NA")), min_size=n, max_size=n)))
    table = pd.DataFrame({
        "time": data.draw(st.lists(_floats, min_size=n, max_size=n)),
        "landmark": pd.Series(ids, dtype=np.int64 if isinstance(ids[0], int) else object),
        "range": data.draw(st.lists(st.floats(0, 1e6), min_size=n, max_size=n)),
        "bearing": data.draw(st.lists(st.floats(-2 * math.pi, 2 * math.pi), min_size=n,
                                      max_size=n)),
    })
    for suffix in (".csv", ".parquet"):
        back = read_observations(write_observations(table, tmp_path / f"p{suffix}"))
        for col in ("time", "range", "bearing"):
            assert back[col].to_numpy().tobytes() == table[col].to_numpy().tobytes()
        assert back["landmark"].tolist() == ids
