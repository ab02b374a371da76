"""Mapping from histories with missing observations (paper §5.1: "missing observations").

On real data a landmark is sensed in a few percent of the steps only (limited field of view,
occlusion, detection range), so a history is mostly *missing*, not zero. Filling the gaps with
zeros (what the paper's pipeline does to a visibility history) makes every rarely-seen landmark
look far from everything. The methods here use only what was observed (the pair statistics of
:mod:`mappers.masked.coobservation`) and say which assumptions they add. They are the methods of
:func:`masked_embedding` (its ``method=``), each mapping complete and masked histories; one is a
label of the catalog (:data:`mappers.catalog.METHODS`), the others are building blocks of labels
or dead ends kept as comparisons (their figures: ``docs/dead-ends.md``):

``"range-quantile"`` (range; the label ``RANGE-QUANTILE``)
    Two landmarks ranged in the same step from an unknown viewpoint satisfy ``|r_i - r_j| <=
    d_ij`` (triangle inequality), with equality when the viewpoint is on the line through them;
    a high ``quantile`` of ``|r_i - r_j|`` over the steps that observed both estimates ``d_ij``.
    Pairs observed together in fewer than ``min_pairs`` steps are missing; the others weigh
    ``min(n_ij, weight_cap) / weight_cap``. Weighted SMACOF with the anchors held fixed.
    *Assumes*: one step's ranges come from one viewpoint; over the run some viewpoints are nearly
    collinear with each observed pair; ranges are unbiased.

``"range-bounds"`` (range; a dead end)
    ``range-quantile`` plus an upper bound from the field of view ``fov`` [rad]: two landmarks
    in one image are at most ``fov`` apart in bearing, so ``d_ij <= sqrt(r_i^2 + r_j^2 - 2 r_i
    r_j cos(fov))``; SMACOF on distance intervals ``[L_ij, min(U_ij, (1 + slack) L_ij)]``.
    *Assumes* additionally: the camera's full field of view.

``"covis-nonmetric"`` (any sensor; only the pattern of what was observed; a member of
``COVIS-ENSEMBLE`` and ``DROPOUT-BLEND``)
    ``delta_ij = -log(C_ij / sqrt(n_i n_j))`` from the co-observation counts (the Ochiai
    coefficient: the missing-data analogue of the paper's L2-normalised visibility, eq. 7); only
    its order is trusted: non-metric weighted SMACOF with weights ``sqrt(C_ij)``, anchors fixed.
    Pairs seen together in fewer than ``min_co`` steps are lower bounds, not measurements.
    A history that sensed every object in every step (complete bearing or range) has no such
    pattern and is refused (ValueError), as by ``covis-power``.
    *Assumes*: the chance of seeing two landmarks in one step falls monotonically with their
    distance, the same way everywhere.

``"covis-power"`` (any sensor; only the pattern of what was observed; the member of
``COVIS-ENSEMBLE``, a dead end on its own)
    ``covis-nonmetric``'s dissimilarity and weights with a metric link ``d = a * delta**power``
    (the scale refitted as it goes), started from the ``covis-nonmetric`` map: one global link
    constrains a small layout far more than the order alone. When the usable pairs fall apart
    into groups, one link cannot be calibrated across them and the ``covis-nonmetric`` map is
    kept (with a warning). *Assumes* additionally: one power law over the whole layout.

``"covis-angle"`` (bearing; ``COVIS-AUTO``'s branch for a local view)
    ``covis-nonmetric`` with an angle-weighted co-observation: a step that sensed both counts
    ``cos`` of their bearing difference (:func:`mappers.masked.coobservation.angle_covisibility_dissimilarity`),
    so two landmarks seen together in one direction are closer than two seen at the edges of a
    wide view. Weights ``C_ij`` (the co-observation count, not its square root: a pair seen
    together often is measured better). *Assumes*: the angle-weighted rate of seeing two
    landmarks together falls monotonically with their distance, the same way everywhere.

``"masked-euclidean"`` (any sensor; the textbook recipe, a dead end kept as a comparison)
    Root-mean-square difference of the two histories over the steps that observed both,
    weighted SMACOF over the pairs that have it. *Assumes*: a history difference is comparable
    across pairs (false for a narrow field of view, where co-observed bearings always differ by
    less than the field of view).

Every method returns positions in the anchors' frame when anchors are given (they are held at
their positions), else a free embedding. A group of objects whose usable pairs never link it to
the rest, held by fewer than 2 anchors, has no measured scale or rotation: it is left unmapped
with a warning, never drawn with false confidence.
"""

