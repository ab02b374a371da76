"""VIS-BA's sensor model: the chance that an object is seen from a viewpoint at distance ``d``.

A visibility bit is read as a noisy range threshold (:mod:`mappers.viewpoints.visibility`):

    P(visible | d) = (1 - eps) (1 - gamma min(d / R, 1.5)^k) sigmoid((R - d) / s)

with a visibility radius ``R``, a softness ``s``, a rate ``eps`` of misses that do not depend
on the geometry (a camera's dropouts) and a miss rate that grows with distance (``gamma``,
``k``: occlusion by other objects, rare near the viewpoint, common near ``R``). Here: the
log-likelihood of the bits, its score and Fisher information in ``d`` (the objects' M-step),
the model's start values and its maximum-likelihood fit on expected counts (the model's
M-step). ``theta`` is ``(R, s, eps, gamma, k)`` throughout.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize
from scipy.special import expit

__all__: list[str] = []  # VIS-BA's own pieces: nothing handed on

_EPS_FLOOR = 1e-4
"""Smallest miss rate of the model (a perfect sensor's bits would otherwise make log(0))."""

_CAP = 1.5
"""The occlusion term grows with ``d / R`` up to this value and stays flat beyond it."""


def _miss_curve(d, theta):
    """``q(d) = (1 - eps) (1 - gamma min(d / R, cap)^k)``, the chance that an object within the
    threshold is seen, and its derivative in d."""
    R, _, eps, gamma, k = theta
    r = np.minimum(d / R, _CAP)
    q = (1.0 - eps) * (1.0 - gamma * r**k)
    dq = np.where(d / R < _CAP, -(1.0 - eps) * gamma * k * r ** (k - 1) / R, 0.0)
    return q, dq


def _log_terms(d, theta) -> tuple[np.ndarray, np.ndarray]:
    """``(log P(seen), log P(not seen))`` at distance ``d`` (stable forms)."""
    R, s = theta[0], theta[1]
    eta = (R - d) / s
    q, _ = _miss_curve(d, theta)
    sig = 0.5 * (1.0 + np.tanh(0.5 * eta))  # sigmoid without overflow
    return np.log(q) - np.logaddexp(0.0, -eta), np.log1p(-q * sig)


def _loglik(d, yes, no, theta) -> np.ndarray:
    """Per entry, the log-likelihood of ``yes`` bits seen and ``no`` not seen (counts)."""
    a, b = _log_terms(d, theta)
    return yes * a + no * b


def _score_fisher(d, yes, no, theta) -> tuple[np.ndarray, np.ndarray]:
    """Per entry, d loglik / d d and the Fisher information in d (expected -d2/dd2)."""
    R, s = theta[0], theta[1]
    eta = (R - d) / s
    sig = 0.5 * (1.0 + np.tanh(0.5 * eta))
    one_minus = 0.5 * (1.0 - np.tanh(0.5 * eta))
    q, dq = _miss_curve(d, theta)
    pi = q * sig
    dpi = dq * sig - q * sig * one_minus / s  # d P(seen) / d d
    not_seen = 1.0 - pi
    score = yes * (dq / q - one_minus / s) - no * dpi / not_seen
    fisher = dpi * dpi / np.maximum(pi * not_seen, 1e-300)
    return score, (yes + no) * fisher


def _distances(G: np.ndarray, P: np.ndarray) -> np.ndarray:
    """(G, M) distances between the cells and the objects."""
    return np.sqrt(np.maximum(np.sum(G * G, axis=1)[:, None] + np.sum(P * P, axis=1)[None]
                              - 2.0 * G @ P.T, 0.0))


def _guess_model(P, S) -> tuple:
    """Start values of ``(R, s, eps, gamma, k)``: R the 90th percentile of the distances from
    the seen objects to the centroid of the objects each step saw."""
    count = S.sum(axis=1, keepdims=True)
    C = S @ P / np.maximum(count, 1.0)
    d = np.linalg.norm(C[:, None, :] - P[None, :, :], axis=2)[S > 0]
    R = float(np.quantile(d, 0.9)) if d.size and np.quantile(d, 0.9) > 0 else 1.0
    return R, 0.1 * R, 0.1, 0.0, 3.0


def _fit_model(P, G, Sg, Ng, theta, s_min, occlusion=True) -> tuple:
    """Maximum expected log-likelihood ``(R, s, eps, gamma, k)`` (``occlusion`` False: gamma
    stays 0) at the objects ``P`` under the expected counts (the distances binned finely: a fit
    of a few parameters over a few hundred bins)."""
    R0 = theta[0]
    d = _distances(G, P).T
    edges = np.linspace(0.0, 3.0 * R0, 601)
    k = np.minimum(np.searchsorted(edges, d, side="right") - 1, len(edges) - 1)
    yes = np.bincount(k.ravel(), weights=Sg.ravel(), minlength=len(edges))
    no = np.bincount(k.ravel(), weights=Ng.ravel(), minlength=len(edges))
    wsum = np.bincount(k.ravel(), weights=(Sg + Ng).ravel(), minlength=len(edges))
    dsum = np.bincount(k.ravel(), weights=((Sg + Ng) * d).ravel(), minlength=len(edges))
    used = wsum > 0
    dv, yes, no = dsum[used] / wsum[used], yes[used], no[used]
    if yes.sum() <= 0 or no.sum() <= 0:
        return theta
    scale = 1.0 / (yes.sum() + no.sum())

    def unpack(z):
        k = 1.0 + 5.0 * expit(z[4])  # in (1, 6)
        return (z[0], s_min + np.exp(min(z[1], 50.0)),
                _EPS_FLOOR + (1 - 2 * _EPS_FLOOR) * expit(z[2]),
                (1 - _EPS_FLOOR) * expit(z[3]) / _CAP**k, k)

    def nll(z):
        return -scale * float(np.sum(_loglik(dv, yes, no, unpack(z))))

    R, s, eps, gamma, k = theta
    eps = min(max(eps, 2 * _EPS_FLOOR), 1 - 2 * _EPS_FLOOR)
    g = min(max(gamma * _CAP**k / (1 - _EPS_FLOOR), 1e-4), 1 - 1e-4)
    kk = min(max((k - 1.0) / 5.0, 1e-4), 1 - 1e-4)
    z0 = np.array([R, np.log(max(s - s_min, 1e-3 * s_min + 1e-12)),
                   np.log((eps - _EPS_FLOOR) / (1 - _EPS_FLOOR - eps)), np.log(g / (1 - g)),
                   np.log(kk / (1 - kk))])
    if not occlusion:
        z0, full = z0[:3], z0

        def nll3(z):
            return nll(np.concatenate([z, full[3:]]))
        res = minimize(nll3, z0, method="Nelder-Mead",
                       options={"xatol": 1e-4, "fatol": 1e-8, "maxiter": 200})
        z = np.concatenate([res.x if np.isfinite(res.fun) and res.fun <= nll3(z0) else z0,
                            full[3:]])
        return tuple(float(v) for v in unpack(z))
    res = minimize(nll, z0, method="Nelder-Mead",
                   options={"xatol": 1e-4, "fatol": 1e-8, "maxiter": 300})
    z = res.x if np.isfinite(res.fun) and res.fun <= nll(z0) else z0
    return tuple(float(v) for v in unpack(z))
