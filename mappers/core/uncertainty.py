"""Per-object uncertainty: covariances from normal equations or from resampled maps, and their
scores.

Generic over the dimension ``d`` of the map (2 or 3). Two ways to a covariance:

* from an adjustment's Gauss-Newton normal matrix ``S`` of the free objects (viewpoints already
  eliminated): :func:`block_marginals` reads the (d, d) diagonal blocks of ``S^-1`` — the
  marginal covariances of the objects, to be scaled by the residuals' variance (Triggs et al.,
  *Bundle Adjustment — A Modern Synthesis*, 2000, §9; Hartley & Zisserman, *Multiple View
  Geometry*, 2nd ed., §5.2);
* from replicate maps of resampled histories: :func:`moving_blocks` draws the steps of a moving
  block bootstrap (Künsch, *The jackknife and the bootstrap for general stationary
  observations*, Ann. Statist. 1989), :func:`sample_covariances` takes the replicates' spread,
  and :func:`sample_size_factor` widens it for the few replicates it comes from.

:func:`coverage` and :func:`rms_radius` score a set of covariances against the truth.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.linalg
from scipy import stats

__all__ = [
    "UNCERTAINTY_MODES",
    "block_marginals",
    "check_uncertainty",
    "chi2_quantile",
    "coverage",
    "mahalanobis_squared",
    "moving_blocks",
    "rms_radius",
    "sample_covariances",
    "sample_size_factor",
    "systematic_floor",
    "transform_covariances",
]

UNCERTAINTY_MODES = (False, True, "model", "jackknife", "bootstrap", "anchors", "floor")
"""The values ``build_map(uncertainty=...)`` takes: none, the method's own (``True``: for a
method with a bundle adjustment, the normal equations' plus the systematic floor its held-out
anchors estimate, :func:`mappers.core.held_out_anchors.held_out_floor`), from the
normal equations alone (``"model"``), from CAL-SMA's linearised block jackknife (``"jackknife"``,
:mod:`mappers.calibrated.cal_sma_uncertainty`), from a bootstrap over steps (``"bootstrap"``),
the method's own checked and scaled by the held-out anchors (``"anchors"``,
:mod:`mappers.core.held_out_anchors`), the normal equations' with a floor for a logged sensor's
systematic errors (``"floor"``, :func:`systematic_floor`)."""

SYSTEMATIC_FLOOR = 0.003
"""``uncertainty="floor"``'s standard deviation per axis of a landmark's systematic error, as a
share of the anchors' extent (the largest distance between two anchors): 0.3 %, 1.2 cm for
anchors 4 m apart. Chosen on STAR-loc's s3 sequences (stereo, SPATIAL-BA: the smallest share,
in steps of 0.0005, that put 95 % of their 181 scored tags inside their 95 % regions; 94.5 % with
the maps of SPATIAL-BA's later ``gain_tol`` stop) and
confirmed on bodies of data not used to choose it: MRCLAM's four runs (range and bearing,
LOC-SMA: 0.932 inside, sharpness 1.95) and STAR-loc's s1 and s2 sequences (other calibrations:
0.863, 0.93) — ``benchmarks/bench_uncertainty.py``, docs/guide/uncertainty.md. It is also
``uncertainty=True``'s floor for a map whose anchors cannot be held out
(:func:`mappers.covariances.with_held_out_floor`)."""


def check_uncertainty(value) -> bool | str:
    """``value`` if it is one of :data:`UNCERTAINTY_MODES`, else a ValueError naming them."""
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, str) and value in UNCERTAINTY_MODES:
        return value
    raise ValueError(f"uncertainty must be one of {list(UNCERTAINTY_MODES)}, got {value!r}")


def chi2_quantile(d: int, level: float = 0.95) -> float:
    """The ``level`` quantile of the chi-squared law with ``d`` degrees of freedom: the squared
    Mahalanobis radius of the ``level`` region of a d-dimensional Gaussian."""
    return float(stats.chi2.ppf(level, d))


def systematic_floor(cov: np.ndarray, positions: np.ndarray, anchor_ids,
                     share: float = SYSTEMATIC_FLOOR) -> np.ndarray:
    """Covariances (M, d, d) with an isotropic floor for the errors a sensor's model does not
    describe: ``(share * extent)² I`` added to every object's that is not an anchor (``extent``
    the largest distance between two of the anchors' ``positions`` (M, d) rows ``anchor_ids``);
    anchors, NaN and unbounded covariances are left as they are.

    On logged runs a map's errors are mostly systematic (a stereo rig's calibration, a robot's
    range bias, a landmark's marker off its surveyed centre): the same over a whole run, so the
    readings' residuals and their spread do not show them, and the model's ellipses are far too
    small (docs/guide/uncertainty.md). Such errors scale with the scene, so the floor is a share
    of the anchors' extent (a map scaled with its anchors gets its floor scaled alike); the
    share is :data:`SYSTEMATIC_FLOOR`, chosen on one body of real data and confirmed on two
    others. The floor is the "additive" variance component of a model's error budget (Koch,
    *Parameter Estimation and Hypothesis Testing in Linear Models*, 1999, §3.5). ValueError
    with fewer than two anchors or a negative ``share``."""
    if not share >= 0:
        raise ValueError(f"the floor's share must be >= 0, got {share!r}")
    ids = np.asarray(list(anchor_ids), dtype=int)
    a = np.asarray(positions, dtype=float)[ids]
    a = a[np.all(np.isfinite(a), axis=1)]
    if len(a) < 2:
        raise ValueError(f"a systematic floor needs at least two placed anchors, got {len(a)}")
    extent = float(np.max(np.linalg.norm(a[:, None] - a[None], axis=2)))
    out = np.array(cov, dtype=float)
    d = out.shape[-1]
    rows = np.all(np.isfinite(out), axis=(1, 2))
    rows[ids] = False
    out[rows] += (share * extent) ** 2 * np.eye(d)
    return out


def block_marginals(S: np.ndarray, d: int) -> np.ndarray:
    """The (F, d, d) diagonal blocks of ``S^-1`` for a symmetric (dF, dF) normal matrix ``S``.

    Solved by Cholesky factorisation when ``S`` is positive definite; otherwise through its
    eigen-decomposition with the null directions given an infinite variance (an object the
    readings do not pin down is not reported as known).
    """
    n = S.shape[0]
    if n == 0:
        return np.zeros((0, d, d))
    if S.shape != (n, n) or n % d:
        raise ValueError(f"S must be a square matrix of d x F rows (d = {d}), got {S.shape}")
    S = 0.5 * (S + S.T)
    try:
        cho = scipy.linalg.cho_factor(S, lower=True, check_finite=True)
        inv = scipy.linalg.cho_solve(cho, np.eye(n))
    except np.linalg.LinAlgError:
        ev, vec = np.linalg.eigh(S)
        null = ev <= 1e-12 * max(float(ev[-1]), 1e-300)
        inv = (vec[:, ~null] / ev[~null]) @ vec[:, ~null].T
        blocks = _diagonal_blocks(inv, d)
        loose = np.abs(vec[:, null]).max(axis=1).reshape(-1, d).max(axis=1) > 1e-9 if null.any() \
            else np.zeros(n // d, dtype=bool)
        blocks[loose] = np.diag(np.full(d, np.inf))
        return blocks
    return _diagonal_blocks(inv, d)


def _diagonal_blocks(A: np.ndarray, d: int) -> np.ndarray:
    f = A.shape[0] // d
    idx = np.arange(f)[:, None] * d + np.arange(d)[None, :]
    return A[idx[:, :, None], idx[:, None, :]]


def transform_covariances(cov: np.ndarray, linear: np.ndarray) -> np.ndarray:
    """Covariances (M, d, d) of row vectors ``x`` carried to ``x @ linear`` ((d, d)):
    ``linear^T cov linear``."""
    return np.einsum("ji,mjk,kl->mil", linear, cov, linear)


def moving_blocks(n_steps: int, block: int, rng: np.random.Generator) -> np.ndarray:
    """The steps of one moving-block bootstrap replicate (Künsch 1989): ``ceil(n / block)``
    blocks of ``block`` consecutive steps, each starting at a uniformly drawn step, joined and
    cut to ``n_steps``. Consecutive steps of a walk see nearly the same scene, so resampling
    single steps would understate the spread."""
    if not 1 <= block <= n_steps:
        raise ValueError(f"block must be in [1, {n_steps}] steps, got {block}")
    starts = rng.integers(0, n_steps - block + 1, size=-(-n_steps // block))
    return (starts[:, None] + np.arange(block)[None, :]).ravel()[:n_steps]


def sample_covariances(replicates: np.ndarray, min_replicates: int) -> np.ndarray:
    """(M, d, d) sample covariances of replicate maps ``(R, M, d)`` (NaN rows: not placed in that
    replicate), each object's from the replicates that placed it; NaN for an object placed in
    fewer than ``min_replicates``."""
    R, m, d = replicates.shape
    ok = np.all(np.isfinite(replicates), axis=2)  # (R, M)
    count = ok.sum(axis=0)
    x = np.where(ok[:, :, None], replicates, 0.0)
    mean = x.sum(axis=0) / np.maximum(count, 1)[:, None]
    dev = np.where(ok[:, :, None], replicates - mean[None], 0.0)
    cov = np.einsum("rmi,rmj->mij", dev, dev) / np.maximum(count - 1, 1)[:, None, None]
    cov[count < max(min_replicates, 2)] = np.nan
    return cov


def sample_size_factor(n_replicates: int, d: int, level: float = 0.95) -> float:
    """How much wider a covariance estimated from ``n_replicates`` samples must be for its
    chi-squared region to hold ``level`` of a Gaussian error independent of them.

    With ``S`` the sample covariance of R draws and ``e`` a further zero-mean draw, ``e^T S^-1 e``
    follows ``d (R - 1) / (R - d) F(d, R - d)`` (Hotelling's T², known centre), heavier-tailed
    than chi-squared(d); the factor is the ratio of the two ``level`` quantiles (1.25 for R = 20,
    d = 2; tends to 1)."""
    if n_replicates <= d:
        raise ValueError(f"need more than d = {d} replicates, got {n_replicates}")
    r = n_replicates
    t2 = d * (r - 1) / (r - d) * stats.f.ppf(level, d, r - d)
    return float(t2 / chi2_quantile(d, level))


def mahalanobis_squared(errors: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """``e^T cov^-1 e`` per row of ``errors`` (M, d) and ``cov`` (M, d, d); NaN where either is
    not finite, inf for a singular covariance with the error off its support."""
    out = np.full(len(errors), np.nan)
    ok = np.all(np.isfinite(errors), axis=1) & np.all(np.isfinite(cov), axis=(1, 2))
    if ok.any():
        inv = np.linalg.pinv(cov[ok], hermitian=True)
        e = errors[ok]
        q = np.einsum("mi,mij,mj->m", e, inv, e)
        back = np.einsum("mij,mj->mi", cov[ok], np.einsum("mij,mj->mi", inv, e))
        q[np.linalg.norm(back - e, axis=1) > 1e-6 * np.maximum(np.linalg.norm(e, axis=1), 1e-12)] = np.inf
        out[ok] = q
    inf_cov = np.all(np.isfinite(errors), axis=1) & np.any(np.isinf(cov), axis=(1, 2))
    out[inf_cov] = 0.0  # an unbounded region holds the truth
    return out


def coverage(positions: np.ndarray, cov: np.ndarray, truth: np.ndarray, objects,
             level: float = 0.95) -> float:
    """The share of ``objects`` whose true position lies inside their ``level`` region
    (squared Mahalanobis distance at most the chi-squared(d) quantile); objects with no finite
    position are left out."""
    objects = np.asarray(objects, dtype=int)
    q = mahalanobis_squared(truth[objects] - positions[objects], cov[objects])
    ok = ~np.isnan(q)
    if not ok.any():
        return float("nan")
    return float(np.mean(q[ok] <= chi2_quantile(positions.shape[1], level)))


def rms_radius(cov: np.ndarray, level: float = 0.95) -> np.ndarray:
    """The root-mean-square radius of each ``level`` ellipse (ellipsoid) of covariances
    (M, d, d): ``sqrt(q trace(cov) / d)`` with ``q`` the chi-squared(d) quantile — for an ellipse
    of semi-axes ``a, b``, the RMS of its radius over the angle, ``sqrt((a² + b²) / 2)``."""
    d = cov.shape[-1]
    return np.sqrt(chi2_quantile(d, level) * np.trace(cov, axis1=-2, axis2=-1) / d)


BuildReplicate = Callable[[np.ndarray], np.ndarray]
"""A function from a replicate's steps (indices into the history's steps) to the replicate's
(M, d) map (NaN rows: not placed)."""
