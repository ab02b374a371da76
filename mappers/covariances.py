"""``Map.covariances``: each object's position uncertainty, for ``build_map(uncertainty=...)``.

Two sources, chosen by ``uncertainty``:

* ``"model"`` — from the normal equations of a bundle adjustment, where the method ends with one
  (``BEARING-BA``, ``LOC-SMA`` refined by its range-bearing or bearing adjustment, and in 3-D
  ``SPATIAL-BA``): the objects' marginal covariances with the viewpoints eliminated and the
  anchors fixed, scaled by the robustly weighted residuals' variance
  (:mod:`mappers.viewpoints.marginals`, :mod:`mappers.spatial.marginals`);
* ``"jackknife"`` — for the dense CAL-SMA of visibility histories (the visibility default): a
  block jackknife over the steps whose replicates are carried to the map by the weighted stress
  minimiser's linear response, not re-embedded
  (:mod:`mappers.calibrated.cal_sma_uncertainty`, :mod:`mappers.smacof.stress_covariance`),
  widened by :data:`JACKKNIFE_INFLATION`; a fraction of one map's time;
* ``"bootstrap"`` — for every method: a moving-block bootstrap over the history's steps
  (Künsch 1989; blocks of ``ceil(sqrt(N))`` consecutive steps, since consecutive steps of a walk
  see nearly the same scene), :data:`BOOTSTRAP_REPLICATES` replicate histories each mapped by
  the same method with the same anchors (each replicate's anchor fit aligns it to the anchors),
  the covariance of the replicates' positions widened by
  :func:`mappers.core.uncertainty.sample_size_factor` for the few replicates it comes from, and
  by :data:`BOOTSTRAP_INFLATION` for the method's bias, which resampling cannot see.

``True`` is ``"model"`` where there is one, else ``"jackknife"`` where it applies, else
``"bootstrap"``; ``build_map`` then adds to the model's the systematic floor the map's anchors,
each released from the adjustment in turn, estimate (:func:`with_held_out_floor`, issue 35: the
model alone cannot see a logged run's calibration errors). The covariances are in the
map's frame (a method's embedding carried by the anchor fit's linear part), zero for the anchors
(taken as exact: they fix the frame), NaN for unmapped objects. A bootstrap costs about
``BOOTSTRAP_REPLICATES`` maps; the model and the jackknife a small fraction of one
(docs/guide/uncertainty.md).
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from mappers.calibrated import has_linear_jackknife, linear_jackknife_covariances
from mappers.core.errors import MappingError
from mappers.core.held_out_anchors import held_out_factor, held_out_floor
from mappers.core.threads import thread_limit
from mappers.core.uncertainty import (
    SYSTEMATIC_FLOOR,
    check_uncertainty,
    mahalanobis_squared,
    moving_blocks,
    sample_covariances,
    sample_size_factor,
    systematic_floor,
    transform_covariances,
)
from mappers.fitting import Map
from mappers.spatial.marginals import spatial_covariances
from mappers.spatial.spatial_ba import SpatialAdjustment
from mappers.viewpoints import adjustment_covariances
from mappers.viewpoints import has_model_covariances as _has_planar_model

__all__ = ["BOOTSTRAP_INFLATION", "BOOTSTRAP_REPLICATES", "JACKKNIFE_INFLATION", "MIN_REPLICATES",
           "SINGLE_THREAD_MAX_OBJECTS", "covariance_threads", "has_model_covariances",
           "with_covariances", "with_held_out_check", "with_held_out_floor",
           "with_model_covariances"]

BOOTSTRAP_REPLICATES = 20
"""Replicate maps of a bootstrap."""

BOOTSTRAP_INFLATION = 1.7
"""Factor on every bootstrap covariance for what resampling cannot see (the method's bias):
the factor that put 95 % of the landmarks inside their regions (1.697) on a second, independent
simulator's visibility histories (``benchmarks/bench_uncertainty.py --sets
visibility-other-sim --seed0 13000 --layouts 15``, run with the factor at 1), confirmed on fresh
layouts of the project's world (``--sets visibility``; docs/guide/uncertainty.md)."""

