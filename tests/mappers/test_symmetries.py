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

Each property holds exactly in exact arithmetic. In floating point the two maps differ by
rounding, which an iterative solver may carry to a different last iteration before its stop
criterion fires. The solvers of the defaults stop on a relative decrease of their cost (SMACOF's
stress: 1e-6 of it; the adjustments' robust costs: 1e-6 too); the cost is quadratic in the
positions, so one iteration more or less moves the map by up to about sqrt(1e-6) = 1e-3 of its
extent (measured: up to 1.15e-3 for VB-SMA). :data:`TOLERANCE` is therefore 3e-3 of the
layout's extent (the unit square, times ``s`` in (c)): 3 mm on a 1 m layout, a tenth of the
smallest map error the benchmarks quote. A method
whose result depends on the object order, on the frame or on the unit (a random start drawn in
object order or in world axes, a tie split by index, an absolute threshold) moves its map by far
more than that, and the few defaults that still do are marked ``xfail(strict=True)`` in
:data:`KNOWN_FAILURES`, each with the cause.

The default run checks a few hundred cases (derandomized: the same cases on every run, so that CI
is stable); ``-m slow`` checks many more, freshly drawn each run (hypothesis prints the seed of a
failure, to replay it with ``@seed``). A known failure that is not strict (:data:`NOT_STRICT`)
passes whatever its maps do, so it runs with ``-m slow`` only: in the default run it would cost
maps and check nothing.
"""

from __future__ import annotations

import functools
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from synthetic_walk import ANCHORS, history, layout, walk

from mappers import build_map
from mappers.defaults import DEFAULTS

pytestmark = pytest.mark.usefixtures("one_blas_thread")

TOLERANCE = 3e-3
"""Largest difference allowed between the map of the transformed input and the transformed map,
relative to the layout's extent (see the module's docstring for why)."""

EXAMPLES = {
    "range-complete": 50, "range-masked": 30, "bearing+range-complete": 6,
    "bearing+range-masked": 5, "visibility-complete": 6, "bearing-complete": 5,
    "bearing-masked": 4, "bearing+visibility-complete": 3, "visibility-masked": 2,
}
"""Hypothesis examples per symmetry of each default in the default run, fewer where a map takes
longer (VIEW-BA about a second, UNFOLD a few milliseconds): 3 x 111 = 333 cases, of which the
default run checks the 301 that are not :data:`NOT_STRICT` known failures."""

SLOW_FACTOR = 10
"""``-m slow`` checks this many times more examples, freshly drawn."""


def _name(key) -> str:
    sensor, masked = key
    sensor = "+".join(sorted(sensor)) if isinstance(sensor, frozenset) else sensor
    return f"{sensor}-{'masked' if masked else 'complete'}"


KNOWN_FAILURES = {
    ("bearing-complete", "scale"): "BEARING-BA's closed-form resection "
    "(mappers.viewpoints.engine.initial_poses) minimises an algebraic error in unnormalised "
    "world coordinates (no Hartley normalisation), and its steps stop on an absolute tol [m] "
    "and a 1e-12 damping: the viewpoints it starts from, so the adjusted map, depend on the "
    "unit",
    ("bearing-masked", "rigid-motion"): "BEARING-BA: the resection's algebraic error is not "
    "translation or rotation invariant (above), and viewpoints are dropped outside the map's "
    "axis-aligned bounding box, which turns with the frame",
    ("bearing-masked", "scale"): "BEARING-BA: the resection depends on the unit (above)",
    ("range-masked", "rigid-motion"): "RANGE-QUANTILE: when a group of the pair graph holds only "
    "2 anchors the affine fit of SMACOF's start fails and the start is left in classical MDS's "
    "own frame (mappers.masked.pair_maps._initial), not moved with the anchors; a similarity "
    "fit there makes it exact, but may move committed MRCLAM / masked benchmark figures",
    ("bearing-masked", "permutation"): "BEARING-BA from a degenerate COVIS-AUTO start (objects "
    "placed tens of metres off by 3 anchors) depends on the order of the objects and anchors: "
    "not yet traced",
    ("bearing+range-masked", "permutation"): "LOC-SMA draws its random starts in object order "
    "(below): other pairs are dropped as outliers, other objects go unplaced",
    ("bearing+range-masked", "rigid-motion"): "LOC-SMA draws its random starts "
    "(mappers.fused.loc_sma._place_part, when both deterministic starts fold) in world axes and "
    "in object order, so the outlier rounds drop other pairs and other objects go unplaced",
    ("bearing+range-masked", "scale"): "LOC-SMA's outlier rounds (above) on one default case "
    "(params (19, 2947, 30, 601)): the scaled history leaves objects 3, 4, 7 unplaced, the "
    "original more, or the same, depending on the process's rounding (it failed once the 3-D "
    "modules were added, or with lfmdr_gym imported first, and passed before)",
    ("visibility-masked", "permutation"): "VIEW-BA (and its DROPOUT-BLEND start) depends on the "
    "object order: not yet traced",
    ("visibility-masked", "rigid-motion"): "VIEW-BA integrates each viewpoint over a grid of "
    "cells aligned with the world axes (mappers.viewpoints.visibility, _grid over the objects' "
    "bounding box): turning the frame moves the cells relative to the objects (its DROPOUT-BLEND "
    "start passes)",
    ("visibility-masked", "scale"): "VIEW-BA depends on the unit: not traced further; it stops "
    "when no object moves more than tol = 1e-4 m, an absolute length (a likely cause)",
    ("visibility-complete", "permutation"): "CAL-SMA on a few scenes: the maps of the two orders "
    "differ by about 1 cm; not traced (a likely cause: ties between equal distances of 0/1 "
    "histories broken by object order in the neighbour graph). Seen in a full-suite run, not "
    "with the file run alone",
}
"""(default, symmetry) -> why the default breaks it (found by this suite; issue 35). Each is
``xfail(strict=True)`` in the default run (a fix makes the test pass, and the entry must then
go), except those of :data:`NOT_STRICT`, which run with ``-m slow`` only; with ``-m slow`` each is
an xfail that is not strict."""

MISSED_BY_DEFAULT_CASES = {("bearing-complete", "scale"), ("bearing+range-masked", "rigid-motion")}
"""Known failures that the default run's cases happen not to meet (``-m slow``'s and other
draws do)."""

ROUNDING_DEPENDENT = {("bearing+range-masked", "permutation"), ("bearing+range-masked", "scale"),
                      ("visibility-masked", "rigid-motion"),
                      ("visibility-masked", "scale"), ("visibility-complete", "permutation"),
                      ("visibility-masked", "permutation")}
"""Known failures whose default cases pass or fail with the process's floating-point rounding
(BLAS threads, what ran before in the worker): each failed when this file ran alone and passed in
a full-suite run, or the other way round. Not strict, so that the suite's outcome does not depend
on the machine; the entries stay until the cause is fixed."""

NOT_STRICT = MISSED_BY_DEFAULT_CASES | ROUNDING_DEPENDENT
"""Known failures that pass as XPASS as well as XFAIL: they run with ``-m slow`` only."""


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


@functools.lru_cache(maxsize=32)
def _original(key, params):
    """The scene of ``params`` and its default map (or error), kept for the other symmetries of
    the same case (derandomized, the three tests of a default draw the same scenes)."""
    P, X, mask = scene(key, *params)
    return P, X, mask, _build(X, mask, ANCHORS, P[ANCHORS])


def _permutation(data, key, params) -> None:
    P, X, mask, want = _original(key, params)
    m = len(P)
    perm = np.array(data.draw(st.permutations(range(m)), label="perm"))  # new i = old perm[i]
    inv = np.argsort(perm)
    order = np.array(data.draw(st.permutations(range(len(ANCHORS))), label="anchor order"))
    got = _build(_apply(X, lambda s, v: v[perm]), _apply(mask, lambda s, v: v[perm]),
                 inv[ANCHORS][order], P[ANCHORS][order])
    _check_same(got, want, lambda pos, unm: (pos[perm], [int(inv[i]) for i in unm]))


def _rigid_motion(data, key, params) -> None:
    P, X, mask, want = _original(key, params)
    angle = data.draw(st.floats(-np.pi, np.pi), label="angle")
    shift = np.array(data.draw(st.tuples(*[st.floats(-50.0, 50.0)] * 2), label="shift"))
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    got = _build(X, mask, ANCHORS, P[ANCHORS] @ R.T + shift)
    _check_same(got, want, lambda pos, unm: (pos @ R.T + shift, list(unm)))


def _scale(data, key, params) -> None:
    P, X, mask, want = _original(key, params)
    s = data.draw(st.floats(0.05, 20.0), label="scale")
    scaled = _apply(X, lambda sensor, v: v * s if (sensor or key[0]) == "range" else v)
    got = _build(scaled, mask, ANCHORS, P[ANCHORS] * s)
    _check_same(got, want, lambda pos, unm: (pos * s, list(unm)), scale=s)


SYMMETRIES = {"permutation": _permutation, "rigid-motion": _rigid_motion, "scale": _scale}


_PHASES = (Phase.explicit, Phase.reuse, Phase.generate, Phase.target)
"""No shrinking: a case is a few seeds and sizes, reported as they are; shrinking would rebuild
maps for minutes to make them a little smaller."""


def _run(key, symmetry: str, slow: bool) -> None:
    check = SYMMETRIES[symmetry]
    n = EXAMPLES[_name(key)] * (SLOW_FACTOR if slow else 1)

    @settings(max_examples=n, deadline=None, database=None, derandomize=not slow,
              suppress_health_check=[HealthCheck.too_slow], phases=_PHASES)
    @given(params=scene_params(key), data=st.data())
    def test(params, data):
        check(data, key, params)

    test()


def _cases(slow: bool):
    marks = [pytest.mark.slow] if slow else []
    for key in KEYS:
        for symmetry in SYMMETRIES:
            reason = KNOWN_FAILURES.get((_name(key), symmetry))
            if not slow and (_name(key), symmetry) in NOT_STRICT:
                continue  # an xfail that cannot fail: -m slow only
            # strict in the default run, whose cases are the same every run; not with -m slow,
            # whose fresh cases may all miss a rare failure
            strict = not slow
            xfail = [pytest.mark.xfail(strict=strict, reason=reason)] if reason else []
            # a default's symmetries on one worker: they share the cached original maps
            yield pytest.param(key, symmetry, id=f"{_name(key)}-{symmetry}",
                               marks=[*marks, *xfail, pytest.mark.xdist_group(_name(key))])


@pytest.mark.parametrize(("key", "symmetry"), _cases(slow=False))
def test_symmetry(key, symmetry):
    _run(key, symmetry, slow=False)


@pytest.mark.parametrize(("key", "symmetry"), _cases(slow=True))
def test_symmetry_many(key, symmetry):
    _run(key, symmetry, slow=True)