from __future__ import annotations

import inspect
import warnings
from dataclasses import dataclass, field
from numbers import Integral, Real
from typing import Any

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import shortest_path
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval, StrOptions

from mappers.core.align import apply_affine, check_anchors, fit_affine
from mappers.core.estimator_params import store_params
from mappers.core.sensors import step_observations
from mappers.core.validation import check_fit
from mappers.masked.coobservation import (
    angle_covisibility_dissimilarity,
    covisibility_dissimilarity,
    masked_euclidean_dissimilarity,
    pair_components,
    range_pair_bounds,
    range_pair_distances,
)
from mappers.smacof import (
    bounded_smacof,
    classical_mds,
    nonmetric_smacof,
    power_link_smacof,
    weighted_smacof,
)

__all__ = ["MASKED_METHODS", "MaskedMap", "MaskedMapWarning", "MaskedMapper", "UnanchoredGraphError",
           "masked_embedding"]

_COVIS = ("covis-nonmetric", "covis-power", "covis-angle")
_PATTERN_ONLY = ("covis-nonmetric", "covis-power")
"""The methods that read only the pattern of what was sensed: refused on a history that sensed
every object in every step (a complete bearing or range history), where they would draw a map
from no information."""
_OWN_DEFAULT = {"visibility": "covis-nonmetric", "bearing": "covis-nonmetric", "range": "range-quantile"}
"""The default of :func:`masked_embedding`'s own parameter ``method`` (a building block's
default, not a choice of ``build_map``: which label maps which data is
:data:`mappers.defaults.DEFAULTS`' one table)."""


class MaskedMapWarning(UserWarning):
    """A masked map is partial or rests on a fallback (groups that fall apart, unmapped objects)."""


@dataclass(frozen=True, eq=False)
class MaskedMap:
    """Result of :func:`masked_embedding`.

    positions: (M, 2) map (in the anchors' frame when anchors were given), NaN rows unmapped.
    delta, weights: the dissimilarities and weights used (weight 0 = missing pair).
    components: connected components of the graph of usable pairs (one list when connected).
    unmapped: objects left NaN: never sensed, or in a group of usable pairs holding fewer than
        2 anchors (its scale and rotation are not measured).
    """

    positions: np.ndarray
    method: str
    params: dict[str, Any]
    delta: np.ndarray
    weights: np.ndarray
    components: list[list[int]]
    unmapped: tuple[int, ...] = ()
    warnings: tuple[str, ...] = field(default=())


@dataclass
class _Pairs:
    """The usable pairs of the kept objects: dissimilarities, weights, counts (0 = missing),
    lower-bound pairs (covis methods) and interval upper bounds (range-bounds)."""

    delta: np.ndarray
    weights: np.ndarray
    counts: np.ndarray
    censored: np.ndarray | None = None
    upper: np.ndarray | None = None

    def subset(self, sel: np.ndarray) -> _Pairs:
        ix = np.ix_(sel, sel)
        pick = (lambda a: None if a is None else a[ix])  # noqa: E731
        return _Pairs(self.delta[ix], self.weights[ix], self.counts[ix], pick(self.censored),
                      pick(self.upper))