JACKKNIFE_INFLATION = 4.63
"""Factor on every linearised-jackknife covariance (``"jackknife"``) for what the linearisation
and the resampling cannot see (new neighbour pairs, a refitted calibration, the method's bias):
the factor that put 95 % of the landmarks inside their regions (4.627; 0.606 inside without it)
on the second simulator's visibility histories (``benchmarks/bench_uncertainty.py --sets
visibility-other-sim --seed0 13000 --layouts 15 --no-inflation``, the bootstrap's body of
data), confirmed on fresh layouts of the project's world (``--sets visibility``) and on fresh
layouts of the second simulator (``--seed0 13100 --layouts 25``; docs/guide/uncertainty.md)."""

MIN_REPLICATES = 10
"""An object placed in fewer replicates gets a NaN covariance (and a note)."""


SINGLE_THREAD_MAX_OBJECTS = 500
"""Up to this many objects the covariances are computed with one BLAS thread, as the maps are
(:mod:`mappers.fitting`): their matrices are small, and more threads only spin on a shared
machine's cores (on a 50-object bearing map of 1,000 steps they made the model's
covariances cost about five times the CPU time)."""


def covariance_threads(n_objects: int):
    """The BLAS thread limit (:func:`mappers.core.threads.thread_limit`) the covariances of a
    map of ``n_objects`` are computed under: one thread up to
    :data:`SINGLE_THREAD_MAX_OBJECTS`, else the libraries decide."""
    return thread_limit(1 if n_objects <= SINGLE_THREAD_MAX_OBJECTS else None)


def has_model_covariances(est) -> bool:
    """Whether the fitted estimator ``est`` ends with a bundle adjustment whose normal equations
    give covariances: BEARING-BA, LOC-SMA refined by an adjustment, SPATIAL-BA (3-D)."""
    return isinstance(est, SpatialAdjustment) or _has_planar_model(est)


def _finish(result: Map, cov: np.ndarray) -> np.ndarray:
    cov = np.array(cov, dtype=float)
    cov[list(result.anchor_ids)] = 0.0
    cov[list(result.unmapped)] = np.nan
    return cov


def _rows(a, rows):
    """The ``rows`` of an array, of each array of a mapping (None stays None)."""
    if isinstance(a, dict):
        return {k: _rows(v, rows) for k, v in a.items()}
    return None if a is None else a[rows]


def _model(result: Map, est, mapped: np.ndarray, X, mask, timeline) -> np.ndarray:
    if isinstance(est, SpatialAdjustment):  # 3-D: every row fitted, in the output frame
        return spatial_covariances(est)
    local = np.searchsorted(mapped, np.asarray(result.anchor_ids, dtype=int))
    cov_local = adjustment_covariances(est, X, mask, local, timeline)
    d = result.positions.shape[1]
    cov = np.full((len(result.positions), d, d), np.nan)
    cov[mapped] = cov_local
    return transform_covariances(cov, np.asarray(result.affine)[:d])


def _jackknife(result: Map, est, mapped: np.ndarray, X, n_steps: int,
               notes: list[str]) -> np.ndarray:
    local = np.searchsorted(mapped, np.asarray(result.anchor_ids, dtype=int))
    cov_local, few = linear_jackknife_covariances(est, np.asarray(X)[mapped], n_steps, local)
    if few.any():
        notes.append(f"uncertainty: objects {mapped[few].tolist()} were seen in fewer than two "
                     "of the jackknife's blocks of steps: their covariance is NaN")
    d = result.positions.shape[1]
    cov = np.full((len(result.positions), d, d), np.nan)
    cov[mapped] = cov_local * JACKKNIFE_INFLATION
    return transform_covariances(cov, np.asarray(result.affine)[:d])


def _bootstrap(result: Map, n_steps: int, refit: Callable[[np.ndarray], np.ndarray],
               random_state, notes: list[str]) -> np.ndarray:
    rng = np.random.default_rng(random_state)
    block = max(1, math.ceil(math.sqrt(n_steps)))
    reps, failed = [], 0
    for _ in range(BOOTSTRAP_REPLICATES):
        steps = moving_blocks(n_steps, block, rng)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # a replicate's notes are the full map's, again
                reps.append(refit(steps))
        except (MappingError, ValueError):
            failed += 1
    if failed:
        notes.append(f"uncertainty: {failed} of {BOOTSTRAP_REPLICATES} bootstrap replicates "
                     "could not be mapped")
    d = result.positions.shape[1]
    if len(reps) < MIN_REPLICATES:
        raise MappingError(f"uncertainty: only {len(reps)} of {BOOTSTRAP_REPLICATES} bootstrap "
                           f"replicates could be mapped (at least {MIN_REPLICATES} needed)")
    cov = (sample_covariances(np.stack(reps), MIN_REPLICATES)
           * sample_size_factor(len(reps), d) * BOOTSTRAP_INFLATION)
    few = [i for i in np.flatnonzero(np.isnan(cov[:, 0, 0])) if i not in result.unmapped]
    if few:
        notes.append(f"uncertainty: objects {few} were placed in fewer than {MIN_REPLICATES} "
                     "bootstrap replicates: their covariance is NaN")
    return cov


