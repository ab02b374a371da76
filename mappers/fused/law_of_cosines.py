"""Pose-free distances between objects from range and bearing measured in the same frame.

Two objects i, j sensed in one step at ranges r_i, r_j and bearings theta_i, theta_j (both
relative to the robot's unknown heading) are ``d_ij`` apart by the law of cosines,

    d_ij^2 = r_i^2 + r_j^2 - 2 r_i r_j cos(theta_i - theta_j),

whatever the robot's position and heading: the pose drops out, so no localisation is needed.
Each step that senses both objects gives one sample of ``d_ij``; :func:`pooled_frame_distances`
pools the samples of a pair robustly (median, with the spread as a robust scale), and the
weights of the pairs follow the precision of a median, ``n / s^2`` (Huber & Ronchetti, *Robust
Statistics*, 2009, §3.2: the median's asymptotic variance is ``pi s^2 / (2 n)`` for Gaussian
samples of scale s).

The same frames also carry what distances cannot: handedness. The local coordinates
``(r cos theta, r sin theta)`` of three objects in one frame are a rotated and translated, never
mirrored, copy of their true layout, so the sign of their triangle's area is the true one
(:func:`frame_triangles`, :func:`handedness_votes`).
"""

from __future__ import annotations

import numpy as np

from mappers.core.sensors import step_observations

__all__ = [
    "frame_triangles",
    "frame_values",
    "handedness_votes",
    "pooled_frame_distances",
    "sample_variance_model",
]

_MAD_TO_SIGMA = 1.4826  # the median absolute deviation of a Gaussian is 0.6745 sigma


def frame_values(
    histories: dict[str, np.ndarray], masks: dict[str, np.ndarray | None]
) -> tuple[np.ndarray, np.ndarray]:
    """Per-step ranges and bearings ((M, N) each, NaN where the step did not sense the object in
    both) from fused ``range`` and ``bearing`` histories (:func:`mappers.core.sensors.step_observations`)."""
    seen_r, r = step_observations(histories["range"], masks.get("range"), "range")
    seen_b, b = step_observations(histories["bearing"], masks.get("bearing"), "bearing")
    both = seen_r & seen_b
    return np.where(both, r, np.nan), np.where(both, b, np.nan)