def _method_params(method: str | None, sensor: str, params: dict[str, Any]) -> tuple[str, dict]:
    method = _OWN_DEFAULT[sensor] if method is None else method
    if method not in MASKED_METHODS:
        raise ValueError(f"method must be one of {sorted(MASKED_METHODS)}, got {method!r}")
    unknown = set(params) - set(MASKED_METHODS[method])
    if unknown:
        raise ValueError(f"unknown parameter(s) {sorted(unknown)} for method {method!r}")
    if method.startswith("range-") and sensor != "range":
        raise ValueError(f"method {method!r} needs a range history, got sensor {sensor!r}")
    if method == "covis-angle" and sensor != "bearing":
        raise ValueError(f"method 'covis-angle' needs a bearing history, got sensor {sensor!r}")
    p = {**MASKED_METHODS[method], **params}
    if method == "range-bounds" and p["slack"] < 0:
        raise ValueError(f"slack must be >= 0, got {p['slack']}")
    return method, p


def _pair_statistics(method: str, seen: np.ndarray, values: np.ndarray, sensor: str,
                     p: dict[str, Any]) -> _Pairs:
    if method.startswith("range-"):
        delta, counts = range_pair_distances(values, seen, quantile=p["quantile"],
                                             min_pairs=p["min_pairs"])
        upper = None
        if method == "range-bounds":
            upper = range_pair_bounds(values, seen, fov=p["fov"],
                                      upper_quantile=p["upper_quantile"], min_pairs=p["min_pairs"])
        return _Pairs(delta, np.minimum(counts, p["weight_cap"]) / p["weight_cap"], counts,
                      upper=upper)
    if method == "masked-euclidean":
        delta, counts = masked_euclidean_dissimilarity(values, seen, sensor,
                                                       min_pairs=p["min_pairs"])
        return _Pairs(delta, (counts > 0).astype(float), counts)
    if method == "covis-angle":
        delta, C = angle_covisibility_dissimilarity(seen, values)
    else:
        delta, C = covisibility_dissimilarity(seen)
    Cn = C.copy()
    np.fill_diagonal(Cn, 0)
    W = np.maximum(Cn, 1.0) if method == "covis-angle" else np.sqrt(np.maximum(Cn, 1.0))
    W /= W.max()
    np.fill_diagonal(W, 0.0)
    censored = Cn < p["min_co"]
    return _Pairs(delta, W, np.where(censored, 0, Cn), censored=censored)


def _initial(delta: np.ndarray, weights: np.ndarray, anchor_ids, anchor_positions) -> np.ndarray:
    """Classical MDS of the shortest-path completion of the observed dissimilarities, aligned
    to the anchors when given (a start for SMACOF; missing pairs get graph distances)."""
    G = np.where(weights > 0, np.maximum(delta, 1e-9), 0.0)
    sp = shortest_path(csr_matrix(G), directed=False)
    finite = np.isfinite(sp)
    big = sp[finite].max() if finite.any() else 1.0
    sp = np.where(finite, sp, 1.5 * big)
    Y = classical_mds(sp, 2)
    if anchor_ids is not None:
        try:
            Y = apply_affine(Y, fit_affine(Y[anchor_ids], anchor_positions))
        except ValueError:
            pass  # degenerate start: keep the unaligned one, SMACOF with fixed anchors fixes it
    return Y


class UnanchoredGraphError(ValueError):
    """The graph of usable pairs falls apart and no group holds 2 or more anchors: nothing can
    be placed in the anchors' frame."""


def _drop_loose_groups(pairs, comps, keep, anchor_ids, anchor_positions, msgs):
    """Leave out the groups of usable pairs held by fewer than 2 anchors (their scale and
    rotation in the anchors' frame are not measured; non-metric stress and lower bounds would
    push them off to kilometres). Returns the pairs, kept rows, anchors and groups that remain."""
    sub_anchor = np.searchsorted(keep, anchor_ids)
    loose = [c for c in comps if np.isin(c, sub_anchor).sum() < 2]
    if len(loose) == len(comps):
        raise UnanchoredGraphError(
            "the graph of usable pairs falls apart and no group holds 2 or more anchors "
            f"(groups {[[int(keep[i]) for i in c] for c in comps]}, anchors "
            f"{anchor_ids.tolist()}): nothing can be placed in the anchors' frame"
        )
    if not loose:
        return pairs, keep, anchor_ids, anchor_positions, comps
    drop = np.concatenate([np.asarray(c, dtype=np.int64) for c in loose])
    lost = sorted(int(keep[i]) for i in drop if keep[i] not in set(anchor_ids.tolist()))
    msgs.append(
        f"object(s) (rows) {lost} are unmapped: the graph of usable pairs falls apart and "
        "their group holds fewer than 2 anchors, so its scale and rotation are not "
        "measured (choose at least 2 anchors in every group)"
    )
    sel = np.setdiff1d(np.arange(len(keep)), drop)
    keep = keep[sel]
    kept = np.isin(anchor_ids, keep)
    comps = [[int(i) for i in np.searchsorted(sel, c)] for c in comps if np.isin(c, sel).all()]
    return pairs.subset(sel), keep, anchor_ids[kept], anchor_positions[kept], comps


