"""Mapping from histories with missing observations (SPEC §7).

On real data a landmark is sensed in a few percent of the steps only (limited field of view,
occlusion, detection range), so a history is mostly *missing*, not zero. Filling the gaps with
zeros (what the paper's pipeline does to a visibility history) makes every rarely-seen landmark
look far from everything. The methods here use only what was observed and say which
assumptions they add:

``"range-quantile"`` (range sensor)
    Two landmarks ranged in the same step (same image) from an unknown viewpoint satisfy
    ``|r_i - r_j| <= d_ij`` (triangle inequality), with equality when the viewpoint is on the
    line through them. A high quantile (``quantile``, default 0.98) of ``|r_i - r_j|`` over the
    steps that observed both estimates ``d_ij``. Pairs observed together in fewer than
    ``min_pairs`` steps are missing; the rest are weighted by ``min(n_ij, weight_cap) /
    weight_cap``. Metric weighted SMACOF (``mappers.smacof.weighted_smacof``) with the anchors
    held at their known positions gives the map.
    *Assumes*: one step's ranges come from one viewpoint (bin no longer than a camera frame
    or two); over the run some viewpoints are nearly collinear with each observed pair
    (robots roam the whole area); ranges are calibrated (unbiased, metric).

``"range-bounds"`` (range sensor)
    ``range-quantile`` plus an upper bound from the field of view: two landmarks in one image
    are at most ``fov`` apart in bearing, so ``d_ij <= sqrt(r_i^2 + r_j^2 - 2 r_i r_j cos(fov))``
    (the ``upper_quantile`` of that over the shared steps). Starting from the range-quantile map,
    SMACOF iterates with each pair's target clipped to ``[L_ij, min(U_ij, (1 + slack) L_ij)]``
    (``L`` = the range-quantile estimate, which is a lower bound in nature: robots are rarely
    exactly collinear with far-apart pairs). *Assumes* additionally: the camera's full field of
    view ``fov`` (MRCLAM: |bearing| <= 0.61 rad, so 1.22 rad).

``"covis-nonmetric"`` (any sensor; uses only the pattern of what was observed)
    Co-observation counts ``C_ij`` (steps in which both were sensed) normalised by how often
    each was sensed (Ochiai / cosine, the missing-data analogue of the paper's L2-normalised
    visibility): ``delta_ij = -log(C_ij / sqrt(n_i n_j))``. Only the *order* of these
    dissimilarities is trusted: non-metric weighted SMACOF (isotonic regression of the map's
    distances on ``delta``, then a Guttman step) with weights ``sqrt(C_ij)`` and the anchors
    held fixed (they set the scale). Pairs seen together in fewer than ``min_co`` steps are
    treated as *lower bounds* (at least as far as any co-observed pair), not as measurements.
    *Assumes*: the chance of seeing two landmarks in one step falls monotonically with their
    distance, the same way everywhere (roughly uniform viewpoints and headings; one field of
    view for all robots).

``"covis-power"`` (any sensor; uses only the pattern of what was observed)
    ``covis-nonmetric``'s dissimilarity, weights and lower bounds, but with a *metric* link:
    the map's distances are fitted to ``a * delta**power`` (``delta = -log`` Ochiai
    co-observation coefficient; the scale ``a`` re-fitted by weighted least squares after every
    few Guttman steps, the anchors held fixed), started from the ``covis-nonmetric`` map. Why:
    the order of the co-observation rates leaves a 15-landmark map under-determined (the
    non-metric fit reaches near-zero stress far from the truth); one global link with a single
    exponent is far more constrained. MRCLAM (leave-one-run-out over power in {0.35, 0.5, 0.7,
    1}): 0.5 is chosen in every fold. *Assumes* additionally: one power law links distance and
    ``-log`` co-observation rate over the whole layout. Such a link is calibrated only across
    pairs that are measured together, so when the graph of usable pairs falls apart (a
    clustered layout) the method keeps the ``covis-nonmetric`` map and says so in a warning
    (MRCLAM DS6: the link fitted across the two groups inflates the 10-30 cm clusters, 0.96 m
    instead of 0.49 m; this fallback rule was written after seeing that run). Optional
    ``nearness`` (per object, e.g. :func:`parallax_nearness`) with ``nearness_weight`` w > 0
    multiplies the dissimilarity by ``(h_i h_j)**-w`` (see the parallax paragraph below: measured,
    no gain; off by default). *Assumes* additionally then: objects seen from close are
    co-observed less often at a given distance, and relative bearing parallax tracks closeness.

Ensembles (:func:`ensemble_embedding`; MRCLAM's ``"covis-ensemble"``)
    The mean of several masked maps of the *same* objects with the anchors held fixed (so all
    maps share the anchors' frame), e.g. ``covis-nonmetric`` on one run binned at several bin
    widths and with several ``min_co``. Why: on MRCLAM a single covis-nonmetric map moves by
    +-0.3 m with the bin width (the setting that is best on one run is not on another), while
    the mean over a fixed spread of settings is within 0.02 m of its best choice on every run
    (benchmarks/bench_mrclam.py). *Assumes* what its members assume; it adds no information,
    it removes the choice of one setting.

``"masked-euclidean"`` (any sensor; the plain SPEC §7 recipe, kept as a comparison)
    Root-mean-square difference of the two histories over the steps that observed both
    (pairs with fewer than ``min_pairs`` such steps missing), weighted SMACOF over the pairs
    that have it, anchors fixed. *Assumes*: a history difference is comparable across pairs —
    false for a narrow field of view, where co-observed bearings always differ by less than
    the field of view (measured: worse than ``covis-nonmetric``).

Bearing-specific statistics measured on MRCLAM (DS1-3) without gain, so bearing histories are
mapped from their pattern of what was seen: subtended angles of same-image pairs (quantiles: the
+-33 deg field of view saturates them beyond about 1.5 m and lined-up pairs look close; the
lower bounds ``d >= 2 r0 tan(alpha / 2)`` with r0 = 0.8 m are never active), ratios of
subtended angles within an image, betweenness of triples (fraction "k between i and j" vs the
triangle's angle at k), which side of each pair the viewpoints were on (fitted with a uniform
viewpoint model: consistent with the covisibility map already), adding the mean subtended angle
to the dissimilarity, and inverse-probability weighting of co-observations by the field-of-view
overlap. A forward model of co-observation under uniform viewpoints scores the ground truth worse
than the covisibility map.

Bearing parallax between images of one robot (:func:`parallax_nearness`; covis-power's
``nearness`` / ``nearness_weight``), measured on MRCLAM without a gain that holds. Between two
images of one robot 1.5-6 s apart, the robot's rotation shifts every bearing equally, so
differences of bearing changes are translation parallax, larger for nearer landmarks
(measured against range, which the method does not see: correlation 0.73-0.88 with
``s (sin b_i / r_i - sin b_j / r_j)`` at 1.5-6 s, 0.2-0.46 below 0.8 s, where the
0.004-0.012 rad bearing noise dominates). With a +-33 deg field of view one image pair cannot
separate rotation from translation (``s sin(b_k) / r_k`` is known only up to a common constant),
and metric depth needs the distance travelled (a motion model), so only statistics are
available. (1) The normalised parallax of a pair (``|d(b_i - b_j)|`` over the image pair's
median) as a factor or addend on the ``-log`` co-observation rate, or as a down-weighting of
co-observations: worse on every weight tried (mean MPE over DS1, 2, 3, 6 0.64 m -> 0.66-0.83 m;
down-weighting 0.64-0.66 m). (2) A landmark's relative nearness ``h`` (:func:`parallax_nearness`;
Spearman 0.47-0.83 with its median range on DS1-3) scaling the dissimilarity by
``(h_i h_j)**-w``: a landmark seen from close is co-observed less often at a given distance. The
same factor built from the true median range (not available to the method) gains 0.05 m (0.64 ->
0.59 m at w = 0.25, every run better); with ``h`` from parallax DS1 gains (0.63 -> 0.57 m), DS2
loses (0.80 -> 0.81 m), DS3 is flat, and DS6 (fallback map) goes from 0.49 to 0.89 m (hence the
factor is not applied when the pairs fall apart). Leave-one-run-out over w in {0, 0.04, 0.08,
0.12, 0.25} (power 0.5): DS1 0.628, DS2 0.813, DS3 0.655, DS6 0.488, mean 0.646 m, against
0.641 m without it. Over power {0.35, 0.5, 0.7, 1} x w it is also 0.646 m, below the 0.670 m of
the power grid alone (the visibility figure), but only because on DS2 the other runs then pick
power 0.5 instead of 0.35 (0.913 -> 0.813 m). At powers 0.7 and 1 the factor helps DS1-3 (mean
0.82 -> 0.73 m, 0.97 -> 0.87 m: it partly corrects a mis-set exponent), but at 0.5, which the
runs pick either way, the mean does not improve. No gain from parallax, so the bearing default
stays the covisibility ensemble.

Measured since, also without gain (``python benchmarks/bench_mrclam_bearing.py``): chaining one
robot's consecutive images through shared landmarks (a wider panorama) exceeds the field of view
for <= 0.13 % of the chained pairs; the rate of seeing a pair within 0.3 rad of each other (a
uniform-viewpoint argument makes it ~ 1 / distance) ranks distances worse than the co-observation
rate; clipping the field of view to a narrower, reliable part loses more than it cleans (LOO
0.67 -> 0.67-0.93 m); a per-landmark nearness from subtended angles over map distances does not
track range (Spearman -0.34-0.83); and the weak-perspective model (an image's bearings affine in
the positions, so the centred bearing matrix is rank 2 -- a PCA with missing data), fitted from
the true map, drifts 1.05-2.05 m on DS1-3 (0.09 m on DS6, clusters seen from afar); keeping only
the images that model fits within 3-10 mrad holds the true map on DS1-2 (0.02-0.15 m) but, started
from the covisibility map, it stays put or gets worse on every run (DS1 0.63 -> 0.65-3.5 m, DS6
0.49 -> 0.41-0.47 m): too few such images to pull a map out of its basin. Counting only pairs
adjacent in a bin's bearing order as co-observed (or half-weighting the others) is worse too
(LOO 0.67 -> 0.76-0.94 m), and so is co-observation within 0.9 rad rather than the whole field
of view (0.66 m, within the runs' noise).

Every method returns positions in the anchors' frame when anchors are given (the anchors are
held at their positions, so the affine fit that follows is the identity), else a free embedding.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components, shortest_path
from sklearn.isotonic import IsotonicRegression

from mappers.align import apply_affine, fit_affine
from mappers.smacof import classical_mds, weighted_smacof

__all__ = [
    "MASKED_METHODS",
    "MaskedMap",
    "build_masked_embedding",
    "co_observation_counts",
    "end_on_penalty",
    "ensemble_embedding",
    "covisibility_dissimilarity",
    "masked_embedding",
    "bounded_smacof",
    "masked_euclidean_dissimilarity",
    "nearness_factor",
    "range_pair_bounds",
    "nonmetric_smacof",
    "parallax_nearness",
    "power_link_smacof",
    "range_pair_distances",
    "step_observations",
]

MASKED_METHODS: dict[str, dict[str, Any]] = {
    "range-quantile": {"quantile": 0.98, "min_pairs": 5, "weight_cap": 50},
    "range-bounds": {"quantile": 0.98, "min_pairs": 5, "weight_cap": 50, "slack": 1.0,
                     "fov": 1.22, "upper_quantile": 0.02},
    "covis-nonmetric": {"min_co": 3},
    "covis-power": {"min_co": 3, "power": 0.5, "n_rounds": 60, "angle_weight": 0.0,
                    "nearness": None, "nearness_weight": 0.0},
    "masked-euclidean": {"min_pairs": 5},
}
"""Label -> default parameters of each masked method. The defaults were picked by measurement on
the four MRCLAM runs (so the default-setting scores there are in-sample); the leave-one-run-out
columns of benchmarks/bench_mrclam.py score settings chosen without the scored run."""

DEFAULT_METHOD = {
    "range": "range-quantile",
    "visibility": "covis-nonmetric",
    "bearing": "covis-nonmetric",
}
_COLUMNS = {"visibility": 1, "bearing": 2, "range": 1}


# ------------------------------------------------------------------------- observations
def step_observations(
    X: np.ndarray, mask: np.ndarray | None, sensor: str
) -> tuple[np.ndarray, np.ndarray]:
    """Per-step view of a (possibly masked) history matrix.

    Returns ``(seen, values)``: ``seen`` (M, N) bool, True where the object was sensed in the
    step; ``values`` (M, N) float: the 0/1 visibility, the bearing angle [rad] or the range [m]
    (NaN where not sensed). A visibility 0 or an unmasked range of 0 counts as not sensed.
    """
    if sensor not in _COLUMNS:
        raise ValueError(f"sensor must be one of {sorted(_COLUMNS)}, got {sensor!r}")
    X = np.asarray(X, dtype=float)
    if X.ndim != 2 or X.shape[1] % _COLUMNS[sensor]:
        raise ValueError(f"X must be (M, N*{_COLUMNS[sensor]}) for {sensor!r}, got {X.shape}")
    if mask is not None:
        mask = np.asarray(mask)
        if mask.dtype != np.bool_ or mask.shape != X.shape:
            raise ValueError(
                f"mask must be a bool array of shape {X.shape}, got {mask.dtype} {mask.shape}"
            )
    Xf = np.where(np.isfinite(X), X, 0.0)
    if sensor == "bearing":
        c, s = Xf[:, 0::2], Xf[:, 1::2]
        seen = (c != 0) | (s != 0)
        if mask is not None:
            seen &= mask[:, 0::2] & mask[:, 1::2]
        values = np.where(seen, np.arctan2(s, c), np.nan)
    else:
        seen = Xf > 0 if mask is None else (mask & np.isfinite(X))
        if sensor == "visibility":
            seen &= Xf > 0
        values = np.where(seen, Xf, np.nan)
    return seen, values


def co_observation_counts(seen: np.ndarray) -> np.ndarray:
    """(M, M) number of steps in which both objects were sensed (diagonal: each one's count)."""
    S = np.asarray(seen, dtype=float)
    return S @ S.T


# ---------------------------------------------------------------------- dissimilarities
def covisibility_dissimilarity(seen: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``-log`` of the Ochiai co-observation coefficient, and the co-observation counts.

    Returns ``(delta, C)``; pairs never seen together get ``delta = -log(1e-6)``.
    """
    C = co_observation_counts(seen)
    n = np.diag(C).copy()
    with np.errstate(divide="ignore", invalid="ignore"):
        och = C / np.sqrt(np.outer(n, n))
    och = np.nan_to_num(och, nan=0.0)
    delta = -np.log(np.clip(och, 1e-6, 1.0))
    np.fill_diagonal(delta, 0.0)
    return delta, C


def end_on_penalty(bearings: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """``max_kl a_kl - a_ij``: how much smaller the mean subtended angle ``a_ij`` of a pair
    (mean over the steps that saw both of ``|wrap(b_i - b_j)|``) is than the largest one.

    A pair seen mostly end-on (lined up from where the robots were) is co-observed from far
    along its line, so its co-observation rate overstates its closeness; its subtended angle
    is small. Pairs never seen together get 0 (they are censored anyway)."""
    M = seen.shape[0]
    a = np.full((M, M), np.nan)
    for i in range(M):
        for j in range(i + 1, M):
            both = seen[i] & seen[j]
            if both.any():
                a[i, j] = a[j, i] = np.mean(np.abs(np.angle(
                    np.exp(1j * (bearings[i, both] - bearings[j, both])))))
    if np.all(np.isnan(a)):
        return np.zeros((M, M))
    pen = np.nan_to_num(np.nanmax(a) - a, nan=0.0)
    np.fill_diagonal(pen, 0.0)
    return pen


def range_pair_distances(
    ranges: np.ndarray, seen: np.ndarray, *, quantile: float = 0.98, min_pairs: int = 5
) -> tuple[np.ndarray, np.ndarray]:
    """Distance estimates from same-step ranges: the ``quantile`` of ``|r_i - r_j|``.

    Returns ``(delta, counts)``; ``delta`` is 0 where ``counts < min_pairs`` (missing).
    """
    if not 0 < quantile <= 1:
        raise ValueError(f"quantile must be in (0, 1], got {quantile}")
    if min_pairs < 1:
        raise ValueError(f"min_pairs must be >= 1, got {min_pairs}")
    M = seen.shape[0]
    delta = np.zeros((M, M))
    counts = co_observation_counts(seen)
    for i in range(M):
        for j in range(i + 1, M):
            both = seen[i] & seen[j]
            if both.sum() >= min_pairs:
                delta[i, j] = delta[j, i] = np.quantile(
                    np.abs(ranges[i, both] - ranges[j, both]), quantile
                )
    counts[counts < min_pairs] = 0
    np.fill_diagonal(counts, 0)
    return delta, counts


def range_pair_bounds(
    ranges: np.ndarray, seen: np.ndarray, *, fov: float = 1.22, upper_quantile: float = 0.02,
    min_pairs: int = 5,
) -> np.ndarray:
    """Upper bounds on pair distances from same-step ranges and a field of view ``fov`` [rad]:
    the ``upper_quantile`` of ``sqrt(r_i^2 + r_j^2 - 2 r_i r_j cos(fov))``; inf where missing."""
    if not 0 < fov <= np.pi:
        raise ValueError(f"fov must be in (0, pi] radians, got {fov}")
    if not 0 <= upper_quantile <= 1:
        raise ValueError(f"upper_quantile must be in [0, 1], got {upper_quantile}")
    M = seen.shape[0]
    upper = np.full((M, M), np.inf)
    for i in range(M):
        for j in range(i + 1, M):
            both = seen[i] & seen[j]
            if both.sum() >= min_pairs:
                ri, rj = ranges[i, both], ranges[j, both]
                u = np.sqrt(np.maximum(ri**2 + rj**2 - 2 * ri * rj * np.cos(fov), 0.0))
                upper[i, j] = upper[j, i] = np.quantile(u, upper_quantile)
    np.fill_diagonal(upper, 0.0)
    return upper


def masked_euclidean_dissimilarity(
    values: np.ndarray, seen: np.ndarray, sensor: str, *, min_pairs: int = 5
) -> tuple[np.ndarray, np.ndarray]:
    """RMS difference of two histories over the steps that observed both (bearing: chord
    ``|e^{ib_i} - e^{ib_j}|``). Returns ``(delta, counts)``, counts 0 where missing."""
    M = seen.shape[0]
    delta = np.zeros((M, M))
    counts = co_observation_counts(seen)
    for i in range(M):
        for j in range(i + 1, M):
            both = seen[i] & seen[j]
            if both.sum() < min_pairs:
                counts[i, j] = counts[j, i] = 0
                continue
            a, b = values[i, both], values[j, both]
            diff2 = 2 - 2 * np.cos(a - b) if sensor == "bearing" else (a - b) ** 2
            delta[i, j] = delta[j, i] = np.sqrt(np.mean(diff2))
    np.fill_diagonal(counts, 0)
    return delta, counts


def parallax_nearness(
    robot: np.ndarray,
    time: np.ndarray,
    landmark: np.ndarray,
    bearing: np.ndarray,
    n_objects: int,
    *,
    dt_min: float = 1.5,
    dt_max: float = 6.0,
    min_common: int = 3,
    min_samples: int = 5,
) -> np.ndarray:
    """Relative nearness of each landmark from bearing parallax between two images of one robot.

    Rows sharing ``(robot, time)`` are one image. Each image is paired with the first later image
    of the same robot at least ``dt_min`` s later (skipped if more than ``dt_max`` s later). Over
    the ``n >= min_common`` landmarks seen in both, the robot's rotation shifts every bearing
    equally, so ``e_k = |dtheta_k - mean_{l != k} dtheta_l|`` is translation parallax only
    (larger for nearer landmarks); it is divided by the image pair's median ``|dtheta_k -
    dtheta_l|`` (which removes the unknown distance travelled). A landmark's nearness is the
    median of its ``e_k`` over the image pairs (NaN with fewer than ``min_samples``).

    Only bearings, timestamps and landmark identities are used: no pose, motion or range. The
    per-pair rotation/translation ambiguity of a narrow field of view is not resolved; this is a
    statistic (MRCLAM DS1-3: Spearman 0.47-0.83 with a landmark's median range, which it does
    not see), not a depth estimate.
    """
    robot, time, landmark, bearing = (np.asarray(a) for a in (robot, time, landmark, bearing))
    n = len(robot)
    if not (len(time) == len(landmark) == len(bearing) == n):
        raise ValueError("robot, time, landmark and bearing must have the same length")
    if n_objects < 1:
        raise ValueError(f"n_objects must be >= 1, got {n_objects}")
    if not 0 < dt_min <= dt_max:
        raise ValueError(f"need 0 < dt_min <= dt_max, got dt_min={dt_min}, dt_max={dt_max}")
    if min_common < 3:
        raise ValueError(f"min_common must be >= 3 (2 landmarks carry no per-landmark term), got {min_common}")
    lm = landmark.astype(np.int64)
    if n and (lm.min() < 0 or lm.max() >= n_objects):
        raise ValueError(f"landmark indices must lie in [0, {n_objects})")
    samples: list[list[float]] = [[] for _ in range(n_objects)]
    for r in np.unique(robot):
        sel = robot == r
        ts, img = np.unique(time[sel], return_inverse=True)
        lms, brg = lm[sel], bearing[sel].astype(float)
        images = [dict(zip(lms[img == k].tolist(), brg[img == k].tolist(), strict=True))
                  for k in range(len(ts))]
        for a in range(len(ts)):
            b = int(np.searchsorted(ts, ts[a] + dt_min))
            if b >= len(ts) or ts[b] - ts[a] > dt_max:
                continue
            common = sorted(set(images[a]) & set(images[b]))
            m = len(common)
            if m < min_common:
                continue
            dth = np.angle(np.exp(1j * np.array([images[b][k] - images[a][k] for k in common])))
            e = np.abs(dth - (dth.sum() - dth) / (m - 1))
            iu = np.triu_indices(m, 1)
            scale = np.median(np.abs(dth[:, None] - dth[None])[iu])
            if scale <= 0:
                continue
            for k, ek in zip(common, e / scale, strict=True):
                samples[k].append(float(ek))
    return np.array([np.median(s) if len(s) >= min_samples else np.nan for s in samples])


def nearness_factor(nearness: np.ndarray | None, weight: float, n_objects: int) -> np.ndarray:
    """(M, M) factor ``(h_i h_j)**(-weight)`` on a covisibility dissimilarity, ``h`` = nearness
    over its geometric mean (missing -> the median, floored at 0.05). Why: a landmark seen from
    close is co-observed less often at a given distance than one seen from afar, so its
    ``-log`` co-observation rate overstates its distances."""
    if nearness is None:
        raise ValueError("nearness_weight needs nearness (e.g. from parallax_nearness)")
    if weight < 0:
        raise ValueError(f"nearness_weight must be >= 0, got {weight}")
    h = np.asarray(nearness, dtype=float)
    if h.shape != (n_objects,):
        raise ValueError(f"nearness must have shape ({n_objects},), got {h.shape}")
    if not np.isfinite(h).any():
        raise ValueError("nearness has no finite entry")
    h = np.maximum(np.where(np.isfinite(h), h, np.nanmedian(h)), 0.05)
    h = h / np.exp(np.mean(np.log(h)))
    F = np.outer(h, h) ** (-float(weight))
    np.fill_diagonal(F, 1.0)
    return F


# ------------------------------------------------------------------------------ solvers
def _components(weights: np.ndarray) -> list[list[int]]:
    n, labels = connected_components(csr_matrix(weights > 0), directed=False)
    return [np.flatnonzero(labels == k).tolist() for k in range(n)]


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


def nonmetric_smacof(
    delta: np.ndarray,
    weights: np.ndarray,
    init: np.ndarray,
    *,
    censored: np.ndarray | None = None,
    fixed: np.ndarray | None = None,
    fixed_positions: np.ndarray | None = None,
    max_iter: int = 300,
    tol: float = 1e-6,
) -> np.ndarray:
    """Non-metric (ordinal) weighted SMACOF, optionally with fixed points and lower bounds.

    Each iteration fits disparities by isotonic regression of the current distances on
    ``delta`` (pairs with weight > 0 and not ``censored``), sets each censored pair's
    disparity to its current distance clipped to [t, u] (t = largest fitted disparity: a
    censored pair is at least as far as any measured one; u = max(2 t, 1.5 x the fixed points'
    diameter) only stops a point held by nothing but lower bounds from drifting away), then takes one Guttman step of
    :func:`mappers.smacof.weighted_smacof`. sklearn's non-metric MDS has neither weights nor
    fixed points nor bounds, hence this loop. Without fixed points the disparities are scaled
    to a constant weighted sum of squares (Kruskal's normalisation).
    """
    delta = np.asarray(delta, dtype=float)
    W = np.asarray(weights, dtype=float).copy()
    np.fill_diagonal(W, 0.0)
    n = len(delta)
    iu = np.triu_indices(n, 1)
    cens = np.zeros((n, n), bool) if censored is None else np.asarray(censored, bool)
    w = W[iu]
    obs = (w > 0) & ~cens[iu]
    cen = (w > 0) & cens[iu]
    if obs.sum() < 2:
        raise ValueError("nonmetric_smacof needs at least 2 measured (weighted, uncensored) pairs")
    X = np.array(init, dtype=float)
    if fixed is not None and fixed_positions is not None:
        X[np.asarray(fixed)] = fixed_positions
    iso = IsotonicRegression(increasing=True)
    scale = np.sqrt(np.sum(w[obs | cen]))
    span = 0.0
    if fixed is not None and len(np.atleast_1d(fixed)) > 1:
        F = X[np.asarray(fixed)]
        span = float(np.max(np.linalg.norm(F[:, None] - F[None], axis=2)))
    for _ in range(max_iter):
        d = np.linalg.norm(X[iu[0]] - X[iu[1]], axis=1)
        dh = np.zeros_like(d)
        dh[obs] = iso.fit_transform(delta[iu][obs], d[obs], sample_weight=w[obs])
        if cen.any():
            t = dh[obs].max()
            dh[cen] = np.clip(d[cen], t, max(2 * t, 1.5 * span))
        if fixed is None:
            norm = np.sqrt(np.sum(w * dh**2))
            if norm > 0:
                dh *= scale / norm
        T = np.zeros((n, n))
        T[iu] = dh
        T = T + T.T
        X_new, _, _ = weighted_smacof(T, W, X, fixed=fixed, max_iter=1, tol=0.0)
        step = np.abs(X_new - X).max()
        X = X_new
        if step <= tol * max(np.abs(X).max(), 1e-12):
            break
    return X


def power_link_smacof(
    delta: np.ndarray,
    weights: np.ndarray,
    init: np.ndarray,
    *,
    power: float = 0.5,
    censored: np.ndarray | None = None,
    fixed: np.ndarray | None = None,
    fixed_positions: np.ndarray | None = None,
    n_rounds: int = 60,
    steps_per_round: int = 5,
) -> tuple[np.ndarray, float]:
    """Weighted SMACOF on targets ``a * delta**power`` with the scale ``a`` re-fitted each round.

    Each round sets ``a`` to the weighted least-squares fit of the current distances on
    ``delta**power`` over the measured (weighted, uncensored) pairs, gives each censored pair
    the target ``clip(d, t, max(2 t, 1.5 x fixed points' diameter))`` (t = largest measured
    target: a lower bound, as in :func:`nonmetric_smacof`), then takes ``steps_per_round``
    Guttman steps of :func:`mappers.smacof.weighted_smacof`. Returns ``(X, a)``. A monotone
    link with one free exponent instead of the isotonic one of :func:`nonmetric_smacof`
    (sklearn's MDS has neither weights, fixed points nor a parametric link).
    """
    if not power > 0:
        raise ValueError(f"power must be > 0, got {power}")
    if n_rounds < 1 or steps_per_round < 1:
        raise ValueError("n_rounds and steps_per_round must be >= 1")
    delta = np.asarray(delta, dtype=float)
    W = np.asarray(weights, dtype=float).copy()
    np.fill_diagonal(W, 0.0)
    n = len(delta)
    cens = np.zeros((n, n), bool) if censored is None else np.asarray(censored, bool)
    meas = (W > 0) & ~cens
    if meas.sum() < 4:
        raise ValueError("power_link_smacof needs at least 2 measured (weighted, uncensored) pairs")
    X = np.array(init, dtype=float)
    if fixed is not None and fixed_positions is not None:
        X[np.asarray(fixed)] = fixed_positions
    span = 0.0
    if fixed is not None and len(np.atleast_1d(fixed)) > 1:
        F = X[np.asarray(fixed)]
        span = float(np.max(np.linalg.norm(F[:, None] - F[None], axis=2)))
    dp = np.maximum(delta, 0.0) ** power
    a = 1.0
    for _ in range(n_rounds):
        D = np.linalg.norm(X[:, None] - X[None], axis=2)
        den = np.sum(W[meas] * dp[meas] ** 2)
        a = float(np.sum(W[meas] * D[meas] * dp[meas]) / den) if den > 0 else 1.0
        T = a * dp
        t = T[meas].max()
        T = np.where(cens, np.clip(D, t, max(2 * t, 1.5 * span)), T)
        np.fill_diagonal(T, 0.0)
        X, _, _ = weighted_smacof(T, W, X, fixed=fixed, max_iter=steps_per_round, tol=0.0)
    return X, a


def bounded_smacof(
    lower: np.ndarray,
    upper: np.ndarray,
    weights: np.ndarray,
    init: np.ndarray,
    *,
    fixed: np.ndarray | None = None,
    fixed_positions: np.ndarray | None = None,
    max_iter: int = 500,
    tol: float = 1e-7,
) -> np.ndarray:
    """Weighted SMACOF on distance *intervals*: each iteration's target for a pair is its current
    distance clipped to ``[lower, upper]`` (zero stress inside the interval), then one Guttman
    step of :func:`mappers.smacof.weighted_smacof` (box-constrained stress; sklearn has none)."""
    lower = np.asarray(lower, dtype=float)
    upper = np.maximum(np.asarray(upper, dtype=float), lower)
    X = np.array(init, dtype=float)
    if fixed is not None and fixed_positions is not None:
        X[np.asarray(fixed)] = fixed_positions
    for _ in range(max_iter):
        D = np.linalg.norm(X[:, None] - X[None], axis=2)
        T = np.clip(D, lower, upper)
        np.fill_diagonal(T, 0.0)
        X_new, _, _ = weighted_smacof(T, weights, X, fixed=fixed, max_iter=1, tol=0.0)
        step = np.abs(X_new - X).max()
        X = X_new
        if step <= tol * max(np.abs(X).max(), 1e-12):
            break
    return X


# ---------------------------------------------------------------------------- entry points
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
        method: a key of :data:`MASKED_METHODS`; None = ``"range-quantile"`` for range,
            else ``"covis-nonmetric"``.
        anchor_ids, anchor_positions: anchors held fixed at their positions (recommended; the
            non-metric method needs them to know the scale of the map).
        **params: overrides of the method's defaults.
    """
    method = DEFAULT_METHOD.get(sensor, "covis-nonmetric") if method is None else method
    if method not in MASKED_METHODS:
        raise ValueError(f"method must be one of {sorted(MASKED_METHODS)}, got {method!r}")
    unknown = set(params) - set(MASKED_METHODS[method])
    if unknown:
        raise ValueError(f"unknown parameter(s) {sorted(unknown)} for method {method!r}")
    if method.startswith("range-") and sensor != "range":
        raise ValueError(f"method {method!r} needs a range history, got sensor {sensor!r}")
    p = {**MASKED_METHODS[method], **params}
    seen, values = step_observations(X, mask, sensor)
    M = seen.shape[0]
    never = np.flatnonzero(~seen.any(axis=1))
    if anchor_ids is not None:
        anchor_ids = np.asarray(anchor_ids, dtype=np.int64)
        anchor_positions = np.asarray(anchor_positions, dtype=float)
        if anchor_positions.shape != (anchor_ids.size, 2):
            raise ValueError(
                f"anchor_positions must have shape ({anchor_ids.size}, 2), got {anchor_positions.shape}"
            )
        if anchor_ids.size < 3:
            raise ValueError(f"need at least 3 anchors, got {anchor_ids.size}")
        if anchor_ids.min() < 0 or anchor_ids.max() >= M:
            raise ValueError(f"anchor_ids must lie in [0, {M})")
        if np.isin(anchor_ids, never).any():
            raise ValueError(f"anchor(s) {sorted(set(anchor_ids) & set(never))} were never sensed")
    msgs: list[str] = []
    keep = np.setdiff1d(np.arange(M), never)
    if len(keep) < 3:
        raise ValueError(f"only {len(keep)} object(s) were ever sensed; need at least 3")
    sub_anchor = None if anchor_ids is None else np.searchsorted(keep, anchor_ids)

    s, v = seen[keep], values[keep]
    censored = None
    if method.startswith("range-"):
        delta, counts = range_pair_distances(v, s, quantile=p["quantile"], min_pairs=p["min_pairs"])
        W = np.minimum(counts, p["weight_cap"]) / p["weight_cap"]
    elif method == "masked-euclidean":
        delta, counts = masked_euclidean_dissimilarity(v, s, sensor, min_pairs=p["min_pairs"])
        W = (counts > 0).astype(float)
    else:
        delta, C = covisibility_dissimilarity(s)
        if p.get("angle_weight", 0.0):
            if sensor != "bearing":
                raise ValueError(f"angle_weight needs a bearing history, got sensor {sensor!r}")
            if p["angle_weight"] < 0:
                raise ValueError(f"angle_weight must be >= 0, got {p['angle_weight']}")
            delta = delta + p["angle_weight"] * end_on_penalty(v, s)
        delta_plain = delta
        if p.get("nearness_weight", 0.0):
            delta = delta * nearness_factor(p.get("nearness"), p["nearness_weight"], M)[
                np.ix_(keep, keep)]
        Cn = C.copy()
        np.fill_diagonal(Cn, 0)
        W = np.sqrt(np.maximum(Cn, 1.0))
        W /= W.max()
        np.fill_diagonal(W, 0.0)
        censored = Cn < p["min_co"]
        counts = np.where(censored, 0, Cn)
    comps = _components(counts)
    comps_full = [[int(keep[i]) for i in c] for c in comps]  # the data's groups, object ids
    all_anchors = (anchor_ids, anchor_positions)
    if sub_anchor is not None and len(comps) > 1:
        # A group held by fewer than 2 anchors has no measured scale or rotation in the
        # anchors' frame (non-metric stress and lower bounds then push it off to kilometres):
        # its objects are left unmapped (its anchor, if any, stays at its known position)
        # rather than drawn with false confidence.
        loose = [c for c in comps if np.isin(c, sub_anchor).sum() < 2]
        if len(loose) == len(comps):
            raise ValueError(
                "the graph of usable pairs falls apart and no group holds 2 or more anchors "
                f"(groups {[[int(keep[i]) for i in c] for c in comps]}, anchors "
                f"{anchor_ids.tolist()}): nothing can be placed in the anchors' frame"
            )
        if loose:
            drop = np.concatenate([np.asarray(c, dtype=np.int64) for c in loose])
            lost = sorted(int(keep[i]) for i in drop if keep[i] not in set(anchor_ids.tolist()))
            msgs.append(
                f"object(s) (rows) {lost} are unmapped: the graph of usable pairs falls apart and "
                "their group holds fewer than 2 anchors, so its scale and rotation are not "
                "measured (choose at least 2 anchors in every group)"
            )
            sel = np.setdiff1d(np.arange(len(keep)), drop)
            ix = np.ix_(sel, sel)
            delta, W, counts = delta[ix], W[ix], counts[ix]
            if censored is not None:
                censored, delta_plain = censored[ix], delta_plain[ix]
            s, v, keep = s[sel], v[sel], keep[sel]
            kept = np.isin(anchor_ids, keep)
            anchor_ids, anchor_positions = anchor_ids[kept], anchor_positions[kept]
            sub_anchor = np.searchsorted(keep, anchor_ids)
            comps = [[int(i) for i in np.searchsorted(sel, c)] for c in comps
                     if np.isin(c, sel).all()]
    if method == "covis-power" and len(comps) > 1 and p.get("nearness_weight", 0.0):
        # the fallback keeps the pattern-only covis-nonmetric map: no nearness factor either
        # (MRCLAM DS6: the factor moves its clustered map by up to 0.4 m; rule set after seeing it)
        delta = delta_plain
        msgs.append("covis-power: nearness_weight not applied (the usable pairs fall apart)")
    if method in ("covis-nonmetric", "covis-power"):
        start = _initial(
            np.where(censored, 0, delta), counts.astype(float), sub_anchor, anchor_positions
        )
        Y = nonmetric_smacof(
            delta,
            W,
            start,
            censored=censored,
            fixed=sub_anchor,
            fixed_positions=anchor_positions,
            max_iter=max_iter,
        )
        if method == "covis-power" and len(comps) > 1:
            msgs.append(
                "covis-power: the usable pairs fall apart, so one distance link cannot be "
                "calibrated across the groups; kept the covis-nonmetric map"
            )
        elif method == "covis-power":
            Y, _ = power_link_smacof(
                delta, W, Y, power=p["power"], censored=censored, fixed=sub_anchor,
                fixed_positions=anchor_positions, n_rounds=p["n_rounds"],
            )
    else:
        start = _initial(delta, W, sub_anchor, anchor_positions)
        Y, _, _ = weighted_smacof(
            delta, W, start, fixed=sub_anchor, fixed_positions=anchor_positions, max_iter=max_iter
        )
        if method == "range-bounds":
            if p["slack"] < 0:
                raise ValueError(f"slack must be >= 0, got {p['slack']}")
            upper = range_pair_bounds(v, s, fov=p["fov"], upper_quantile=p["upper_quantile"],
                                      min_pairs=p["min_pairs"])
            upper = np.minimum(upper, (1.0 + p["slack"]) * delta)
            Y = bounded_smacof(delta, upper, W, Y, fixed=sub_anchor,
                               fixed_positions=anchor_positions, max_iter=max(max_iter, 500))
        if method == "masked-euclidean" and sub_anchor is not None:
            # a history difference has no metric scale: the anchors can only fix an affine frame
            free, _, _ = weighted_smacof(delta, W, start, max_iter=max_iter)
            Y = apply_affine(free, fit_affine(free[sub_anchor], anchor_positions))
    if len(comps_full) > 1:
        sizes = sorted((len(c) for c in comps_full), reverse=True)
        msgs.append(
            f"the graph of usable pairs falls apart into {len(comps_full)} components (sizes {sizes}): "
            "the relative placement of the components is not measured"
        )
    positions = np.full((M, 2), np.nan)
    positions[keep] = Y
    if all_anchors[0] is not None:  # anchors of unmapped groups stay at their known positions
        positions[all_anchors[0]] = all_anchors[1]
    D_full = np.zeros((M, M))
    W_full = np.zeros((M, M))
    D_full[np.ix_(keep, keep)] = delta
    W_full[np.ix_(keep, keep)] = W
    if never.size:
        msgs.append(f"object(s) {never.tolist()} were never sensed and are unmapped")
    return MaskedMap(
        positions=positions,
        method=method,
        params=p,
        delta=D_full,
        weights=W_full,
        components=comps_full,
        unmapped=tuple(int(i) for i in np.flatnonzero(np.isnan(positions).any(axis=1))),
        warnings=tuple(msgs),
    )


def build_masked_embedding(
    X: np.ndarray, mask: np.ndarray | None, method: str | None, sensor: str, **params: Any
) -> np.ndarray:
    """Hook for ``mappers.build_map(..., mask=...)``: an (M, 2) embedding (NaN rows unmapped).

    ``method`` may be a key of :data:`MASKED_METHODS` (anything else, e.g. a paper label, falls
    back to the sensor's default masked method). Pass ``anchor_ids`` and ``anchor_positions``
    in ``params`` to get positions with the anchors held fixed (the affine fit that
    ``build_map`` applies afterwards is then the identity).
    """
    if method not in MASKED_METHODS:
        method = None
    return masked_embedding(X, mask, sensor, method, **params).positions


def ensemble_embedding(
    histories: Sequence[tuple[np.ndarray, np.ndarray | None]],
    sensor: str,
    method: str | None = None,
    *,
    anchor_ids: np.ndarray,
    anchor_positions: np.ndarray,
    param_sets: Sequence[dict[str, Any]] = ({},),
    max_iter: int = 300,
) -> MaskedMap:
    """Mean of :func:`masked_embedding` maps over several histories of the same objects and
    several parameter sets, anchors held fixed (all maps are then in the anchors' frame).

    Args:
        histories: ``(X, mask)`` pairs, e.g. one run binned at several bin widths (same objects
            in the same row order).
        sensor, method: as for :func:`masked_embedding` (one method for all members).
        anchor_ids, anchor_positions: required: without fixed anchors the members' frames differ.
        param_sets: parameter overrides; every history is mapped with every set.

    Returns a :class:`MaskedMap` whose ``positions`` are the mean of the members' positions (an
    object unmapped in any member is unmapped), ``delta``/``weights`` the members' means,
    ``components`` those of the member with the most components, ``warnings`` the union, and
    ``params`` ``{"members": [...params of each member...]}``.
    """
    if anchor_ids is None or anchor_positions is None:
        raise ValueError("ensemble_embedding needs anchor_ids and anchor_positions (a common frame)")
    if len(histories) == 0:
        raise ValueError("histories must hold at least one (X, mask) pair")
    if len(param_sets) == 0:
        raise ValueError("param_sets must hold at least one parameter dict")
    members: list[MaskedMap] = []
    for X, mask in histories:
        for ps in param_sets:
            members.append(masked_embedding(
                X, mask, sensor, method, anchor_ids=anchor_ids, anchor_positions=anchor_positions,
                max_iter=max_iter, **ps,
            ))
    shapes = {m.positions.shape for m in members}
    if len(shapes) != 1:
        raise ValueError(f"histories must describe the same objects, got maps of shapes {shapes}")
    positions = np.mean([m.positions for m in members], axis=0)  # NaN anywhere -> NaN
    msgs: list[str] = []
    for m in members:
        msgs.extend(w for w in m.warnings if w not in msgs)
    worst = max(members, key=lambda m: len(m.components))
    unmapped = tuple(int(i) for i in np.flatnonzero(np.isnan(positions).any(axis=1)))
    return MaskedMap(
        positions=positions,
        method=members[0].method,
        params={"members": [dict(m.params) for m in members]},
        delta=np.mean([m.delta for m in members], axis=0),
        weights=np.mean([m.weights for m in members], axis=0),
        components=worst.components,
        unmapped=unmapped,
        warnings=tuple(msgs),
    )
