"""build_map: the whole pipeline, unmapped objects, sensor inference, and every bad input."""

import re
from types import SimpleNamespace

import numpy as np
import pytest

from mappers import (
    DEFAULT_METHODS,
    METHODS,
    MappingError,
    MethodSpec,
    build_map,
    infer_sensor,
    mean_position_error,
    register_method,
)
from mappers.catalog import _METHODS


def world(n_objects=40, n_steps=1200, seed=0, sensor="visibility"):
    """Raw (unnormalised) histories of known points, corner anchors and their positions."""
    rng = np.random.default_rng(seed)
    g = np.linspace(-1.0, 1.0, 7)
    grid = np.array([(x, y) for x in g for y in g])
    idx = np.concatenate([[0, 6, 42, 48], rng.choice(np.arange(1, 42), n_objects - 4, replace=False)])
    P = grid[idx] + rng.uniform(-0.05, 0.05, (n_objects, 2))
    R = rng.uniform(-1.25, 1.25, (n_steps, 2))
    d = P[:, None, :] - R[None]
    dist = np.hypot(d[..., 0], d[..., 1])
    if sensor == "visibility":
        H = (dist < 0.55).astype(float)
    elif sensor == "bearing":
        th = np.arctan2(d[..., 1], d[..., 0]) - rng.uniform(-np.pi, np.pi, n_steps)[None]
        H = np.stack([np.cos(th), np.sin(th)], -1).reshape(n_objects, -1)
    else:
        H = dist
    anchors = np.array([0, 1, 2, 3])
    return H, P, anchors


@pytest.mark.parametrize("sensor", ["visibility", "bearing", "range"])
def test_default_method_maps_each_sensor(sensor):
    H, P, a = world(sensor=sensor)
    m = build_map(H, a, P[a])
    assert m.sensor == sensor and m.method == DEFAULT_METHODS[(sensor, False)]
    assert m.positions.shape == (40, 2) and m.unmapped == ()
    assert np.all(np.isfinite(m.positions))
    m = build_map(H, a, P[a], "SMA(WGT)")
    assert m.params["n_neighbors"] == 5
    assert mean_position_error(m.positions, P, exclude=a) < 0.25
    np.testing.assert_allclose(m.positions, np.column_stack([m.embedding, np.ones(40)]) @ m.affine)


@pytest.mark.parametrize("label", list(METHODS)[:10])
def test_every_method_through_build_map(label):
    H, P, a = world(sensor="bearing", n_steps=600)
    m = build_map(H, a, P[a], label)
    assert m.method == label
    assert np.all(np.isfinite(m.positions))
    # anchor fit only (4 corners); measured: KPCA(POLY) 0.61, KPCA(GAUS) 0.44, LEM 0.37,
    # LLE 0.24, LPCA 0.19, SMA(UNWGT) 0.13, ISOMAP 0.14, SDE 0.12, SMA(WGT) 0.10, HLLE 0.08
    limit = {"KPCA(POLY)": 0.8, "KPCA(GAUS)": 0.6, "LEM": 0.55, "LLE": 0.35, "LPCA": 0.3}
    limit = limit.get(label, 0.2)
    assert mean_position_error(m.positions, P, exclude=a) < limit


def test_empty_history_is_unmapped_and_others_still_mapped():
    H, P, a = world()
    H[[7, 19]] = 0.0
    m = build_map(H, a, P[a], "ISOMAP")
    assert m.unmapped == (7, 19)
    assert np.all(np.isnan(m.positions[[7, 19]])) and np.all(np.isnan(m.embedding[[7, 19]]))
    assert mean_position_error(m.positions, P, exclude=[*a, *m.unmapped]) < 0.25


def test_unmapped_anchor_warns_or_fails():
    H, P, _ = world()
    a = np.array([0, 1, 2, 3, 10])
    H[2] = 0.0
    m = build_map(H, a, P[a], "SMA(WGT)")
    assert m.unmapped == (2,) and m.anchor_ids == (0, 1, 3, 10)
    assert any("anchors [2]" in w for w in m.warnings)
    H[3] = 0.0
    H[10] = 0.0
    with pytest.raises(ValueError, match="only 2 anchors remain"):
        build_map(H, a, P[a])


def test_normalize_switch_and_history_like_object():
    H, P, a = world()
    H = H * np.arange(1, 41)[:, None]  # objects seen "more easily" have larger rows
    on = build_map(H, a, P[a], "SMA(UNWGT)")
    off = build_map(H, a, P[a], "SMA(UNWGT)", normalize=False)
    assert not np.allclose(on.positions, off.positions)
    assert on.sensor == "range"  # not 0/1 any more
    assert build_map(H, a, P[a], "SMA(UNWGT)", sensor="visibility").sensor == "visibility"
    hist = SimpleNamespace(matrix=(H > 0).astype(float), sensor="visibility", mask=None)
    assert build_map(hist, a, P[a], "LPCA").sensor == "visibility"