def _solve(method, pairs: _Pairs, n_groups, fixed, fixed_positions, p, max_iter, msgs):
    """The map of the kept objects from their usable pairs."""
    if method in _COVIS:
        start = _initial(np.where(pairs.censored, 0, pairs.delta), pairs.counts.astype(float),
                         fixed, fixed_positions)
        Y = nonmetric_smacof(pairs.delta, pairs.weights, start, censored=pairs.censored,
                             fixed=fixed, fixed_positions=fixed_positions, max_iter=max_iter)
        if method == "covis-power" and n_groups > 1:
            msgs.append("covis-power: the usable pairs fall apart, so one distance link cannot be "
                        "calibrated across the groups; kept the covis-nonmetric map")
        elif method == "covis-power":
            Y, _ = power_link_smacof(pairs.delta, pairs.weights, Y, power=p["power"],
                                     censored=pairs.censored, fixed=fixed,
                                     fixed_positions=fixed_positions, n_rounds=p["n_rounds"])
        return Y
    start = _initial(pairs.delta, pairs.weights, fixed, fixed_positions)
    Y, _, _ = weighted_smacof(pairs.delta, pairs.weights, start, fixed=fixed,
                              fixed_positions=fixed_positions, max_iter=max_iter)
    if method == "range-bounds":
        upper = np.minimum(pairs.upper, (1.0 + p["slack"]) * pairs.delta)
        Y = bounded_smacof(pairs.delta, upper, pairs.weights, Y, fixed=fixed,
                           fixed_positions=fixed_positions, max_iter=max(max_iter, 500))
    if method == "masked-euclidean" and fixed is not None:
        # a history difference has no metric scale: the anchors can only fix an affine frame
        free, _, _ = weighted_smacof(pairs.delta, pairs.weights, start, max_iter=max_iter)
        Y = apply_affine(free, fit_affine(free[fixed], fixed_positions))
    return Y