def _row_weighted_medians(d: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted median of each row of ``d`` (weights ``w``, 0 where ``d`` is NaN; 0 for a row
    without weight): the smallest value whose cumulative weight reaches half the row's."""
    order = np.argsort(np.where(w > 0, d, np.inf), axis=1)
    ds, cw = np.take_along_axis(d, order, axis=1), np.cumsum(np.take_along_axis(w, order, axis=1), axis=1)
    total = cw[:, -1:]
    k = np.minimum(np.argmax(cw >= 0.5 * total, axis=1), d.shape[1] - 1)
    med = np.take_along_axis(ds, k[:, None], axis=1)[:, 0]
    return np.where(total[:, 0] > 0, med, 0.0)


def _pair_samples(r, c, s, i, js):
    """Law-of-cosines distances of object i with objects js in every step ((len(js), N), NaN
    where a pair was not sensed together) and ``r_i^2 + r_j^2``."""
    cos_ij = c[i] * c[js] + s[i] * s[js]  # cos(theta_i - theta_j), no angle wrapping needed
    q = r[i] ** 2 + r[js] ** 2
    return np.sqrt(np.maximum(q - 2.0 * r[i] * r[js] * cos_ij, 0.0)), q


def sample_variance_model(
    r: np.ndarray, theta: np.ndarray, n_bins: int = 20, max_samples: int = 200_000
) -> tuple[float, float]:
    """``(alpha, beta)`` of the variance of one distance sample, ``alpha + beta (r_i^2 + r_j^2)``:
    range noise adds a constant, bearing noise moves each object sideways by its range times the
    error. Fitted by least squares to robust variances (median squared deviation from the pair's
    median / 0.455, the median of a chi-square of one degree) in ``n_bins`` quantile bins of
    ``r_i^2 + r_j^2``, so misread samples do not inflate it. Every k-th step is used, k such
    that about ``max_samples`` samples enter the fit."""
    ok = np.isfinite(r) & np.isfinite(theta)
    c, s = np.where(ok, np.cos(theta), np.nan), np.where(ok, np.sin(theta), np.nan)
    rows = np.flatnonzero(ok.any(axis=1))
    seen = ok[rows].astype(float)
    stride = max(1, int(np.sum(seen @ seen.T) / 2 // max_samples))
    r, c, s = r[:, ::stride], c[:, ::stride], s[:, ::stride]  # every k-th step
    dev2, qs = [], []
    for a, i in enumerate(rows[:-1]):
        d, q = _pair_samples(r, c, s, i, rows[a + 1:])
        w = np.isfinite(d).astype(float)
        med = _row_weighted_medians(d, w)
        keep = w > 0
        dev2.append(((d - med[:, None]) ** 2)[keep])
        qs.append(q[keep])
    dev2, q = np.concatenate(dev2 or [np.zeros(0)]), np.concatenate(qs or [np.zeros(0)])
    if q.size < 2 * n_bins:
        return 1.0, 0.0
    edges = np.quantile(q, np.linspace(0, 1, n_bins + 1))
    b = np.clip(np.searchsorted(edges, q, side="right") - 1, 0, n_bins - 1)
    order = np.argsort(b, kind="stable")
    groups = np.split(order, np.flatnonzero(np.diff(b[order])) + 1)
    centre = np.array([np.median(q[g]) for g in groups])
    var = np.array([np.median(dev2[g]) / 0.455 for g in groups])
    (alpha, beta), *_ = np.linalg.lstsq(np.column_stack([np.ones_like(centre), centre]), var, rcond=None)
    alpha, beta = max(alpha, 0.0), max(beta, 0.0)
    if alpha + beta * np.median(q) <= 0:
        return 1.0, 0.0
    floor = 1e-3 * (alpha + beta * np.median(q))  # no sample infinitely precise
    return max(alpha, floor), beta


def pooled_frame_distances(
    r: np.ndarray, theta: np.ndarray, *, max_range: float | None = None, trim: float | None = 3.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per pair, the precision-weighted, trimmed mean law-of-cosines distance over the steps
    that sensed both objects: the mean of the samples within 3 robust scales of their weighted
    median (Huber & Ronchetti 2009, §3: trimming keeps a misread sample from moving it), or
    with ``trim=None`` that weighted median.

    A sample's weight is the inverse of its modelled variance (:func:`sample_variance_model`):
    a bearing error moves an object sideways in proportion to its range, so samples taken near
    both objects are the precise ones when bearings are the noisier (and a median of noisy
    distances is biased upwards, the more the noisier the samples).

    Args:
        r, theta: (M, N) ranges [m] and bearings [rad] per object and step, NaN where not sensed.
        max_range: ignore readings farther than this (None: keep all).
        trim: keep the samples within this many robust scales of the median (None: the
            weighted median itself, for errors far from Gaussian).

    Returns:
        ``(distance, spread, count)``, each (M, M) and symmetric: the trimmed mean distance
        (0 where no sample), the samples' robust scale (1.4826 x weighted median absolute
        deviation) and their effective number ``(sum w)^2 / sum w^2`` (0: never sensed together).
    """
    r = np.asarray(r, dtype=float)
    theta = np.asarray(theta, dtype=float)
    if r.shape != theta.shape or r.ndim != 2:
        raise ValueError(f"r and theta must be (M, N) arrays of one shape, got {r.shape} and {theta.shape}")
    if max_range is not None:
        r = np.where(r <= max_range, r, np.nan)
    alpha, beta = sample_variance_model(r, theta)
    m = r.shape[0]
    dist, spread, count = np.zeros((m, m)), np.zeros((m, m)), np.zeros((m, m))
    ok = np.isfinite(r) & np.isfinite(theta)
    c, s = np.where(ok, np.cos(theta), np.nan), np.where(ok, np.sin(theta), np.nan)
    rows = np.flatnonzero(ok.any(axis=1))
    for a, i in enumerate(rows[:-1]):
        js = rows[a + 1:]
        d, q = _pair_samples(r, c, s, i, js)
        w = np.where(np.isfinite(d), 1.0 / (alpha + beta * np.nan_to_num(q)), 0.0)
        med = _row_weighted_medians(d, w)
        sigma = _MAD_TO_SIGMA * _row_weighted_medians(np.abs(d - med[:, None]), w)
        dist[i, js], spread[i, js] = med, sigma
        if trim is not None:  # a median alone keeps only 64 % of a Gaussian sample's information
            kept = np.where(np.abs(d - med[:, None]) <= trim * sigma[:, None] + 1e-12, w, 0.0)
            sk = kept.sum(axis=1)
            mean = np.einsum("ij,ij->i", kept, np.nan_to_num(d)) / np.where(sk > 0, sk, 1.0)
            dist[i, js] = np.where(sk > 0, mean, med)
        sw, sw2 = w.sum(axis=1), (w**2).sum(axis=1)
        count[i, js] = np.where(sw2 > 0, sw**2 / np.where(sw2 > 0, sw2, 1.0), 0.0)
    return dist + dist.T, spread + spread.T, count + count.T


def frame_triangles(
    r: np.ndarray, theta: np.ndarray, objects: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of ``objects`` sensed together in one frame, and their handedness there.

    Each step that senses at least three of ``objects`` gives the triangles of the first sensed
    object with consecutive pairs of the others (enough to fix handedness). Returns ``(tri,
    sign)``: (T, 3) row indices into ``objects`` and (T,) the sign (+1 counter-clockwise, -1
    clockwise) of each triangle in the frame's local coordinates ``(r cos theta, r sin theta)``;
    nearly collinear triangles (area under 5 % of the frame's largest) are left out.
    """
    objects = np.asarray(objects, dtype=np.int64)
    x, y = r[objects] * np.cos(theta[objects]), r[objects] * np.sin(theta[objects])
    t, k = np.nonzero((np.isfinite(x) & np.isfinite(y)).T)  # by step, then object
    first = np.searchsorted(t, t)  # index of each step's first sensed object
    e = np.flatnonzero((np.arange(len(t)) > first)[:-1] & (t[1:] == t[:-1])) if len(t) else t
    a, b, c, step = k[first[e]], k[e], k[e + 1], t[e]
    area = ((x[b, step] - x[a, step]) * (y[c, step] - y[a, step])
            - (y[b, step] - y[a, step]) * (x[c, step] - x[a, step]))
    largest = np.zeros(x.shape[1])
    np.maximum.at(largest, step, np.abs(area))
    clear = np.abs(area) > 0.05 * largest[step]
    return np.column_stack([a, b, c])[clear], np.sign(area[clear])


def handedness_votes(tri: np.ndarray, sign: np.ndarray, positions: np.ndarray) -> tuple[int, int]:
    """How many of the frames' triangles (:func:`frame_triangles`) turn the same way in
    ``positions`` (rows of the same objects) and how many the other way; a mirrored or folded
    map gets many of the latter."""
    P = np.asarray(positions, dtype=float)
    a, b, c = P[tri[:, 0]], P[tri[:, 1]], P[tri[:, 2]]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    same = np.sign(area) == sign
    return int(same.sum()), int((~same).sum())