def test_infer_sensor():
    assert infer_sensor(np.array([[0, 1], [1, 1.0]])) == "visibility"
    th = np.array([[0.3, 1.2], [2.0, -1.0]])
    bearing = np.stack([np.cos(th), np.sin(th)], -1).reshape(2, 4)
    assert infer_sensor(bearing) == "bearing"
    assert infer_sensor(np.array([[0.3, 1.2, 0.5], [2.0, 0.0, 1.0]])) == "range"


def test_infer_sensor_of_a_sparse_history_reads_the_stored_values_only(monkeypatch):
    """The sparse inference agrees with the dense one and never builds the dense matrix."""
    import scipy.sparse as sp

    rng = np.random.default_rng(0)
    th = rng.uniform(-np.pi, np.pi, (6, 5))
    bearing = np.stack([np.cos(th), np.sin(th)], -1).reshape(6, 10)
    bearing[:, 4:6] = 0.0  # a step with nothing sensed
    bearing[0, 0:2] = (0.0, 1.0)  # cos exactly 0: one stored value in the pair
    ranges = np.where(rng.random((6, 5)) < 0.5, rng.uniform(0.1, 2.0, (6, 5)), 0.0)
    vis = (rng.random((6, 4)) < 0.4).astype(float)
    cases = [(vis, "visibility"), (bearing, "bearing"), (ranges, "range"),
             (ranges[:, :4], "range")]  # an even number of range columns is still range
    for dense, _ in cases:
        assert infer_sensor(sp.csr_array(dense)) == infer_sensor(dense)

    def refuse(self, *args, **kwargs):
        raise AssertionError("the sparse history was densified")

    monkeypatch.setattr(sp.csr_array, "toarray", refuse)
    monkeypatch.setattr(sp.csr_array, "todense", refuse)
    for dense, expected in cases:
        assert infer_sensor(sp.csr_array(dense)) == expected
    B, _, _ = world(sensor="bearing", n_steps=300)
    # build_map's input check, where the sensor is inferred
    from mappers.fitting import check_inputs

    assert check_inputs(sp.csr_array(B), None, None, None)[2] == "bearing"


def _angles_and_mask(seed=0):
    """Bearings as an (M, N) matrix of angles [rad] (the wrong form) and an (M, N) mask."""
    H, P, a = world(sensor="bearing", n_steps=300, seed=seed)
    angles = np.arctan2(H[:, 1::2], H[:, 0::2])
    mask = np.random.default_rng(seed).random(angles.shape) < 0.7
    return np.where(mask, angles, 0.0), mask, P, a


ANGLES_HINT = r"np\.stack\(\[np\.cos\(a\), np\.sin\(a\)\], axis=-1\)\.reshape\(M, 2 \* N\)"


def test_bearings_in_radians_are_refused_with_the_way_to_pass_them():
    import scipy.sparse as sp

    A, mask, P, a = _angles_and_mask()
    assert (A[mask] < 0).any()
    for call in (lambda: build_map(A, a, P[a], mask=mask), lambda: build_map(A, a, P[a]),
                 lambda: build_map(sp.csr_array(A), a, P[a]),
                 lambda: build_map(sp.csr_array(A), a, P[a], mask=sp.csr_array(mask)),
                 lambda: infer_sensor(A, mask), lambda: infer_sensor(sp.csr_array(A))):
        with pytest.raises(ValueError, match=r"range histories must be >= 0") as err:
            call()
        assert re.search(ANGLES_HINT, str(err.value)) and "sensor='bearing'" in str(err.value)
        assert "np.repeat(mask, 2, axis=1)" in str(err.value)
    # what the message says to do maps them
    M, N = A.shape
    X = np.stack([np.cos(A), np.sin(A)], axis=-1).reshape(M, 2 * N)
    m = build_map(X, a, P[a], mask=np.repeat(mask, 2, axis=1))
    assert m.sensor == "bearing" and mean_position_error(m.positions, P, exclude=a) < 0.25


def test_a_negative_range_is_refused_even_when_the_sensor_is_given():
    import scipy.sparse as sp

    R, P, a = world(sensor="range", n_steps=300)
    R[5, 17] = -0.25
    for X in (R, sp.csr_array(R)):
        for sensor in (None, "range"):
            with pytest.raises(ValueError, match=r"range histories must be >= 0, got 1 negative"):
                build_map(X, a, P[a], "SMA(WGT)", sensor=sensor)
    mask = np.ones(R.shape, dtype=bool)
    mask[5, 17] = False  # an unobserved entry may hold anything
    assert build_map(R, a, P[a], sensor="range", mask=mask).sensor == "range"
    with pytest.raises(ValueError, match=r"range histories must be >= 0"):  # fused: the same
        B, _, _ = world(sensor="bearing", n_steps=300)
        build_map({"range": R, "bearing": B}, a, P[a])


