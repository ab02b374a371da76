"""The 3-D column of the one defaults table: which method maps which history with 3-D anchors."""

import numpy as np
import pytest

from mappers import default_method
from mappers.defaults import DEFAULTS, choose_method
from mappers.spatial import METHODS_3D
from mappers.spatial.pipeline_3d import default_method_3d
from tests.mappers.spatial.test_spatial_ba import camera_world


def test_every_spatial_entry_is_a_3d_method_and_2d_answers_do_not_move():
    named = {row.spatial for row in DEFAULTS.values()} - {None}
    # FRUSTUM-BA and FRUSTUM-BA-WALK need the camera's calibration, COVIS-3D-MEDIAN is opt-in
    # (better than COVIS-3D on 8 of 13 STAR-loc sequences only): chosen by name, never a default
    assert named == set(METHODS_3D) - {"FRUSTUM-BA", "FRUSTUM-BA-WALK", "COVIS-3D-MEDIAN"}
    assert choose_method("visibility", dimension=3) == ("COVIS-3D", {})
    assert choose_method("bearing", masked=True, dimension=3) == ("SPATIAL-BA", {})
    assert choose_method("range-bearing", dimension=3) == ("SPATIAL-BA", {})
    assert choose_method("range", dimension=3) == ("RANGE-3D", {})
    assert choose_method("range", masked=True, dimension=3) == ("RANGE-3D", {})
    assert choose_method("range") == ("UNFOLD", {})  # 2-D: as before
    assert choose_method("visibility") == ("CAL-SMA", {})  # 2-D: as before
    with pytest.raises(ValueError, match="dimension must be 2 or 3"):
        choose_method("visibility", dimension=4)


def test_default_method_with_3d_anchors():
    P, X, R = camera_world()
    xyz = P[:6]
    seen = (np.abs(X[:, 0::3]) + np.abs(X[:, 2::3]) > 0).astype(float)
    assert default_method(X, anchor_positions=xyz) == "SPATIAL-BA"
    assert default_method({"bearing": X, "range": R}, anchor_positions=xyz) == "SPATIAL-BA"
    assert default_method(seen, anchor_positions=xyz, return_params=True) == ("COVIS-3D", {})
    assert default_method(seen) == "CAL-SMA"  # no anchors given: the 2-D table
    assert default_method(R, anchor_positions=xyz, sensor="range") == "RANGE-3D"
    assert default_method_3d("range", masked=True) == "RANGE-3D"
    with pytest.raises(ValueError, match="no 3-D method maps 'visibility-bearing'"):
        default_method_3d("visibility-bearing")
