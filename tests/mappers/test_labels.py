"""The method labels: one style, twins as one method with a parameter, old labels resolved with a
warning or refused with where they went (mappers/catalog.py), and one table of defaults that
answers for every input build_map takes (mappers/defaults.py)."""

from __future__ import annotations

import csv
import re
import warnings

import numpy as np
import pytest
from paths import ROOT

import mappers
from mappers import METHODS, build_map, default_method
from mappers.catalog import (
    _METHODS,
    ALIASES,
    RETIRED,
    MethodSpec,
    implied_params,
    register_method,
    resolve_method,
)
from mappers.defaults import DEFAULTS, SCALABLE_ABOVE_OBJECTS, choose_method
from mappers.spatial.pipeline_3d import METHODS_3D

PAPER = ["LPCA", "SMA(UNWGT)", "SMA(WGT)", "KPCA(GAUS)", "KPCA(POLY)", "ISOMAP", "LLE", "LEM",
         "HLLE", "SDE"]
OURS = ["CAL-SMA", "UNFOLD", "RANGE-QUANTILE", "COVIS-ENSEMBLE", "COVIS-AUTO", "COVIS-SPARSE",
        "DROPOUT-BLEND", "LOC-SMA", "VB-SMA", "BEARING-BA", "VIS-BA-WALK", "VIEW-BA"]
# the 30 labels registered before the zoo was made smaller, each with a sensor and kind it mapped
BEFORE = {
    **{label: ("visibility", False) for label in PAPER},
    "CAL-SMA": ("visibility", False), "UNFOLD": ("range", False),
    "CAL-SMA-SPARSE": ("visibility", False), "range-quantile": ("range", True),
    "range-bounds": ("range", True), "covis-nonmetric": ("visibility", True),
    "covis-power": ("visibility", True), "covis-angle": ("bearing", True),
    "masked-euclidean": ("bearing", True), "covis-ensemble": ("visibility", True),
    "covis-cal": ("bearing", True), "covis-auto": ("bearing", True),
    "covis-sparse": ("bearing", True), "dropout-blend": ("visibility", True),
    "LOC-SMA": (frozenset({"range", "bearing"}), True),
    "VB-SMA": (frozenset({"visibility", "bearing"}), False), "BEARING-BA": ("bearing", True),
    "VIS-BA": ("visibility", False), "VIS-BA-WALK": ("visibility", False),
    "VIEW-BA": ("visibility", True),
}
DEAD_ENDS = ("range-bounds", "masked-euclidean", "covis-power", "VIS-BA")
BUILDING_BLOCKS = ("covis-nonmetric", "covis-angle", "covis-cal")


def test_the_labels_of_the_smaller_zoo_in_one_style():
    assert list(METHODS) == PAPER + OURS
    style = re.compile(r"[A-Z][A-Z0-9]*(-[A-Z0-9]+)*")
    assert all(style.fullmatch(label) for label in OURS)
    assert len(BEFORE) == 30


@pytest.mark.parametrize("old", sorted(BEFORE))
def test_every_old_label_resolves_or_says_where_it_went(old):
    sensor, masked = BEFORE[old]
    if old in METHODS:  # kept as it was: no warning
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert resolve_method(old, sensor, masked=masked) is METHODS[old]
    elif old in ALIASES:
        new = ALIASES[old]
        with pytest.warns(FutureWarning, match=f"{re.escape(repr(old))} is now spelled "
                                               f"{re.escape(repr(new.label))}"):
            spec = resolve_method(old, sensor, masked=masked)
        assert spec.label == new.label and implied_params(spec) == dict(new.params)
        assert spec.resolved_params() == METHODS[new.label].resolved_params(new.params)
    else:
        where = "docs/dead-ends.md" if old in DEAD_ENDS else "a building block"
        assert old in DEAD_ENDS + BUILDING_BLOCKS and old in RETIRED
        with pytest.raises(ValueError, match=f"{re.escape(repr(old))} is no longer a label: "
                                             f".*{re.escape(where)}.*use "):
            resolve_method(old, sensor, masked=masked)


def test_the_aliases_and_refusals_cover_exactly_the_labels_that_went():
    assert set(ALIASES) | set(RETIRED) == set(BEFORE) - set(METHODS)
    assert not set(ALIASES) & set(RETIRED)
    assert all(a.label in METHODS for a in ALIASES.values())
    assert all(METHODS[a.label].check_params(a.params) is None for a in ALIASES.values())