@pytest.mark.parametrize("sensor", ["visibility", "bearing", "range"])
def test_valid_histories_keep_their_sensor(sensor):
    import scipy.sparse as sp

    from mappers.core.sensors import check_values

    H, _, _ = world(sensor=sensor, n_steps=300)
    mask = np.random.default_rng(1).random(H.shape) < 0.8
    if sensor == "bearing":
        mask = np.repeat(mask[:, ::2], 2, axis=1)
    for X, m in ((H, None), (np.where(mask, H, 0.0), mask), (sp.csr_array(H), None)):
        assert infer_sensor(X, m) == sensor
        assert check_values(X, m, None) == sensor
        assert check_values(X, m, sensor) == sensor


def test_mask_all_true_is_no_mask():
    H, P, a = world()
    m1 = build_map(H, a, P[a], "LEM")
    m2 = build_map(H, a, P[a], "LEM", mask=np.ones(H.shape, dtype=bool))
    np.testing.assert_array_equal(m1.positions, m2.positions)


class _RecordingMasked:
    """A masked-history method for tests: records what build_map hands it."""

    calls: list = []
    nan_rows: tuple = ()

    def __init__(self, P):
        self.P = P

    def fit_transform(self, X, mask=None, *, sensor, anchor_ids, anchor_positions):
        self.calls.append((X.shape, None if mask is None else mask.shape, sensor, anchor_ids,
                           anchor_positions))
        Y = 2.0 * np.delete(self.P, 9, axis=0) + 1.0  # an exact (affine) embedding of the others
        Y[list(self.nan_rows)] = np.nan
        return Y


def test_partial_mask_goes_to_a_method_for_masked_histories():
    H, P, a = world()
    spec = MethodSpec("MASKED-TEST", lambda: _RecordingMasked(P), uses_anchors=True,
                      normalize=False, histories=("masked",))
    register_method(spec)
    try:
        H[9] = 0.0  # unmapped: not handed to the method
        mask = np.ones(H.shape, dtype=bool)
        mask[5, :10] = False
        H[5, :10] = np.nan  # unobserved entries may hold anything
        with pytest.raises(ValueError, match=r"does not map masked visibility.*MASKED-TEST"):
            build_map(H, a, P[a], "SMA(WGT)", mask=mask)  # a label that does not fit
        m = build_map(H, a, P[a], "masked-test", mask=mask)  # labels are case-insensitive
        (xs, ms, sens, ids, pos), = _RecordingMasked.calls
        assert (xs, ms, sens) == ((39, 1200), (39, 1200), "visibility")
        # anchors go to the method as rows of the mapped objects (object 9 is not handed over)
        np.testing.assert_array_equal(ids, np.searchsorted(np.delete(np.arange(40), 9), a))
        np.testing.assert_array_equal(pos, P[a])
        assert m.method == "MASKED-TEST" and m.unmapped == (9,)
        np.testing.assert_allclose(np.delete(m.positions, 9, axis=0), np.delete(P, 9, axis=0), atol=1e-9)
        with pytest.raises(ValueError, match="does not map complete"):
            build_map(np.nan_to_num(H), a, P[a], "MASKED-TEST")  # masked histories only

        # NaN rows from the method: those objects (here object 5 and anchor 2) become unmapped
        _RecordingMasked.nan_rows = (2, 5)  # rows of mapped objects 2 and 5 (9 is not handed over)
        a5 = np.array([0, 1, 2, 3, 20])
        m = build_map(H, a5, P[a5], "MASKED-TEST", mask=mask)
        assert m.unmapped == (2, 5, 9) and m.anchor_ids == (0, 1, 3, 20)
        assert np.all(np.isnan(m.positions[[2, 5, 9]]))
        assert any("could not be placed" in w for w in m.warnings)
    finally:
        _METHODS.pop("MASKED-TEST")
        _RecordingMasked.calls, _RecordingMasked.nan_rows = [], ()


def test_masked_default_per_sensor_and_a_method_registered_by_a_user_works_with_masks():
    H, P, a = world()
    mask = H > 0
    # a mask that says only what was seen is a log of sightings (its own default,
    # tests/mappers/test_sightings_log.py); one with objects in view but not seen is a view's
    mask[:, ::7] = True
    m = build_map(H, a, P[a], mask=mask)
    assert m.method == DEFAULT_METHODS[("visibility", True)] == "VIEW-BA"
    assert mean_position_error(m.positions, P, exclude=a) < 0.3


