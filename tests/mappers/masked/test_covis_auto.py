"""Masked bearing and visibility maps from co-observation: the building blocks covis-angle
(mappers/masked/pair_maps.py) and covis-cal, and COVIS-AUTO (mappers/masked/covis_auto.py)."""

from __future__ import annotations

import numpy as np
import pytest
from map_errors import non_anchor_error
from synthetic_camera import camera_bearings
from synthetic_walk import ANCHORS, history, layout, walk

from mappers import build_map
from mappers.catalog import resolve_method
from mappers.defaults import DEFAULT_METHODS
from mappers.masked.coobservation import angle_covisibility_dissimilarity
from mappers.masked.covis_auto import CovisAuto, CovisCalibrated, co_observation_coefficient
from mappers.masked.pair_maps import MaskedMapper, masked_embedding

pytestmark = pytest.mark.usefixtures("one_blas_thread")


def _camera(fov_deg, max_range=None, n_obj=30, n_steps=3000, noise_deg=1.0, seed=0):
    """Landmarks in a 2.5 m square seen from random poses by a camera of ``fov_deg`` (and
    ``max_range``): returns positions, the (M, 2N) bearing history and its mask, and anchors."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(-1.2, 1.2, size=(n_obj, 2))
    poses = np.column_stack([rng.uniform(-1.25, 1.25, (n_steps, 2)),
                             rng.uniform(-np.pi, np.pi, n_steps)])
    X, seen = camera_bearings(P, poses, fov_deg, max_range, noise_deg, rng)
    anchors = np.array([int(np.argmin(np.linalg.norm(P - c, axis=1)))
                        for c in [(-1.2, -1.2), (1.2, -1.2), (1.2, 1.2), (-1.2, 1.2)]])
    return P, X, np.repeat(seen, 2, axis=1), anchors


def test_angle_weighted_coefficient_by_hand():
    seen = np.array([[True, True, True, False], [True, True, False, False],
                     [False, False, False, True]])
    ang = np.array([[0.0, 0.2, 0.1, 0.0], [0.0, 0.2 + np.pi / 2, 0.0, 0.0], [0, 0, 0, 0.3]])
    delta, C = angle_covisibility_dissimilarity(seen, ang)
    assert C[0, 1] == 2 and C[0, 2] == 0 and C[0, 0] == 3
    # same direction once (cos 0 = 1), at right angles once (cos = 0): G = 1, n = 3 and 2
    assert delta[0, 1] == pytest.approx(-np.log(1 / np.sqrt(6)))
    assert delta[0, 2] == pytest.approx(-np.log(1e-6))  # never seen together
    assert np.all(np.diag(delta) == 0) and np.allclose(delta, delta.T)
    och, C2 = co_observation_coefficient(
        np.stack([np.cos(ang), np.sin(ang)], -1).reshape(3, -1) * np.repeat(seen, 2, 1),
        np.repeat(seen, 2, axis=1), "bearing")
    assert och[0, 1] == pytest.approx(1 / np.sqrt(6)) and och[0, 2] == 0 and och[1, 1] == 1
    assert np.array_equal(C, C2)


def test_covis_cal_recovers_a_layout_seen_through_a_90_degree_view():
    P, X, mask, a = _camera(90)
    Y = CovisCalibrated().fit_transform(X, mask=mask, sensor="bearing", anchor_ids=a,
                                        anchor_positions=P[a])
    assert np.allclose(Y[a], P[a])
    assert non_anchor_error(Y, P, a) < 0.2  # 2.5 m arena; a random map is ~1 m off


def test_covis_angle_recovers_a_layout_seen_with_a_range_limit():
    P, X, mask, a = _camera(90, max_range=1.2, seed=1)
    mm = masked_embedding(X, mask, "bearing", "covis-angle", anchor_ids=a, anchor_positions=P[a])
    assert non_anchor_error(mm.positions, P, a) < 0.08
    plain = masked_embedding(X, mask, "bearing", "covis-nonmetric", anchor_ids=a,
                             anchor_positions=P[a])
    assert not np.allclose(mm.delta, plain.delta)  # the angles enter the dissimilarity


@pytest.mark.parametrize(("max_range", "branch"), [(None, "covis-cal"), (1.0, "covis-angle")])
def test_covis_auto_chooses_by_the_share_of_pairs_never_seen_together(max_range, branch):
    P, X, mask, a = _camera(90, max_range=max_range, seed=2)
    est = CovisAuto()
    Y = est.fit_transform(X, mask=mask, sensor="bearing", anchor_ids=a, anchor_positions=P[a])
    assert est.branch_ == branch
    assert (est.local_share_ <= 0.1) == (branch == "covis-cal")
    assert non_anchor_error(Y, P, a) < (0.2 if branch == "covis-cal" else 0.08)


def test_covis_auto_maps_masked_bearing_through_build_map():
    P, X, mask, a = _camera(90, seed=3)
    # the masked bearing default refines COVIS-AUTO's map (BEARING-BA); named here, its own map
    assert DEFAULT_METHODS[("bearing", True)] == "BEARING-BA"
    m = build_map(X, a, P[a], "COVIS-AUTO", mask=mask, sensor="bearing")
    assert m.method == "COVIS-AUTO" and non_anchor_error(m.positions, P, a) < 0.2
    vis = (mask[:, 0::2]).astype(float)  # visibility: the co-observation pattern alone
    Y = CovisCalibrated().fit_transform(vis, mask=mask[:, 0::2], sensor="visibility", anchor_ids=a,
                                        anchor_positions=P[a])  # covis-cal, a building block
    assert non_anchor_error(Y, P, a) < 0.3


def test_bad_input_is_refused_with_its_name():
    P, X, mask, a = _camera(90, n_steps=300)
    fit = dict(mask=mask, sensor="bearing", anchor_ids=a, anchor_positions=P[a])
    # parameters are checked when fitting (scikit-learn's contract: __init__ only stores them)
    for est, match in ((CovisCalibrated(min_co=0), "min_co"), (CovisCalibrated(min_co=True), "min_co"),
                       (CovisAuto(local_share=1.5), "local_share"),
                       (CovisCalibrated(links=("cubic",)), "links")):
        with pytest.raises(ValueError, match=match):
            est.fit(X, **fit)
    with pytest.raises(ValueError, match="sensor"):
        CovisCalibrated().fit_transform(X[:, ::2], sensor="range")
    with pytest.raises(ValueError, match="covis-angle.*bearing"):
        masked_embedding(mask[:, ::2].astype(float), None, "visibility", "covis-angle")
    with pytest.raises(ValueError, match="bearing"):
        CovisAuto().fit_transform(mask[:, ::2].astype(float), sensor="visibility")
    with pytest.raises(ValueError, match="mask=..."):  # the mask is a keyword argument
        CovisAuto().fit(X, mask, sensor="bearing")
    with pytest.raises(ValueError, match="range"):
        resolve_method("COVIS-AUTO", "range", masked=True)
    assert resolve_method("COVIS-AUTO", "bearing", masked=True).label == "COVIS-AUTO"
    for old in ("covis-cal", "covis-angle"):  # building blocks, no longer labels
        with pytest.raises(ValueError, match=f"{old!r} is no longer a label: a building block.*"
                                             "use COVIS-AUTO"):
            resolve_method(old, "bearing", masked=True)


@pytest.mark.parametrize("method", ["covis-nonmetric", "covis-power"])
def test_pattern_only_methods_refuse_a_complete_bearing_history(method):
    """Every object sensed in every step: the co-observation pattern is uniform, and these
    methods used to draw a ~0.8 m map of it silently. They refuse, naming the alternatives;
    a masked history of the same camera still maps."""
    P, X, mask, a = _camera(360, n_obj=20, n_steps=400)
    assert mask.all()
    with pytest.raises(ValueError, match="sensed every object in every step.*covis-angle"):
        MaskedMapper(method=method).fit_transform(X, sensor="bearing", anchor_ids=a,
                                                  anchor_positions=P[a])
    with pytest.raises(ValueError, match="sensed every object in every step"):
        masked_embedding(X, None, "bearing", method, anchor_ids=a, anchor_positions=P[a])
    P, X, mask, a = _camera(90, n_obj=20, n_steps=1500)
    Y = MaskedMapper(method=method).fit_transform(X, mask=mask, sensor="bearing", anchor_ids=a,
                                                  anchor_positions=P[a])
    assert np.isfinite(Y).all()


@pytest.mark.parametrize("n_objects", [5, 8, 12])
def test_masked_bearing_default_maps_twelve_objects_or_fewer(n_objects):
    # COVIS-AUTO's 12 neighbours were refused for 12 objects or fewer (issue 35); its default
    # now lets CAL-SMA take at most M - 1, while a number given is still checked
    P = layout(n_objects, seed=1)
    X, mask = history(P, walk(80, seed=2), "bearing", masked=True)
    for method in (None, "COVIS-AUTO"):
        result = build_map(X, ANCHORS, P[ANCHORS], mask=mask, method=method)
        assert not np.isnan(result.positions).any()
    with pytest.raises(ValueError, match="n_neighbors must be an integer in"):
        build_map(X, ANCHORS, P[ANCHORS], mask=mask, method="COVIS-AUTO", n_neighbors=n_objects)