def _stored_labels() -> set[str]:
    labels = set()
    for path in [*ROOT.glob("docs/results/**/*.csv"), *ROOT.glob("docs/exploration/*.csv")]:
        with open(path, newline="") as fh:
            labels |= {row["method"] for row in csv.DictReader(fh) if "method" in row}
    # rows that name a run, not a method (bench_visibility_adjustment.py's columns)
    return labels - {"default (start)", "VIS-BA + walk"}


def test_every_label_of_a_stored_result_resolves_or_is_refused_with_its_reason():
    stored = _stored_labels()
    assert {"covis-auto", "covis-nonmetric", "VIS-BA", "CAL-SMA", "BEARING-BA"} <= stored
    assert stored <= set(BEFORE) | set(METHODS_3D)  # (3-D maps: chosen by the anchors' shape)


def test_case_variants():
    with warnings.catch_warnings():  # a label whose spelling did not change: any case, silently
        warnings.simplefilter("error")
        assert resolve_method("cal-sma", "visibility").label == "CAL-SMA"
        assert resolve_method("sma(wgt)", "bearing").label == "SMA(WGT)"
        assert resolve_method("COVIS-AUTO", "bearing", masked=True).label == "COVIS-AUTO"
        assert resolve_method(" view-ba ", "visibility", masked=True).label == "VIEW-BA"
    # a label whose spelling changed: every spelling but the new one warns, naming it
    for old in ("covis-auto", "Covis-Auto", "COVIS-auto"):
        with pytest.warns(FutureWarning, match="now spelled 'COVIS-AUTO'"):
            assert resolve_method(old, "bearing", masked=True).label == "COVIS-AUTO"
    with pytest.warns(FutureWarning, match="'CAL-SMA' with sparse=True"):
        assert resolve_method("cal-sma-sparse", "bearing").defaults["sparse"] is True
    with pytest.raises(ValueError, match="no longer a label"):
        resolve_method("vis-ba", "visibility")


def test_the_warning_names_the_callers_line():
    P, rng = _layout(20)
    V = rng.uniform(0.0, 2.5, (300, 2))
    r = np.hypot(*(P[:, None] - V[None]).transpose(2, 0, 1))
    seen = r < 1.5
    with pytest.warns(FutureWarning) as caught:
        m = build_map(r * seen, np.arange(4), P[:4], "range-quantile", sensor="range", mask=seen)
    assert caught[0].filename == __file__ and m.method == "RANGE-QUANTILE"
    new = build_map(r * seen, np.arange(4), P[:4], "RANGE-QUANTILE", sensor="range", mask=seen)
    np.testing.assert_array_equal(m.positions, new.positions)


def test_a_user_method_may_take_a_retired_label_back():
    spec = MethodSpec("MASKED-EUCLIDEAN", "mappers.masked.pair_maps:_masked_euclidean",
                      uses_anchors=True, normalize=False, histories=("complete", "masked"))
    try:
        register_method(spec)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert resolve_method("masked-euclidean", "bearing", masked=True) is spec
    finally:
        _METHODS.pop("MASKED-EUCLIDEAN", None)


def test_every_row_of_the_defaults_table_names_methods_that_map_it():
    for (sensor, masked), row in DEFAULTS.items():
        for column in ("method", "localisation_free", "large", "dropouts", "logged"):
            label = getattr(row, column)
            params = getattr(row, f"{column}_params", {})
            if label is None:
                continue
            assert METHODS[label].accepts(sensor, masked), (sensor, masked, column)
            METHODS[label].check_params(params)
    assert choose_method("visibility", n_objects=SCALABLE_ABOVE_OBJECTS + 1) == (
        "CAL-SMA", {"sparse": True})
    assert choose_method("bearing", masked=True, n_objects=10**4) == (
        "BEARING-BA", {"start": "COVIS-SPARSE", "start_params": {"n_rounds": 5},
                       "schur_solver": "cg", "schur_rtol": 1e-3, "gain_tol": 1e-2,
                       "max_rounds": 6})
    assert choose_method("visibility", dropouts=True) == ("VIS-BA-WALK", {})
    # a logged run (MRCLAM): its own column, whatever the size
    for sensor, label in (("visibility", "COVIS-ENSEMBLE"), ("bearing", "COVIS-ENSEMBLE"),
                          ("range", "RANGE-QUANTILE"), ("range-bearing", "LOC-SMA")):
        assert choose_method(sensor, masked=True, logged=True) == (label, {})


