"""Symmetries every default method must respect, checked on many random synthetic histories
(property-based, with hypothesis; issue 35).

For every row of :data:`mappers.defaults.DEFAULTS` (each sensor and fused set of sensors,
complete and masked histories), on small random layouts sensed from random walks
(``tests/synthetic_walk.py``):

(a) **Object order.** Listing the objects (and the anchors) in another order lists the same map in
    that order: ``map(X[perm])[i] == map(X)[perm[i]]``.
(b) **Rigid motion.** The histories are read in the robot's frame (visibility, ranges, bearings
    relative to its heading), so moving the anchors' known positions by a rotation ``R`` and a
    translation ``t`` moves the whole map by the same motion: ``map'(p) == R p + t``.
(c) **Scale.** Multiplying the ranges and the anchors' positions by ``s`` multiplies the map by
    ``s`` (visibility and bearings have no unit: only the anchors are scaled for them).

Each property holds exactly in exact arithmetic. In floating point the maps differ by rounding,
which the iterative solvers (SMACOF, Gauss-Newton / Levenberg-Marquardt adjustments, eigen-solvers)
may carry over to a different last iteration before their stop criterion fires: the maps then
differ by at most the solver's own tolerance, relative to the map's size. The tolerance
:data:`TOLERANCE` is therefore stated relative to the layout's extent (the unit square, scaled by
``s`` in (c)): 1e-4 of it (0.1 mm on a 1 m layout), ten times looser than the tightest of the
default solvers' relative stop criteria (1e-5), a hundred times tighter than the smallest map error
the benchmarks quote. A method whose result depended on the object order, on the frame or on the
unit (a random start drawn in object order, a tie split by index, an absolute stop criterion) moves
its map by far more than that.

The default run checks a few hundred cases (derandomized: the same cases on every run, so that CI
is stable); ``-m slow`` checks many more, freshly drawn each run (hypothesis prints the seed of a
failure, to replay it with ``@seed``).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from mappers import build_map
from mappers.defaults import DEFAULTS
from synthetic_walk import ANCHORS, history, layout, walk

pytestmark = pytest.mark.usefixtures("one_blas_thread")

TOLERANCE = 1e-4
"""Largest difference allowed between a transformed map and the transformed map, relative to the
layout's extent (see the module's docstring for why)."""

FAST_EXAMPLES = 8
"""Hypothesis examples per (default, symmetry) in the default run: 9 defaults x 3 symmetries x 8
= 216 cases."""

SLOW_EXAMPLES = 60
"""Examples per (default, symmetry) with ``-m slow``."""

_SLOW_DEFAULTS = {("visibility", True)}
"""Defaults whose map takes about a second here (VIEW-BA): fewer examples in the default run."""


def _name(key) -> str:
    sensor, masked = key
    sensor = "+".join(sorted(sensor)) if isinstance(sensor, frozenset) else sensor
    return f"{sensor}-{'masked' if masked else 'complete'}"


KEYS = sorted(DEFAULTS, key=_name)


def _steps(key) -> tuple[int, int]:
    """Range of walk lengths for a default: visibility needs a longer walk (each step says less),
    the others are kept short so a case takes a fraction of a second."""
    sensor, masked = key
    if sensor == "visibility":
        return (70, 100) if masked else (120, 160)
    return (30, 60)


def scene(key, n_objects: int, layout_seed: int, n_steps: int, walk_seed: int):
    """``(P, histories, mask)``: ``n_objects`` objects (:func:`synthetic_walk.layout`) sensed
    from a walk of ``n_steps`` as the default ``key`` reads them."""
    P = layout(n_objects, seed=layout_seed)
    poses = walk(n_steps, seed=walk_seed)
    sensor, masked = key
    kwargs = {"radius": 0.5, "fov_deg": 120.0} if sensor == "visibility" and masked else {}
    if isinstance(sensor, frozenset):
        parts = {s: history(P, poses, s, masked=masked) for s in sorted(sensor)}
        X = {s: part[0] for s, part in parts.items()}
        mask = {s: part[1] for s, part in parts.items()} if masked else None
    else:
        X, mask = history(P, poses, sensor, masked=masked, **kwargs)
    return P, X, mask


def scene_params(key):
    """Random sizes and seeds of a small scene for the default ``key``: the arguments of
    :func:`scene` after ``key`` (15-24 objects), so that a failure is reported in a line."""
    return st.tuples(st.integers(15, 24), st.integers(0, 10_000), st.integers(*_steps(key)),
                     st.integers(0, 10_000))


def _apply(X, f):
    """``f`` applied to a single matrix, or to each matrix of fused histories."""
    if X is None:
        return None
    return {s: f(s, v) for s, v in X.items()} if isinstance(X, dict) else f(None, X)


def _build(X, mask, anchor_ids, anchor_positions):
    """The default map, or the error it raised (which the transformed input must raise too)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return build_map(X, anchor_ids, anchor_positions, mask=mask)
        except ValueError as exc:
            return exc


