"""The registry of the ten methods, and each method recovering a known layout."""

import numpy as np
import pytest

from mappers import (
    DEFAULT_METHODS,
    METHODS,
    LaplacianEigenmap,
    LocallyLinear,
    MethodSpec,
    apply_affine,
    fit_affine,
    mean_position_error,
    register_method,
)
from mappers.catalog import _METHODS

LABELS = ["LPCA", "SMA(UNWGT)", "SMA(WGT)", "KPCA(GAUS)", "KPCA(POLY)", "ISOMAP", "LLE", "LEM", "HLLE", "SDE"]


def make_histories(n_objects=40, n_steps=1500, sensor="visibility", seed=0):
    """Histories of known 2-D points: visibility (distance < 0.55 m) or bearing (cos, sin) seen
    from random robot positions and headings. Returns (row-normalised histories, positions)."""
    rng = np.random.default_rng(seed)
    g = np.linspace(-1.0, 1.0, 7)
    grid = np.array([(x, y) for x in g for y in g])
    P = grid[rng.choice(len(grid), n_objects, replace=False)] + rng.uniform(-0.08, 0.08, (n_objects, 2))
    R = rng.uniform(-1.25, 1.25, (n_steps, 2))
    d = P[:, None, :] - R[None, :, :]
    if sensor == "visibility":
        H = (np.hypot(d[..., 0], d[..., 1]) < 0.55).astype(float)
    else:
        th = np.arctan2(d[..., 1], d[..., 0]) - rng.uniform(-np.pi, np.pi, n_steps)[None]
        H = np.stack([np.cos(th), np.sin(th)], -1).reshape(n_objects, -1)
    return H / np.linalg.norm(H, axis=1, keepdims=True), P


def test_registry_labels_defaults_grids():
    assert list(METHODS)[:10] == LABELS
    assert METHODS["SMA(WGT)"].defaults == {"n_neighbors": 5}
    assert METHODS["KPCA(GAUS)"].defaults == {"sigma2": 0.5}
    assert METHODS["KPCA(POLY)"].defaults == {"degree": 8}
    assert {lab: METHODS[lab].defaults["n_neighbors"] for lab in ["ISOMAP", "LLE", "LEM", "HLLE", "SDE"]} == {
        "ISOMAP": 6, "LLE": 8, "LEM": 6, "HLLE": 8, "SDE": 7,
    }
    assert METHODS["LPCA"].grid == {} and METHODS["SMA(UNWGT)"].grid == {}
    assert METHODS["SDE"].grid == {"n_neighbors": [4, 5, 6, 7, 8, 9, 10, 11, 12]}
    assert METHODS["KPCA(GAUS)"].grid == {"sigma2": [0.25, 0.5, 1.0, 2.0, 4.0, 8.0]}
    assert METHODS["KPCA(POLY)"].grid == {"degree": [2, 4, 8]}
    assert METHODS["HLLE"].grid == {"n_neighbors": [6, 7, 8, 9, 10, 11, 12]}  # K > 5 needed in 2-D
    single = {key for key in DEFAULT_METHODS if isinstance(key[0], str)}
    assert single == {(s, masked) for s in ("visibility", "bearing", "range")
                      for masked in (False, True)}
    assert set(DEFAULT_METHODS) - single <= {(frozenset(f), masked) for f in (
        ("range", "bearing"), ("visibility", "bearing")) for masked in (False, True)}
    assert all(METHODS[m].accepts(s, masked) for (s, masked), m in DEFAULT_METHODS.items())


def test_register_method_and_unknown_parameter():
    spec = MethodSpec("TEST-ID", lambda scale=1.0: None, {"scale": 2.0}, {"scale": [1.0, 2.0]})
    try:
        register_method(spec)
        assert list(METHODS)[-1] == "TEST-ID"
        with pytest.raises(ValueError, match="already registered"):
            register_method(spec)
        register_method(spec, replace=True)
    finally:
        _METHODS.pop("TEST-ID", None)
    with pytest.raises(ValueError, match="not accepted"):
        register_method(MethodSpec("BAD", lambda: None, {"k": 1}))
    with pytest.raises(ValueError, match=r"unknown parameter.*'sigma'"):
        METHODS["KPCA(GAUS)"].build(sigma=1.0)
    with pytest.raises(ValueError, match="sigma2"):
        METHODS["KPCA(GAUS)"].build(sigma2=0.0)


# MPE after the best affine fit, metres, for objects spread over 2 m x 2 m; a random embedding
# scores ~0.85. Measured on these seeds (bearing / visibility):
# LPCA .08/.32, SMA(UNWGT) .06/.12, SMA(WGT) .04/.07, KPCA(GAUS) .17/.34, KPCA(POLY) .25/.55,
# ISOMAP .06/.09, LLE .10/.15, LEM .20/.20, HLLE .04/.12, SDE .05/.09.
TOLERANCE = {
    "bearing": {"LPCA": 0.15, "SMA(UNWGT)": 0.1, "SMA(WGT)": 0.08, "KPCA(GAUS)": 0.3,
                "KPCA(POLY)": 0.4, "ISOMAP": 0.12, "LLE": 0.18, "LEM": 0.3, "HLLE": 0.08, "SDE": 0.1},
    "visibility": {"SMA(UNWGT)": 0.2, "SMA(WGT)": 0.12, "ISOMAP": 0.16, "LLE": 0.25, "LEM": 0.32,
                   "HLLE": 0.2, "SDE": 0.15},
}


@pytest.mark.parametrize(
    "sensor, label", [(s, lab) for s in TOLERANCE for lab in TOLERANCE[s]]
)
def test_method_recovers_layout(sensor, label):
    X, P = make_histories(sensor=sensor)
    Y = METHODS[label].build().fit_transform(X)
    assert Y.shape == (len(P), 2)
    err = mean_position_error(apply_affine(Y, fit_affine(Y, P)), P)
    assert err < TOLERANCE[sensor][label], err


@pytest.mark.parametrize("label", LABELS)
def test_methods_are_deterministic(label):
    X, _ = make_histories(n_objects=25, n_steps=400, sensor="bearing", seed=3)
    a = METHODS[label].build().fit_transform(X)
    b = METHODS[label].build().fit_transform(X)
    np.testing.assert_allclose(a, b, atol=1e-8)


def test_lle_signs_fixed_and_errors():
    X, _ = make_histories(n_objects=25, n_steps=400, seed=4)
    Y = LocallyLinear(n_neighbors=8).fit_transform(X)
    top = Y[np.argmax(np.abs(Y), axis=0), [0, 1]]
    assert np.all(top > 0)
    with pytest.raises(ValueError, match=r"n_neighbors > .* = 5"):
        LocallyLinear(n_neighbors=5, method="hessian").fit(X)
    with pytest.raises(ValueError, match="must be < number of points"):
        LocallyLinear(n_neighbors=30).fit(X)
    with pytest.raises(ValueError, match="must be < number of points"):
        LaplacianEigenmap(n_neighbors=25).fit(X)


@pytest.mark.parametrize(
    "X, cause",
    [
        (np.arange(20.0)[:, None], "output dimension"),  # 1-D data cannot give 2 components
    ],
)
def test_hessian_lle_eigenproblem_failure_is_a_clear_error(X, cause):
    with pytest.raises(ValueError, match=f"Hessian LLE eigenproblem failed: .*{cause}"):
        LocallyLinear(n_neighbors=8, method="hessian").fit(X)