def masked_embedding(
    X: np.ndarray,
    mask: np.ndarray | None,
    sensor: str,
    method: str | None = None,
    *,
    anchor_ids: np.ndarray | None = None,
    anchor_positions: np.ndarray | None = None,
    max_iter: int = 300,
    **params: Any,
) -> MaskedMap:
    """Map objects from a history with missing entries (see the module docstring for methods).

    Args:
        X: (M, N * c) history matrix (c = 2 for bearing).
        mask: (M, N * c) bool, True where observed; None = every entry observed (then a
            visibility 0 / range 0 / bearing (0, 0) counts as not sensed).
        sensor: ``"visibility"``, ``"bearing"`` or ``"range"``.
        method: a key of :data:`MASKED_METHODS`; None = ``range-quantile`` for range, else
            ``covis-nonmetric``.
        anchor_ids, anchor_positions: anchors held fixed at their positions (recommended; the
            non-metric method needs them to know the scale of the map).
        **params: overrides of the method's defaults.
    """
    method, p = _method_params(method, sensor, params)
    seen, values = step_observations(X, mask, sensor)
    M = seen.shape[0]
    never = np.flatnonzero(~seen.any(axis=1))
    if anchor_ids is not None:
        anchor_ids, anchor_positions = check_anchors(anchor_ids, anchor_positions, M)
        if np.isin(anchor_ids, never).any():
            raise ValueError(f"anchor(s) {sorted(set(anchor_ids) & set(never))} were never sensed")
    keep = np.setdiff1d(np.arange(M), never)
    if len(keep) < 3:
        raise ValueError(f"only {len(keep)} object(s) were ever sensed; need at least 3")
    if method in _PATTERN_ONLY and seen[keep].all():
        raise ValueError(
            f"method {method!r} reads only which objects were sensed together, and this {sensor} "
            f"history sensed every object in every step (a complete {sensor} history): that "
            f"pattern says nothing about distance. Use the complete default (CAL-SMA"
            f"{', UNFOLD for range' if sensor == 'range' else ''})"
            f"{' or the method covis-angle' if sensor == 'bearing' else ''}, or pass the "
            "history's mask"
        )
    pairs = _pair_statistics(method, seen[keep], values[keep], sensor, p)
    comps = pair_components(pairs.counts)
    comps_full = [[int(keep[i]) for i in c] for c in comps]  # the data's groups, object ids
    msgs: list[str] = []
    fixed, fixed_positions = None, anchor_positions
    if anchor_ids is not None:
        if len(comps) > 1:
            pairs, keep, anchor_ids_kept, fixed_positions, comps = _drop_loose_groups(
                pairs, comps, keep, anchor_ids, anchor_positions, msgs)
        else:
            anchor_ids_kept = anchor_ids
        fixed = np.searchsorted(keep, anchor_ids_kept)
    Y = _solve(method, pairs, len(comps), fixed, fixed_positions, p, max_iter, msgs)
    if len(comps_full) > 1:
        sizes = sorted((len(c) for c in comps_full), reverse=True)
        msgs.append(f"the graph of usable pairs falls apart into {len(comps_full)} components "
                    f"(sizes {sizes}): the relative placement of the components is not measured")
    positions = np.full((M, 2), np.nan)
    positions[keep] = Y
    if anchor_ids is not None:  # anchors of unmapped groups stay at their known positions
        positions[anchor_ids] = anchor_positions
    D_full, W_full = np.zeros((M, M)), np.zeros((M, M))
    D_full[np.ix_(keep, keep)] = pairs.delta
    W_full[np.ix_(keep, keep)] = pairs.weights
    if never.size:
        msgs.append(f"object(s) {never.tolist()} were never sensed and are unmapped")
    return MaskedMap(
        positions=positions, method=method, params=p, delta=D_full, weights=W_full,
        components=comps_full, warnings=tuple(msgs),
        unmapped=tuple(int(i) for i in np.flatnonzero(np.isnan(positions).any(axis=1))),
    )