def _check_same(got, want, transform, scale: float = 1.0) -> None:
    """``got`` (the map of the transformed input) equals ``transform(want)``: the same error kind,
    or the same method, the same unmapped objects (``transform`` of the ids) and positions
    within :data:`TOLERANCE` x ``scale``."""
    if isinstance(want, Exception):
        assert isinstance(got, type(want)), f"original raised {want!r}, transformed gave {got!r}"
        return
    assert not isinstance(got, Exception), f"transformed input raised {got!r}"
    assert got.method == want.method
    positions, unmapped = transform(want.positions, want.unmapped)
    assert sorted(got.unmapped) == sorted(unmapped)
    np.testing.assert_array_equal(np.isnan(got.positions), np.isnan(positions))
    placed = ~np.isnan(positions[:, 0])
    error = np.abs(got.positions[placed] - positions[placed]).max(initial=0.0)
    assert error <= TOLERANCE * scale, (
        f"{want.method}: the maps differ by {error:.3g} (allowed {TOLERANCE * scale:.3g})")


def _permutation(data, key, scene) -> None:
    P, X, mask = scene
    m = len(P)
    perm = np.array(data.draw(st.permutations(range(m)), label="perm"))  # new i = old perm[i]
    inv = np.argsort(perm)
    order = np.array(data.draw(st.permutations(range(len(ANCHORS))), label="anchor order"))
    want = _build(X, mask, ANCHORS, P[ANCHORS])
    got = _build(_apply(X, lambda s, v: v[perm]), _apply(mask, lambda s, v: v[perm]),
                 inv[ANCHORS][order], P[ANCHORS][order])
    _check_same(got, want, lambda pos, unm: (pos[perm], [int(inv[i]) for i in unm]))


def _rigid_motion(data, key, scene) -> None:
    P, X, mask = scene
    angle = data.draw(st.floats(-np.pi, np.pi), label="angle")
    shift = np.array(data.draw(st.tuples(*[st.floats(-50.0, 50.0)] * 2), label="shift"))
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    want = _build(X, mask, ANCHORS, P[ANCHORS])
    got = _build(X, mask, ANCHORS, P[ANCHORS] @ R.T + shift)
    _check_same(got, want, lambda pos, unm: (pos @ R.T + shift, list(unm)))


def _scale(data, key, scene) -> None:
    P, X, mask = scene
    s = data.draw(st.floats(0.05, 20.0), label="scale")
    want = _build(X, mask, ANCHORS, P[ANCHORS])
    scaled = _apply(X, lambda sensor, v: v * s if (sensor or key[0]) == "range" else v)
    got = _build(scaled, mask, ANCHORS, P[ANCHORS] * s)
    _check_same(got, want, lambda pos, unm: (pos * s, list(unm)), scale=s)


SYMMETRIES = {"permutation": _permutation, "rigid-motion": _rigid_motion, "scale": _scale}


_PHASES = (Phase.explicit, Phase.reuse, Phase.generate, Phase.target)
"""No shrinking: a case is a few seeds and sizes, reported as they are; shrinking would rebuild
maps for minutes to make them a little smaller."""


def _run(key, symmetry: str, slow: bool) -> None:
    check = SYMMETRIES[symmetry]
    n = SLOW_EXAMPLES if slow else FAST_EXAMPLES // (2 if key in _SLOW_DEFAULTS else 1)

    @settings(max_examples=n, deadline=None, database=None, derandomize=not slow,
              suppress_health_check=[HealthCheck.too_slow], phases=_PHASES)
    @given(params=scene_params(key), data=st.data())
    def test(params, data):
        check(data, key, scene(key, *params))

    test()


@pytest.mark.parametrize("symmetry", list(SYMMETRIES))
@pytest.mark.parametrize("key", KEYS, ids=_name)
def test_symmetry(key, symmetry):
    _run(key, symmetry, slow=False)


@pytest.mark.slow
@pytest.mark.parametrize("symmetry", list(SYMMETRIES))
@pytest.mark.parametrize("key", KEYS, ids=_name)
def test_symmetry_many(key, symmetry):
    _run(key, symmetry, slow=True)
