"""Range + bearing mapping without localisation (label ``"LOC-SMA"``; the fused default).

Every step that senses two objects gives their distance by the law of cosines
(:mod:`mappers.fused.law_of_cosines`), so a range-and-bearing history yields measured distances for
the pairs seen together, pooled robustly (median) and weighted by their precision (count over
spread squared). The map is the weighted SMACOF embedding of these distances with the anchors
held at their known positions (de Leeuw 1977; Borg & Groenen, *Modern Multidimensional Scaling*,
2005, §8 and §11 for weights and fixed points; :func:`mappers.smacof.weighted.weighted_smacof`), started
from classical MDS of the shortest-path completion of the distances (Tenenbaum et al. 2000)
placed on the anchors.

The pairs form a sparse graph, which a narrow or short-range camera may split (clustered
layouts). Each connected part is placed by its own anchors: with three or more it is fixed;
with two, distances leave a mirror image about the anchors' line, which the frames' handedness
decides (:func:`mappers.fused.law_of_cosines.handedness_votes`); with fewer it is not placed. Objects
that the pairs and anchors do not pin down (:func:`mappers.fused.rigidity.flexible_objects`) are not
placed either: each such case is a :class:`RigidityWarning` and NaN rows, never a guess.

The map is then refined (``refine="range-bearing"``, the default) by a bundle adjustment that
estimates each step's viewpoint and fits the readings' ranges and angles
(:mod:`mappers.viewpoints.range_bearing`; Triggs et al. 2000), better than the law-of-cosines
map on every setting measured (``docs/fused-sensing.md``, "After BEARING-BA"). ``refine=None``
is the law-of-cosines map alone, ``refine="bearing"`` the bearing-only adjustment
(:mod:`mappers.viewpoints.bearing`, which loses the ranges: worse through a narrow view).
"""

from __future__ import annotations

import warnings
from numbers import Integral, Real

import numpy as np
from scipy.sparse.csgraph import shortest_path
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import Interval, StrOptions

from mappers.core.align import check_anchors
from mappers.core.estimator_params import store_params
from mappers.core.iteration_params import ITERATION_CONSTRAINTS, ROUND_CONSTRAINTS
from mappers.core.validation import check_fused_input
from mappers.fused.law_of_cosines import (
    frame_triangles,
    frame_values,
    handedness_votes,
    pooled_frame_distances,
)
from mappers.fused.rigidity import anchored_components, flexible_objects
from mappers.smacof import classical_mds, weighted_smacof
from mappers.viewpoints import BearingAdjustment, RangeBearingAdjustment

__all__ = ["LawOfCosinesSMACOF", "RigidityWarning", "pair_weights"]


_HANDEDNESS_TOLERANCE = 0.05
"""Share of the frames' triangles a correct map may turn the wrong way (noise, near-collinear
triples); above twice it, a map is reported as folded."""


class RigidityWarning(UserWarning):
    """Objects the measured pairs and the anchors do not pin down (left unplaced)."""


def pair_weights(spread: np.ndarray, count: np.ndarray, min_count: int) -> np.ndarray:
    """Weights ``n / (s^2 + s_0^2)`` of the pairs sensed together at least ``min_count`` times
    (0 for the others): the precision of a median of n samples of scale s. ``s_0``, the median
    spread over the pairs, keeps a pair of few, accidentally agreeing samples from dominating."""
    pairs = count >= min_count
    np.fill_diagonal(pairs, False)
    spreads = spread[pairs & (spread > 0)]
    s0 = np.median(spreads) if spreads.size else 1.0
    return np.where(pairs, count / (spread**2 + s0**2), 0.0)


def _residual_scale(D: np.ndarray, S: np.ndarray, W: np.ndarray) -> np.ndarray:
    """Per pair, the scale its fitted distance may be expected to miss by: its spread combined
    with the median spread, and 0.1 % of the median distance (noise-free data, rounding)."""
    used = W > 0
    s0 = np.median(S[used & (S > 0)]) if np.any(used & (S > 0)) else 0.0
    floor = 1e-3 * np.median(D[used]) if used.any() else 1.0
    return np.sqrt(S**2 + s0**2 + floor**2)


def _similarity_onto(Y: np.ndarray, src: np.ndarray, dst: np.ndarray, mirror: bool) -> np.ndarray:
    """``Y`` moved by the rotation (``mirror``: reflection), scale and shift that best take its
    rows ``src`` onto ``dst`` (Umeyama 1991, least squares)."""
    a, b = Y[src], dst
    ma, mb = a.mean(axis=0), b.mean(axis=0)
    if mirror:
        Y, a, ma = Y * [1.0, -1.0], a * [1.0, -1.0], ma * [1.0, -1.0]
    U, s, Vt = np.linalg.svd((a - ma).T @ (b - mb))
    d = np.sign(np.linalg.det(U @ Vt)) or 1.0
    R = U @ np.diag([1.0, d]) @ Vt
    scale = (s[0] + d * s[1]) / max(np.sum((a - ma) ** 2), 1e-300)
    return (Y - ma) @ R * scale + mb