class MaskedMapper(TransformerMixin, BaseEstimator):
    """The estimator behind ``RANGE-QUANTILE`` and the building blocks of
    :func:`masked_embedding` (module docstring).

    Parameters:
        method: a key of :data:`MASKED_METHODS`; None: ``range-quantile`` for range histories,
            else ``covis-nonmetric`` (as :func:`masked_embedding`).
        quantile, min_pairs, weight_cap: ``range-quantile`` and ``range-bounds``' pair
            distances (``min_pairs`` also ``masked-euclidean``'s).
        slack, fov, upper_quantile: ``range-bounds``' upper bounds.
        min_co: the co-observation methods' smallest count of a measured pair.
        power, n_rounds: ``covis-power``'s link and its rounds.
        max_iter: SMACOF updates.

    A parameter the chosen method does not use is ignored. ``fit(X, mask=None, *, sensor=None,
    anchor_ids=None, anchor_positions=None)`` maps the history (the sensor inferred from the
    observed entries when not given; the anchors held at their positions when given).

    Attributes:
        embedding_ (M, 2): :func:`masked_embedding`'s positions (NaN rows: unmapped); result_
        the whole :class:`MaskedMap` (its notes are issued as :class:`MaskedMapWarning`, so that
        ``build_map`` lists them in ``Map.warnings``); n_features_in_.
    """

    _parameter_constraints: dict = {
        "method": [StrOptions({"range-quantile", "range-bounds", *_COVIS, "masked-euclidean"}), None],
        "quantile": [Interval(Real, 0, 1, closed="both")],
        "min_pairs": [Interval(Integral, 1, None, closed="left")],
        "weight_cap": [Interval(Real, 0, None, closed="neither")],
        "slack": [Interval(Real, 0, None, closed="left")],
        "fov": [Interval(Real, 0, None, closed="neither")],
        "upper_quantile": [Interval(Real, 0, 1, closed="both")],
        "min_co": [Interval(Integral, 1, None, closed="left")],
        "power": [Interval(Real, 0, None, closed="neither")],
        "n_rounds": [Interval(Integral, 1, None, closed="left")],
        "max_iter": [Interval(Integral, 1, None, closed="left")],
    }

    def __init__(self, *, method: str | None = None, quantile: float = 0.98, min_pairs: int = 5,
                 weight_cap: float = 50, slack: float = 1.0, fov: float = 1.22,
                 upper_quantile: float = 0.02, min_co: int = 3, power: float = 0.5,
                 n_rounds: int = 60, max_iter: int = 300) -> None:
        store_params(self, locals())

    def fit(self, X, y=None, *, mask=None, sensor: str | None = None, anchor_ids=None,
            anchor_positions=None):
        """Map the history ``X`` (M, D) (``mask`` True where observed; None: complete)."""
        X, mask, sensor = check_fit(self, X, y, mask=mask, sensor=sensor)
        method = _OWN_DEFAULT[sensor] if self.method is None else self.method
        params = {name: getattr(self, name) for name in MASKED_METHODS[method]}
        self.result_ = masked_embedding(X, mask, sensor, method, anchor_ids=anchor_ids,
                                        anchor_positions=anchor_positions,
                                        max_iter=self.max_iter, **params)
        for msg in self.result_.warnings:
            warnings.warn(msg, MaskedMapWarning, stacklevel=2)
        self.embedding_ = self.result_.positions
        return self

    def fit_transform(self, X, y=None, *, mask=None, sensor: str | None = None, anchor_ids=None,
                      anchor_positions=None):
        """Fit and return the (M, 2) map (NaN rows: unmapped)."""
        return self.fit(X, mask=mask, sensor=sensor, anchor_ids=anchor_ids,
                        anchor_positions=anchor_positions).embedding_


def _range_quantile(quantile=0.98, min_pairs=5, weight_cap=50, max_iter=300):
    return MaskedMapper(method="range-quantile", quantile=quantile, min_pairs=min_pairs,
                        weight_cap=weight_cap, max_iter=max_iter)


def _range_bounds(quantile=0.98, min_pairs=5, weight_cap=50, slack=1.0, fov=1.22,
                  upper_quantile=0.02, max_iter=300):
    return MaskedMapper(method="range-bounds", quantile=quantile, min_pairs=min_pairs,
                        weight_cap=weight_cap, slack=slack, fov=fov,
                        upper_quantile=upper_quantile, max_iter=max_iter)


def _covis_nonmetric(min_co=3, max_iter=300):
    return MaskedMapper(method="covis-nonmetric", min_co=min_co, max_iter=max_iter)


def _covis_power(min_co=3, power=0.5, n_rounds=60, max_iter=300):
    return MaskedMapper(method="covis-power", min_co=min_co, power=power, n_rounds=n_rounds,
                        max_iter=max_iter)


def _covis_angle(min_co=3, max_iter=300):
    return MaskedMapper(method="covis-angle", min_co=min_co, max_iter=max_iter)


def _masked_euclidean(min_pairs=5, max_iter=300):
    return MaskedMapper(method="masked-euclidean", min_pairs=min_pairs, max_iter=max_iter)


_FACTORIES = {
    "range-quantile": _range_quantile,
    "range-bounds": _range_bounds,
    "covis-nonmetric": _covis_nonmetric,
    "covis-power": _covis_power,
    "covis-angle": _covis_angle,
    "masked-euclidean": _masked_euclidean,
}
MASKED_METHODS: dict[str, dict[str, Any]] = {
    name: {k: v.default for k, v in inspect.signature(f).parameters.items() if k != "max_iter"}
    for name, f in _FACTORIES.items()
}
"""Method of :func:`masked_embedding` -> its default parameters (each also takes ``max_iter``)."""
