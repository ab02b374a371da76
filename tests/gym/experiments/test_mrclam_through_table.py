"""``lfmdr mrclam`` maps a run through its observation table (convert + map) and gives the maps it
gave through the loader: the History it maps, its meta and its warnings are the loader's, on every
real run and sensor, at the bin width each default method asks for (issue 33)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from paths import SHARED_DATA

from lfmdr_gym.datasets.mrclam import ROBOT_SUBJECTS, load_mrclam
from lfmdr_gym.experiments import mrclam as experiment
from mappers.core.sensors import check_sensor_set

DATA = SHARED_DATA / "mrclam"
SENSORS = ("visibility", "bearing", "range", "range-bearing")


def _parts(h):
    return dict(h.parts) if h.fused else {h.sensor: h}


@pytest.mark.slow
@pytest.mark.skipif(not DATA.is_dir(), reason=f"MRCLAM data not found at {DATA}")
@pytest.mark.parametrize("name", ["MRCLAM_Dataset1", "MRCLAM_Dataset2", "MRCLAM_Dataset3",
                                  "MRCLAM_Dataset6"])
def test_lfmdr_mrclam_maps_the_loaders_history(name):
    for sensor in SENSORS:
        _, bin_width, _, _ = experiment._plan(sensor, None, None, {}, False)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            got, report = experiment._load(DATA / name, check_sensor_set(sensor), ROBOT_SUBJECTS,
                                           bin_width, None, "known")
            want = load_mrclam(DATA / name, sensor, bin_width=bin_width)
        got = got if isinstance(got, dict) else {sensor: got}
        assert set(got) == set(_parts(want))
        for part, h in _parts(want).items():
            g = got[part]
            assert g.matrix.tobytes() == h.matrix.tobytes(), (name, sensor, part)
            np.testing.assert_array_equal(g.mask, h.mask)
            np.testing.assert_array_equal(g.timeline, h.timeline)
            np.testing.assert_array_equal(g.anchor_ids, h.anchor_ids)
            assert g.object_positions.tobytes() == h.object_positions.tobytes()
            assert g.anchor_positions.tobytes() == h.anchor_positions.tobytes()
            assert {k: v for k, v in g.meta.items() if k in h.meta} == dict(h.meta)
        assert report.warnings == tuple(want.meta["warnings"])