class LawOfCosinesSMACOF(TransformerMixin, BaseEstimator):
    """Anchored weighted SMACOF of law-of-cosines pair distances from fused range + bearing.

    Parameters:
        min_count: a pair needs this many steps that sensed both objects to be used.
        max_range: readings farther than this [m] are ignored (None: all are used).
        trim: a pair's distance is the precision-weighted mean of its samples within ``trim``
            robust scales of their median (None: the weighted median itself).
        outlier: a pair whose fitted distance is off its measured one by more than this many
            robust scales (its spread combined with the median spread) is dropped and the map
            refitted, worst first, for at most ``max_rounds`` fits (a misread label gives a
            consistent but wrong distance that no weight can tame).
        n_init: random starts besides the geodesic one and its mirror image (see ``_place_part``).
        max_iter, tol: of :func:`mappers.smacof.weighted.weighted_smacof`.
        refine: refine the map by bundle adjustment, the map as its start:
            ``"range-bearing"`` (:class:`mappers.viewpoints.range_bearing.RangeBearingAdjustment`,
            range and angle residuals), ``"bearing"`` (bearing-only,
            :class:`mappers.viewpoints.bearing.BearingAdjustment`), or None (the default): the
            law-of-cosines map alone.
        random_state: seed of the random starts.

    Attributes:
        embedding_ (M, 2) in world coordinates (NaN rows: not placed), distances_, weights_
        (M, M) pooled distances and pair weights, unplaced_ (indices not placed).
    """

    _parameter_constraints: dict = {
        "min_count": [Interval(Integral, 1, None, closed="left")],
        "max_range": [Interval(Real, 0, None, closed="neither"), None],
        "trim": [Interval(Real, 0, None, closed="neither"), None],
        **ITERATION_CONSTRAINTS,
        "outlier": [Interval(Real, 0, None, closed="neither")],
        "max_rounds": ROUND_CONSTRAINTS["max_rounds"],
        "n_init": [Interval(Integral, 0, None, closed="left")],
        "refine": [StrOptions({"range-bearing", "bearing"}), None],
        "random_state": ["random_state"],
    }

    def __init__(self, *, min_count: int = 3, max_range: float | None = None,
                 trim: float | None = 3.0, outlier: float = 4.0, max_rounds: int = 10, n_init: int = 4,
                 max_iter: int = 500, tol: float = 1e-7, refine: str | None = "range-bearing",
                 random_state=None) -> None:
        store_params(self, locals())

    def fit(self, X, y=None, *, masks=None, anchor_ids=None, anchor_positions=None):
        """Map the fused histories ``X`` ({"range": (M, N), "bearing": (M, 2N)}; ``masks`` keyed
        alike, None = complete) with the anchors (rows of X) at their positions."""
        self._validate_params()
        check_fused_input(self, X, ("range", "bearing"))
        masks = dict(masks or {})
        r, theta = frame_values(X, masks)
        m = r.shape[0]
        ids, pos = check_anchors(anchor_ids, anchor_positions, m)
        D, S, C = pooled_frame_distances(r, theta, max_range=self.max_range, trim=self.trim)
        W = pair_weights(S, C, self.min_count)
        scale = _residual_scale(D, S, W)
        self.outlier_pairs_ = []
        for _ in range(self.max_rounds):  # drop pairs the rest of the map contradicts, refit
            Y, notes = self._place_all(D, W, ids, pos, r, theta)
            fitted = np.linalg.norm(Y[:, None] - Y[None], axis=2)
            z = np.where((W > 0) & np.isfinite(fitted), np.abs(fitted - D) / scale, 0.0)
            if z.max() <= self.outlier:
                break
            worst = z >= max(self.outlier, 0.5 * z.max())
            W = np.where(worst, 0.0, W)
            self.outlier_pairs_ += [tuple(p) for p in np.argwhere(np.triu(worst, 1)).tolist()]
        else:
            Y, notes = self._place_all(D, W, ids, pos, r, theta)
        self.distances_, self.weights_ = D, W
        if self.outlier_pairs_:
            notes.append(f"{len(self.outlier_pairs_)} pair distance(s) {self.outlier_pairs_[:6]} "
                         "contradicted by the rest of the map were dropped (misread labels?)")
        for msg in notes:
            warnings.warn(msg, RigidityWarning, stacklevel=2)
        self.adjustment_ = None
        if self.refine == "bearing":
            self.adjustment_ = BearingAdjustment()
            Y = self.adjustment_.fit_transform(X["bearing"], mask=masks.get("bearing"),
                                               anchor_ids=ids, anchor_positions=pos,
                                               start_positions=Y)
        elif self.refine == "range-bearing":
            self.adjustment_ = RangeBearingAdjustment()
            Y = self.adjustment_.fit_transform(X, masks=masks, anchor_ids=ids,
                                               anchor_positions=pos, start_positions=Y)
        self.embedding_ = Y
        self.unplaced_ = np.flatnonzero(~np.isfinite(Y[:, 0]))
        return self

    def _place_all(self, D, W, ids, pos, r, theta) -> tuple[np.ndarray, list[str]]:
        """Every connected part of the graph of pairs placed by its anchors; the objects that
        cannot be pinned down are NaN, with the reasons."""
        Y = np.full((len(D), 2), np.nan)
        notes: list[str] = []
        where = {int(a): k for k, a in enumerate(ids)}
        for objects, anchors in anchored_components(W, ids):
            apos = pos[[where[int(a)] for a in anchors]]
            if objects.size == 1 and anchors.size == 1:  # an anchor without pairs
                Y[objects] = apos
            elif anchors.size < 2:
                notes.append(f"objects {objects.tolist()} are tied to {anchors.size} anchor(s) "
                                "by the measured pairs (at least 2 are needed): not placed")
            else:
                Y[objects] = self._place_part(D, W, objects, anchors, apos, r, theta, notes)
        parts = [o for o, a in anchored_components(W, ids) if a.size >= 2]
        if len(parts) > 1:
            notes.append(f"the measured pairs fall apart into {len(parts)} groups "
                         f"{[p.tolist() for p in parts]} (a clustered layout?): each is placed by "
                         "its own anchors, and nothing measured places the groups relative to "
                         "each other")
        placed = np.flatnonzero(np.isfinite(Y[:, 0]))
        loose = flexible_objects(Y[placed], W[np.ix_(placed, placed)], np.flatnonzero(np.isin(placed, ids)))
        if loose.size:
            notes.append(f"objects {placed[loose].tolist()} can move without changing any "
                            "measured pair distance (too few pairs): not placed")
            Y[placed[loose]] = np.nan
        return Y, notes

    def _place_part(self, D, W, objects, anchors, apos, r, theta, notes) -> np.ndarray:
        """Positions of one connected part of the graph of pairs, its anchors fixed.

        SMACOF runs from the geodesic start and its mirror image, both placed on the anchors,
        then (only if both turn more than 5 % of the frames' triangles the wrong way: folded)
        from ``n_init`` random starts. Of the fits that turn at most 5 % the wrong way, the one
        of lowest stress is kept, else the one that turns fewest (a fold or a mirrored cluster
        can fit the distances about as well, but turns many triangles the wrong way)."""
        local_anchors = np.searchsorted(objects, anchors)
        Dp, Wp = D[np.ix_(objects, objects)], W[np.ix_(objects, objects)]
        start = classical_mds(shortest_path(np.where(Wp > 0, Dp, 0.0), directed=False))
        tri, sign = frame_triangles(r, theta, objects)
        rng = check_random_state(self.random_state)
        spread = max(float(np.std(apos)), float(np.median(Dp[Wp > 0])))
        fits = []
        for k in range(2 + self.n_init):
            if k < 2:
                init = _similarity_onto(start, local_anchors, apos, mirror=bool(k))
            elif any(f[0] <= _HANDEDNESS_TOLERANCE for f in fits):
                break
            else:
                init = apos.mean(axis=0) + rng.normal(scale=spread, size=(objects.size, 2))
            Y, stress, _ = weighted_smacof(Dp, Wp, init, fixed=local_anchors, fixed_positions=apos,
                                           max_iter=self.max_iter, tol=self.tol)
            agree, disagree = handedness_votes(tri, sign, Y)
            fits.append((disagree / max(agree + disagree, 1), stress, Y, agree - disagree))
        good = [f for f in fits if f[0] <= _HANDEDNESS_TOLERANCE]
        wrong, _, Y, margin = min(good, key=lambda f: f[1]) if good else min(fits, key=lambda f: f[0])
        if anchors.size == 2 and len({f[3] > 0 for f in fits[:2]}) < 2:
            # two anchors: the mirror images fit alike, and no frame tells them apart
            notes.append(f"objects {objects.tolist()} are tied to 2 anchors only and no frame "
                         "decides their mirror image: not placed")
            return np.full((objects.size, 2), np.nan)
        if wrong > 2 * _HANDEDNESS_TOLERANCE:
            notes.append(f"objects {objects.tolist()}: {wrong:.0%} of the frames' triangles turn "
                         "the other way in the map (folded?)")
        return Y

    def fit_transform(self, X, y=None, *, masks=None, anchor_ids=None, anchor_positions=None):
        """Fit and return the (M, 2) map in world coordinates (NaN rows: not placed)."""
        return self.fit(X, masks=masks, anchor_ids=anchor_ids,
                        anchor_positions=anchor_positions).embedding_


def _loc_sma(*, min_count: int = 3, max_range: float | None = None, trim: float | None = 3.0,
             outlier: float = 4.0, n_init: int = 4, refine: str | None = "range-bearing",
             random_state=None) -> LawOfCosinesSMACOF:
    return LawOfCosinesSMACOF(min_count=min_count, max_range=max_range, trim=trim,
                              outlier=outlier, n_init=n_init, refine=refine,
                              random_state=random_state)