def test_method_failure_is_a_mapping_error_naming_method():
    class Broken:
        def fit_transform(self, X):
            raise np.linalg.LinAlgError("Singular matrix")

    register_method(MethodSpec("BROKEN-TEST", lambda: Broken()))
    try:
        H, P, a = world()
        with pytest.raises(MappingError, match=r"'BROKEN-TEST' failed: LinAlgError: Singular"):
            build_map(H, a, P[a], "BROKEN-TEST")
    finally:
        _METHODS.pop("BROKEN-TEST")


def test_collinear_embedding_of_anchors_is_a_mapping_error():
    H, P, a = world()
    register_method(MethodSpec("LINE-TEST", lambda: SimpleNamespace(
        fit_transform=lambda X: np.column_stack([np.arange(len(X)), np.arange(len(X))]).astype(float)
    )))
    try:
        with pytest.raises(MappingError, match="collinear"):
            build_map(H, a, P[a], "LINE-TEST")
    finally:
        _METHODS.pop("LINE-TEST")


def test_disconnected_graph_is_repaired_and_reported():
    H, P, a = world()
    # two groups of objects that are never seen together
    H2 = np.zeros((40, 2400))
    H2[:20, :1200] = H[:20]
    H2[20:, 1200:] = H[20:]
    m = build_map(H2, [0, 1, 2, 25], P[[0, 1, 2, 25]], "LEM", n_neighbors=4)
    assert any("GraphRepairWarning" in w and "joined" in w for w in m.warnings)


def test_hessian_lle_k_too_small_is_clear():
    H, P, a = world()
    with pytest.raises(MappingError, match=r"'HLLE' failed: .*n_neighbors > "):
        build_map(H, a, P[a], "HLLE", n_neighbors=5)


H0, P0, A0 = world(n_steps=300)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(anchor_ids=[0, 1]), "at least 3 anchors"),
        (dict(anchor_ids=[0, 1, 2], anchor_positions=[[0, 0], [1, 1], [2, 2]]), "collinear"),
        (dict(anchor_ids=[0, 1, 40], anchor_positions=P0[:3]), "out of range"),
        (dict(anchor_ids=[0, 1, -1], anchor_positions=P0[:3]), "out of range"),
        (dict(anchor_ids=[0, 1, 1], anchor_positions=P0[:3]), "duplicates"),
        (dict(anchor_ids=[0.0, 1.0, 2.0], anchor_positions=P0[:3]), "integer"),
        (dict(anchor_positions=P0[:3]), r"shape \(4, 2\)"),
        (dict(anchor_positions=np.full((4, 2), np.nan)), "NaN"),
        (dict(histories=np.where(np.eye(40, 300) > 0, np.nan, H0)), "NaN or inf"),
        (dict(histories=np.where(np.eye(40, 300) > 0, np.inf, H0)), "NaN or inf"),
        (dict(histories=H0[0]), "2-D"),
        (dict(histories=H0[:2]), "at least 3 objects"),
        (dict(histories=[["a", "b"]] * 5), "numeric"),
        (dict(method="PCA"), "unknown method 'PCA'"),
        (dict(method="ISOMAP", K=6), r"unknown parameter\(s\) \['K'\]"),
        (dict(method="ISOMAP", n_neighbors=40), "n_neighbors must be an integer in"),
        (dict(method="ISOMAP", n_neighbors=0), "n_neighbors must be an integer in"),
        (dict(method="ISOMAP", n_neighbors=2.5), "n_neighbors must be an integer in"),
        (dict(method="KPCA(GAUS)", sigma2=-1.0), "sigma2 must be > 0"),
        (dict(sensor="sonar"), "sensor must be one of"),
        (dict(histories=H0[:, :299], sensor="bearing"), "even number of columns"),
        (dict(mask=np.ones((40, 300))), "boolean"),
        (dict(mask=np.ones((40, 299), dtype=bool)), "shape"),
    ],
)
def test_bad_input_raises_value_error_naming_problem(kwargs, match):
    args = dict(histories=H0, anchor_ids=A0, anchor_positions=P0[A0])
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        build_map(**args)


def test_labels_are_matched_case_insensitively_and_reported_canonically():
    rng = np.random.default_rng(4)
    P = rng.uniform(-1, 1, (30, 2))
    P[:4] = [(-1, -1), (1, -1), (-1, 1), (1, 1)]  # anchors at the corners
    robot = rng.uniform(-1.2, 1.2, (800, 2))
    H = (np.linalg.norm(P[:, None] - robot[None], axis=2) < 0.6).astype(float)
    a = np.arange(4)
    m = build_map(H, a, P[a], "isomap", n_neighbors=7)
    assert m.method == "ISOMAP" and m.params["n_neighbors"] == 7
    assert build_map(H, a, P[a], " Cal-Sma ").method == "CAL-SMA"