def with_covariances(result: Map, uncertainty, *, est: Any, mapped: np.ndarray, X: Any,
                     mask: Any, n_steps: int, refit: Callable[[np.ndarray], np.ndarray],
                     random_state, timeline=None) -> Map:
    """``result`` with its ``covariances`` (module docstring) for ``uncertainty`` (False: the map
    as it is). ``est`` is the fitted estimator, ``mapped`` the rows it was fitted on, ``X`` and
    ``mask`` what it was fitted on (all rows; a mapping per sensor for fused histories);
    ``refit(steps)`` maps the history restricted to those steps (with repeats) and returns the
    (M, d) positions; ``timeline`` the steps' (robot, tick), or None. ValueError for an unknown
    mode, ``"model"`` for a method without one, or ``"jackknife"`` for a map it does not cover."""
    mode = check_uncertainty(uncertainty)
    if mode is False:
        return result
    with covariance_threads(len(result.positions)):
        return _with_covariances(result, mode, est, mapped, X, mask, n_steps, refit,
                                 random_state, timeline)


def _with_covariances(result, mode, est, mapped, X, mask, n_steps, refit, random_state,
                      timeline) -> Map:
    jackknife = has_linear_jackknife(est) and mask is None and not isinstance(X, dict)
    if mode in (True, "anchors"):  # ("anchors": build_map scales these afterwards)
        mode = ("model" if has_model_covariances(est) else "jackknife" if jackknife
                else "bootstrap")
    floor = mode == "floor"  # the model's, with the systematic floor (calibrated on it alone)
    notes: list[str] = []
    if mode in ("model", "floor"):
        if not has_model_covariances(est):
            raise ValueError(
                f"uncertainty={mode!r} needs a method that ends with a bundle adjustment "
                f"(BEARING-BA, LOC-SMA refined, SPATIAL-BA), not {result.method!r}: use 'bootstrap' or True")
        cov = _model(result, est, mapped, _rows(X, mapped), _rows(mask, mapped), timeline)
    elif mode == "jackknife":
        if not jackknife:
            raise ValueError(
                f"uncertainty='jackknife' needs the dense CAL-SMA of complete visibility "
                f"histories, not {result.method!r} here: use 'bootstrap' or True")
        cov = _jackknife(result, est, mapped, X, n_steps, notes)
    else:
        cov = _bootstrap(result, n_steps, refit, random_state, notes)
    cov = _finish(result, cov)
    if floor:
        cov = systematic_floor(cov, result.positions, result.anchor_ids)
    return dataclasses.replace(result, covariances=cov,
                               warnings=(*result.warnings, *notes))


def with_model_covariances(result: Map, cov_mapped: np.ndarray,
                           mapped: np.ndarray | None = None) -> Map:
    """``result`` with the model's covariances ``cov_mapped`` (len(mapped), d, d) of its rows
    ``mapped`` in the adjustment's frame (as :func:`mappers.viewpoints.adjustment_covariances`
    gives them), carried to the map's frame as ``uncertainty="model"`` carries them; ``mapped``
    None: ``cov_mapped`` (M, d, d) is already in the map's frame (a 3-D map's,
    :func:`mappers.spatial.marginals.spatial_covariances`)."""
    if mapped is None:
        return dataclasses.replace(result, covariances=_finish(result, cov_mapped))
    d = result.positions.shape[1]
    cov = np.full((len(result.positions), d, d), np.nan)
    cov[mapped] = cov_mapped
    cov = transform_covariances(cov, np.asarray(result.affine)[:d])
    return dataclasses.replace(result, covariances=_finish(result, cov))