# ------------------------------------------------ default_method for every input build_map takes
def _layout(m, seed=0):
    rng = np.random.default_rng(seed)
    P = rng.uniform(0.0, 2.5, (m, 2))
    P[:4] = [[0.0, 0.0], [2.5, 0.0], [2.5, 2.5], [0.0, 2.5]]
    return P, rng


def _fused(m=30, n=200, masked=False, seed=0):
    P, rng = _layout(m, seed)
    V = rng.uniform(0.0, 2.5, (n, 2))
    d = P[:, None] - V[None]
    r = np.hypot(d[..., 0], d[..., 1])
    th = np.arctan2(d[..., 1], d[..., 0])
    B = np.stack([np.cos(th), np.sin(th)], -1).reshape(m, -1)
    vis = (r < 0.8).astype(float)
    seen = r < 1.2 if masked else np.ones_like(r, bool)
    return P, r * seen, B * np.repeat(seen, 2, axis=1), vis, seen


@pytest.mark.parametrize("masked", [False, True])
def test_default_method_of_fused_histories(masked):
    P, R, B, V, seen = _fused(masked=masked)
    masks = {"range": seen, "bearing": np.repeat(seen, 2, axis=1)} if masked else None
    assert default_method({"range": R, "bearing": B}, mask=masks) == "LOC-SMA"
    assert default_method({"range": R, "bearing": B}, mask=masks,
                          return_params=True) == ("LOC-SMA", {})
    if not masked:
        assert default_method({"visibility": V, "bearing": B}) == "VB-SMA"
    else:  # no default for masked visibility + bearing: build_map says so, and default_method
        with pytest.raises(ValueError, match="no default method for masked visibility-bearing"):
            default_method({"visibility": V, "bearing": B},
                           mask={"visibility": seen, "bearing": np.repeat(seen, 2, axis=1)})


def test_default_method_of_large_and_flickering_histories():
    m = SCALABLE_ABOVE_OBJECTS + 1
    P, rng = _layout(m)
    V = rng.uniform(0.0, 2.5, (400, 2))
    r = np.hypot(*(P[:, None] - V[None]).transpose(2, 0, 1))
    X = (r < 0.4).astype(float)
    assert default_method(X, sensor="visibility") == "CAL-SMA"
    assert default_method(X, sensor="visibility", return_params=True) == ("CAL-SMA",
                                                                          {"sparse": True})
    assert default_method(X[:SCALABLE_ABOVE_OBJECTS], sensor="visibility",
                          return_params=True) == ("CAL-SMA", {})
    mask = r < 1.0
    assert default_method(np.where(mask, X, 0.0), sensor="visibility", mask=mask) == "DROPOUT-BLEND"
    th = np.arctan2(*(P[:, None] - V[None]).transpose(2, 0, 1)[::-1])
    B = np.stack([np.cos(th), np.sin(th)], -1).reshape(m, -1)
    assert default_method(B, sensor="bearing", return_params=True) == ("CAL-SMA", {"sparse": True})
    Bm = np.repeat(mask, 2, axis=1)
    assert default_method(B * Bm, sensor="bearing", mask=Bm, return_params=True) == (
        "BEARING-BA", {"start": "COVIS-SPARSE", "start_params": {"n_rounds": 5},
                       "schur_solver": "cg", "schur_rtol": 1e-3, "gain_tol": 1e-2,
                       "max_rounds": 6})
    assert mappers.default_method(r, sensor="range") == "UNFOLD"  # no scalable default


def test_the_large_default_maps_as_cal_sma_with_sparse_true():
    m = SCALABLE_ABOVE_OBJECTS + 20
    P, rng = _layout(m, seed=3)
    V = rng.uniform(0.0, 2.5, (600, 2))
    X = (np.hypot(*(P[:, None] - V[None]).transpose(2, 0, 1)) < 0.45).astype(float)
    ids = np.arange(4)
    default = build_map(X, ids, P[ids], sensor="visibility")
    named = build_map(X, ids, P[ids], "CAL-SMA", sensor="visibility", sparse=True)
    assert default.method == "CAL-SMA" and default.params == named.params
    np.testing.assert_array_equal(default.positions, named.positions)
