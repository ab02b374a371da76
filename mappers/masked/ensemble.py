"""The covisibility ensemble (label ``"COVIS-ENSEMBLE"``): the mean of anchored co-observation
maps over several windows of consecutive steps.

Two landmarks caught in one camera frame are close; caught within a few seconds of each other,
while the camera sweeps, they are still likely close, and the window decides how far "close"
reaches. A single co-observation map moves with the window, and on real runs the window best on
one run is not on another, while the mean of the maps over a fixed spread of windows needs no
choice of one. All members hold the anchors fixed, so they share the anchors'
frame and their mean is a map. It adds no information to its members: it removes the choice of
one setting. *Assumes* what its members assume (:mod:`mappers.masked.pair_maps`).

The members are combined by their mean (``combine="mean"``), or by each object's geometric
median over the members (``combine="median"``): a member whose SMACOF flung an object off (a
failure, not noise: on sparse simulated logs of sightings one member in twelve can put it
kilometres away) moves the mean without bound but the median not at all, while where no member
fails the two agree closely (``docs/dead-ends.md``, "Defaults that carry"). The geometric
median, unlike a median per coordinate, moves with the anchors' frame (rotations included).

Windows are counted in ticks of the history's *timeline*: an (N, 2) integer array giving, for
each step (column group), the robot that took it and the tick of its clock (e.g. the index of a
0.5 s bin); steps of one robot falling in the same ``tick // window`` are merged. Without a
timeline the history is one robot stepping once per tick.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from numbers import Integral, Real
from typing import Any

import numpy as np
from scipy.sparse import csr_matrix
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval, StrOptions

from mappers.core.estimator_params import store_params
from mappers.core.sensors import check_timeline, step_observations
from mappers.core.validation import check_history
from mappers.masked.dropout_blend import DropoutBlend
from mappers.masked.pair_maps import (
    MaskedMap,
    MaskedMapWarning,
    UnanchoredGraphError,
    masked_embedding,
)

__all__ = ["COMBINE", "CovisEnsemble", "ensemble_embedding", "geometric_median", "member_spread",
           "window_steps"]

MEMBERS = ("covis-power", "covis-nonmetric")
COMBINE = ("mean", "median")
"""How the members' maps are combined: their mean, or each object's geometric median."""


def geometric_median(points: np.ndarray, *, tol: float = 1e-10, max_iter: int = 500) -> np.ndarray:
    """(M, d) the geometric median over axis 0 of ``points`` (K, M, d): for each object the
    point with the least sum of Euclidean distances to its positions, over the K members that
    place it (a row with a NaN is left out; NaN for an object no member places). Weiszfeld's
    iteration (Weiszfeld 1937) started from the mean, each distance floored at ``tol`` times the
    spread (the usual guard when an iterate lands on a point; Vardi & Zhang 2000), until no
    object moves more than ``tol`` times the spread. Written here because numpy, scipy and
    scikit-learn have no geometric median and the small packages that do (hdmedians,
    geom-median) have had no release since 2022."""
    P = np.asarray(points, dtype=float)
    if P.ndim != 3 or P.shape[0] == 0:
        raise ValueError(f"points must be (K, M, d) with K >= 1, got shape {P.shape}")
    valid = np.isfinite(P).all(axis=2)  # (K, M)
    placed = valid.any(axis=0)
    Q, v = np.where(valid[..., None], P, 0.0)[:, placed], valid[:, placed].astype(float)
    Y = np.einsum("km,kmd->md", v, Q) / v.sum(axis=0)[:, None]
    spread = float(np.max(np.abs(Q - Y) * v[..., None])) if Q.size else 0.0
    if spread > 0:
        floor = tol * spread
        for _ in range(max_iter):
            w = v / np.maximum(np.linalg.norm(Q - Y, axis=2), floor)  # (K, M'), 0 where unplaced
            new = np.einsum("km,kmd->md", w, Q) / w.sum(axis=0)[:, None]
            done = np.max(np.linalg.norm(new - Y, axis=1)) <= floor
            Y = new
            if done:
                break
    out = np.full(P.shape[1:], np.nan)
    out[placed] = Y
    return out


def member_spread(stack: np.ndarray, center: np.ndarray, anchor_ids, anchor_positions) -> float:
    """How far the members' maps ``stack`` (K, M, 2) scatter about the combined map ``center``
    (M, 2): the median over the placed non-anchor objects of the median distance of their
    members' positions from ``center``, over the anchors' spread (their largest distance apart);
    NaN when no non-anchor object is placed. A few hundredths where the members agree; tenths
    and more where the co-observations are too few for them to (``docs/dead-ends.md``)."""
    ids = np.asarray(anchor_ids)
    apos = np.asarray(anchor_positions, dtype=float)
    span = float(np.max(np.linalg.norm(apos[:, None] - apos[None], axis=2)))
    rest = np.setdiff1d(np.arange(stack.shape[1]), ids)
    d = np.linalg.norm(stack[:, rest] - center[rest], axis=2)  # NaN where unplaced
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns: unplaced objects
        per_object = np.nanmedian(d, axis=0)
    per_object = per_object[np.isfinite(per_object)]
    return float(np.median(per_object)) / span if per_object.size else float("nan")


def window_steps(seen: np.ndarray, window: int, timeline: np.ndarray | None = None) -> np.ndarray:
    """(M, W) bool: objects sensed within each window of ``window`` ticks of one robot.

    Windows are ordered robot by robot, then in time; windows with no step are absent.
    """
    seen = np.asarray(seen, dtype=bool)
    n = seen.shape[1]
    if timeline is None:
        robot, tick = np.zeros(n, dtype=np.int64), np.arange(n, dtype=np.int64)
    else:
        robot, tick = check_timeline(timeline, n).T
    key = robot * (int(tick.max(initial=0)) // window + 1) + tick // window
    used, inv = np.unique(key, return_inverse=True)
    merge = csr_matrix((np.ones(n), (np.arange(n), np.asarray(inv).ravel())), shape=(n, len(used)))
    return (merge.T @ seen.T.astype(float)).T > 0


def ensemble_embedding(
    histories: Sequence[tuple[np.ndarray, np.ndarray | None]],
    sensor: str,
    method: str | None = None,
    *,
    anchor_ids: np.ndarray,
    anchor_positions: np.ndarray,
    param_sets: Sequence[dict[str, Any]] = ({},),
    max_iter: int = 300,
    combine: str = "mean",
) -> MaskedMap:
    """Mean of :func:`~mappers.masked.pair_maps.masked_embedding` maps over several histories of the same
    objects and several parameter sets, anchors held fixed (all maps are then in their frame).

    Args:
        histories: ``(X, mask)`` pairs, e.g. one run at several windows (same objects, same rows).
        sensor, method: as for :func:`~mappers.masked.pair_maps.masked_embedding` (one method for all).
        anchor_ids, anchor_positions: required: without fixed anchors the members' frames differ.
        param_sets: parameter overrides; every history is mapped with every set.
        combine: ``"mean"`` or ``"median"`` (:func:`geometric_median`) of the members' positions;
            with ``"median"`` a member whose pair graph falls apart with no group held by 2
            anchors (it places nothing) is left out, with a warning (ValueError if all are).

    Returns a :class:`~mappers.masked.pair_maps.MaskedMap` whose ``positions`` are the mean of
    the members' (an object unmapped in any member is unmapped) or their geometric median (over
    the members that place the object), ``delta``/``weights`` the members' means,
    ``components`` those of the member with the most components, ``warnings`` the union, and
    ``params`` ``{"members": [...params of each member...]}``.
    """
    if anchor_ids is None or anchor_positions is None:
        raise ValueError("ensemble_embedding needs anchor_ids and anchor_positions (a common frame)")
    if len(histories) == 0:
        raise ValueError("histories must hold at least one (X, mask) pair")
    if len(param_sets) == 0:
        raise ValueError("param_sets must hold at least one parameter dict")
    if combine not in COMBINE:
        raise ValueError(f"combine must be one of {COMBINE}, got {combine!r}")
    members, failed = [], []
    for k, (X, mask) in enumerate(histories):
        for ps in param_sets:
            try:
                members.append(masked_embedding(X, mask, sensor, method, anchor_ids=anchor_ids,
                                                anchor_positions=anchor_positions,
                                                max_iter=max_iter, **ps))
            except UnanchoredGraphError as exc:  # it can place nothing in the anchors' frame
                if combine == "mean":
                    raise
                failed.append(f"history {k} with {dict(ps)}: {exc}")
    if not members:
        raise ValueError(f"no member of the ensemble could be mapped; {failed[0]}")
    shapes = {m.positions.shape for m in members}
    if len(shapes) != 1:
        raise ValueError(f"histories must describe the same objects, got maps of shapes {shapes}")
    stack = np.stack([m.positions for m in members])
    positions = stack.mean(axis=0) if combine == "mean" else geometric_median(stack)
    extra = {} if combine == "mean" else {"spread": member_spread(stack, positions, anchor_ids,
                                                                   anchor_positions)}
    msgs: list[str] = [f"{len(failed)} of {len(failed) + len(members)} members placed nothing "
                       f"in the anchors' frame and are left out of the median (first: "
                       f"{failed[0]})"] if failed else []
    for m in members:
        msgs.extend(w for w in m.warnings if w not in msgs)
    return MaskedMap(
        positions=positions,
        method=members[0].method,
        params={"members": [dict(m.params) for m in members], **extra},
        delta=np.mean([m.delta for m in members], axis=0),
        weights=np.mean([m.weights for m in members], axis=0),
        components=max(members, key=lambda m: len(m.components)).components,
        unmapped=tuple(int(i) for i in np.flatnonzero(np.isnan(positions).any(axis=1))),
        warnings=tuple(msgs),
    )


class CovisEnsemble(TransformerMixin, BaseEstimator):
    """``"COVIS-ENSEMBLE"``: the mean of anchored co-observation maps over windows of steps.

    Parameters:
        windows: the windows [ticks] the history is merged over, one member map each.
        min_co: the members' ``min_co``, one member map each (with each window).
        member: ``"covis-power"`` or ``"covis-nonmetric"``.
        power: covis-power's exponent (None: its default; only with ``member="covis-power"``).
        max_iter: the members' SMACOF updates.
        combine: ``"mean"`` of the members' maps or each object's geometric ``"median"``
            (robust to a member that failed; the default for logs of sightings,
            :mod:`mappers.defaults`).
        max_spread: with ``combine="median"`` on a visibility history: when the members scatter
            about their median by more than this share of the anchors' spread
            (:func:`member_spread`: too few co-observations for the members to agree), the map
            is ``DROPOUT-BLEND``'s of the same history instead, with a warning. None: never.

    Uses only the pattern of what was observed, so any sensor's history serves.
    ``fit(X, mask=None, *, sensor=None, anchor_ids, anchor_positions, timeline=None)`` needs the
    anchors: the members meet in their frame.

    Attributes:
        embedding_ (M, 2) (NaN rows: unmapped); result_ the :class:`MaskedMap` of the mean (its
        notes issued as :class:`MaskedMapWarning`); n_features_in_.
    """

    _parameter_constraints: dict = {
        "windows": ["array-like", Interval(Integral, 1, None, closed="left")],
        "min_co": ["array-like", Interval(Integral, 1, None, closed="left")],
        "member": [StrOptions(set(MEMBERS))],
        "power": [Interval(Real, 0, None, closed="neither"), None],
        "max_iter": [Interval(Integral, 1, None, closed="left")],
        "combine": [StrOptions(set(COMBINE))],
        "max_spread": [Interval(Real, 0, None, closed="neither"), None],
    }

    def __init__(self, *, windows: Sequence[int] = (2, 3, 4, 6, 8, 10),
                 min_co: Sequence[int] = (3, 5), member: str = "covis-power",
                 power: float | None = None, max_iter: int = 300, combine: str = "mean",
                 max_spread: float | None = None) -> None:
        store_params(self, locals())

    def fit(self, X, y=None, *, mask=None, sensor: str | None = None, anchor_ids=None,
            anchor_positions=None, timeline=None):
        """Map the history ``X`` (M, D) (``mask`` True where observed) with the anchors."""
        self._validate_params()
        windows = tuple(int(w) for w in np.atleast_1d(self.windows))
        min_co = tuple(int(m) for m in np.atleast_1d(self.min_co))
        if not windows or min(windows) < 1 or not min_co:
            raise ValueError(f"windows must be positive integers and min_co non-empty, got "
                             f"windows={self.windows!r}, min_co={self.min_co!r}")
        if self.power is not None and self.member != "covis-power":
            raise ValueError("power applies to member='covis-power' only")
        X, mask, sensor = check_history(self, X, y, mask=mask, sensor=sensor)
        if self.max_spread is not None and (self.combine != "median" or sensor != "visibility"):
            raise ValueError(f"max_spread applies to combine='median' on visibility histories, "
                             f"got combine={self.combine!r}, sensor={sensor!r}")
        seen, _ = step_observations(X, mask, sensor)
        extra = {} if self.power is None else {"power": float(self.power)}
        hists = [(window_steps(seen, w, timeline).astype(float), None) for w in windows]
        self.result_ = ensemble_embedding(
            hists, "visibility", self.member, anchor_ids=anchor_ids,
            anchor_positions=anchor_positions, max_iter=self.max_iter,
            param_sets=[{"min_co": m, **extra} for m in min_co], combine=self.combine,
        )
        for msg in self.result_.warnings:
            warnings.warn(msg, MaskedMapWarning, stacklevel=2)
        self.embedding_ = self.result_.positions
        spread = self.result_.params.get("spread", float("nan"))
        if self.max_spread is not None and not spread <= self.max_spread:
            warnings.warn(f"COVIS-ENSEMBLE: its members scatter by {spread:.2f} of the anchors' "
                          f"spread about their median (above max_spread = {self.max_spread}): "
                          "too few co-observations for them to agree, so the map is "
                          "DROPOUT-BLEND's", MaskedMapWarning, stacklevel=2)
            self.embedding_ = DropoutBlend().fit_transform(
                X, mask=mask, sensor=sensor, anchor_ids=anchor_ids,
                anchor_positions=anchor_positions, timeline=timeline)
        return self

    def fit_transform(self, X, y=None, *, mask=None, sensor: str | None = None, anchor_ids=None,
                      anchor_positions=None, timeline=None) -> np.ndarray:
        """Fit and return the (M, 2) map (NaN rows: unmapped)."""
        return self.fit(X, mask=mask, sensor=sensor, anchor_ids=anchor_ids,
                        anchor_positions=anchor_positions, timeline=timeline).embedding_