def with_held_out_check(result: Map, held_out: Callable[[int], tuple[np.ndarray, np.ndarray]],
                        anchor_positions: np.ndarray) -> Map:
    """``result`` (a map with its covariances) with the covariances of its non-anchor objects
    scaled by what its anchors say of them (:mod:`mappers.core.held_out_anchors`):
    ``held_out(j)`` maps again without the ``j``-th anchor and returns that anchor's position and
    covariance there (a MappingError or ValueError: it cannot be mapped without it). The anchors'
    squared Mahalanobis distances give the factor (1 when they pass the test); a note in
    ``Map.warnings`` says what was found. With fewer than two anchors checked the covariances are
    kept as they are, with a note saying they could not be checked."""
    positions = np.asarray(anchor_positions, dtype=float)
    q = []
    for j in range(len(positions)):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the held-out maps' notes are the map's, again
                p, c = held_out(j)
        except (MappingError, ValueError):
            continue
        # an anchor not placed, or with a singular covariance it lies off: no check from it
        qj = float(mahalanobis_squared((np.asarray(p) - positions[j])[None], np.asarray(c)[None])[0])
        if np.isfinite(qj):
            q.append(qj)
    d = positions.shape[1]
    if len(q) < 2:
        note = (f"uncertainty: only {len(q)} of {len(positions)} anchors could be mapped without "
                "themselves: the covariances are not checked (they may be too small on logged "
                "data)")
        return dataclasses.replace(result, warnings=(*result.warnings, note))
    factor, k = held_out_factor(np.array(q), d)
    cov = np.array(result.covariances, dtype=float)
    free = np.ones(len(cov), dtype=bool)
    free[list(result.anchor_ids)] = False
    cov[free] *= factor
    note = (f"uncertainty: {len(q)} held-out anchors give the variance factor {k:.3g}; "
            + ("the covariances pass the test (kept)" if factor == 1.0 else
               f"the covariances are multiplied by {factor:.3g}"))
    return dataclasses.replace(result, covariances=cov, warnings=(*result.warnings, note))


def with_held_out_floor(result: Map, held_positions, held_covariances,
                        anchor_positions) -> Map:
    """``result`` (a map with the model's covariances) with the isotropic floor its held-out
    anchors estimate added to the covariance of every non-anchor object
    (:func:`mappers.core.held_out_anchors.held_out_floor`): ``held_positions`` (A, d) and
    ``held_covariances`` (A, d, d) are each anchor's position and covariance in the map without
    it, ``anchor_positions`` (A, d) where it is. What ``uncertainty=True`` gives a method with an
    adjustment: about nothing added where the anchors land inside their regions (a history the
    model describes), the systematic error's size where they do not (a logged run). With fewer
    than two anchors that can be held out (an anchor seen along one ray, a sparse run) the floor
    is ``"floor"``'s fixed share of the extent of the anchors' known positions
    (:data:`mappers.core.uncertainty.SYSTEMATIC_FLOOR`,
    :func:`mappers.core.uncertainty.systematic_floor`). A note in ``Map.warnings`` says which."""
    target = np.asarray(anchor_positions, dtype=float)
    errors = np.asarray(held_positions, dtype=float) - target
    covs = np.asarray(held_covariances, dtype=float)
    ok = np.all(np.isfinite(errors), axis=1) & np.all(np.isfinite(covs), axis=(1, 2))
    if ok.sum() < 2:  # (the extent from the anchors' known positions: some may be unplaced)
        known = np.array(result.positions, dtype=float)
        known[list(result.anchor_ids)] = target
        cov = systematic_floor(result.covariances, known, result.anchor_ids)
        note = (f"uncertainty: only {int(ok.sum())} of {len(target)} anchors could be held out: "
                f"the covariances get the fixed systematic floor ({SYSTEMATIC_FLOOR:g} of the "
                "anchors' extent per axis)")
    else:
        variance, used = held_out_floor(errors, covs)
        cov = np.array(result.covariances, dtype=float)
        rows = np.all(np.isfinite(cov), axis=(1, 2))
        rows[list(result.anchor_ids)] = False
        cov[rows] += variance * np.eye(cov.shape[-1])
        note = (f"uncertainty: {used} held-out anchors miss their regions: a systematic floor "
                f"of {math.sqrt(variance):.3g} per axis is added to the model's covariances"
                if variance > 0 else None)
    notes = (note,) if note else ()
    return dataclasses.replace(result, covariances=cov, warnings=(*result.warnings, *notes))
