"""VIS-BA's E-step: each step's posterior over a grid of candidate viewpoints.

The viewpoints of a visibility history are integrated out over a square grid of cells (a
discretised EM, as in Dempster, Laird & Rubin 1977): each step's posterior over the cells from the
bits of the objects it observed under the sensor model (:mod:`mappers.viewpoints.visibility_model`),
with the steps independent under a learnt occupancy prior, or linked as a walk (a hidden Markov
model, :mod:`mappers.viewpoints.walk_prior`). The posteriors give the expected counts of bits
seen and not seen from each cell, on which the M-steps fit the objects and the model.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter

from mappers.viewpoints.visibility_model import _distances, _log_terms

__all__: list[str] = []  # VIS-BA's own pieces: nothing handed on

_MAX_POSTERIOR = 2e8
"""Largest steps x cells the E-step holds (float32: 800 MB)."""

def _grid(P, R, cells_per_radius) -> tuple[np.ndarray, tuple[int, int]]:
    """Candidate viewpoints: a square grid of spacing R / cells_per_radius over the objects'
    bounding box widened by R (a step that saw an object was within about R of it), and its
    shape (x-major)."""
    h = R / cells_per_radius
    lo, hi = P.min(axis=0) - R, P.max(axis=0) + R
    xs, ys = np.arange(lo[0], hi[0] + h / 2, h), np.arange(lo[1], hi[1] + h / 2, h)
    return (np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2),
            (len(xs), len(ys)))


def _log_emission(P, G, S, Obs, theta) -> np.ndarray:
    """(N, G) float32 log-likelihood of each step's bits at each cell. ``S`` and ``Obs`` are
    float32 (the (N, G) products and exponentials dominate the cost; the sums are float64)."""
    a, b = _log_terms(_distances(G, P), theta)  # (G, M)
    return Obs @ b.T.astype(np.float32) + S @ (a - b).T.astype(np.float32)


def _posterior(P, G, S, Obs, theta, log_prior=None) -> tuple[np.ndarray, float]:
    """Each step's posterior over the cells (``log_prior`` per cell; None: uniform), the steps
    independent, and the marginal log-likelihood of the bits."""
    L = _log_emission(P, G, S, Obs, theta)
    L += np.float32(-np.log(len(G))) if log_prior is None else log_prior.astype(np.float32)
    top = L.max(axis=1, keepdims=True)
    np.exp(L - top, out=L)
    total = L.sum(axis=1, keepdims=True, dtype=np.float64)
    L /= total.astype(np.float32)
    return L, float(np.sum(top[:, 0].astype(np.float64) + np.log(total[:, 0])))


def _walk_posterior(P, G, S, Obs, theta, log_prior, walk, fit_sigma) -> tuple:
    """Each step's posterior over the cells under the continuity prior (a hidden Markov model:
    :func:`mappers.viewpoints.walk_prior.forward_backward`, ``log_prior`` the distribution of a run's
    first step), its marginal log-likelihood, and the expected squared displacement [m^2]
    summed over the links. ``walk``: dict of the kept ``cells``, the full grid's ``shape``, its
    spacing ``h``, the walk's width ``sigma`` and the run ``starts``."""
    from mappers.viewpoints.walk_prior import forward_backward

    L = _log_emission(P, G, S, Obs, theta)
    top = L.max(axis=1, keepdims=True)
    np.exp(L - top, out=L)
    init = np.exp(log_prior - log_prior.max())
    return forward_backward(L, top[:, 0], init / init.sum(), walk["cells"], walk["shape"],
                            walk["sigma"], walk["h"], walk["starts"], want_disp=fit_sigma)


def _update_prior(post, cells, shape, blur) -> np.ndarray:
    """The log of the viewpoints' distribution over the ``cells`` (indices into the full grid of
    ``shape``): the mean posterior (the EM update of a mixture's weights) blurred by a Gaussian
    of ``blur`` cells (else, with more cells than steps, it collapses onto the current
    viewpoints), floored so that no cell is ruled out for good."""
    full = np.zeros(shape[0] * shape[1])
    full[cells] = post.mean(axis=0)
    if blur > 0:
        full = gaussian_filter(full.reshape(shape), blur, mode="constant").ravel()
    w = full[cells] + 1e-3 / len(cells)
    return np.log(w / w.sum())


def _expected_counts(S, Obs, post) -> tuple[np.ndarray, np.ndarray]:
    """(M, G) expected counts of the bits seen and not seen of each object from each cell under
    the steps' posteriors (float32 products, float64 results)."""
    seen = (S.T @ post).astype(np.float64)
    return seen, np.maximum((Obs.T @ post).astype(np.float64) - seen, 0.0)


class _EStep:
    """VIS-BA's E-step on the steps' bits ``S`` (seen) and ``Obs`` (observed), (N, M) float32:
    the steps independent (:func:`_posterior`), or linked as a walk (:func:`_walk_posterior`;
    ``walk`` the dict it takes), whose width per axis is then refitted by EM from the expected
    squared displacement over ``n_links`` links when ``fit_sigma``."""

    def __init__(self, S, Obs, walk: dict | None = None, n_links: int = 1,
                 fit_sigma: bool = False) -> None:
        self.S, self.Obs, self.walk = S, Obs, walk
        self.n_links, self.fit_sigma = n_links, fit_sigma

    @property
    def sigma(self) -> float:
        """The walk's width per axis [m] (NaN without a walk)."""
        return self.walk["sigma"] if self.walk is not None else float("nan")

    @sigma.setter
    def sigma(self, value: float) -> None:
        if self.walk is not None:
            self.walk["sigma"] = value

    def __call__(self, P, G, theta, log_prior, independent=False, refit=True):
        """``(post, loglik)`` at the objects ``P`` over the cells ``G``; ``independent``: the
        steps independent even with a walk; ``refit``: the walk's width refitted (if it is)."""
        if self.walk is None or independent:
            return _posterior(P, G, self.S, self.Obs, theta, log_prior)
        fit_sigma = refit and self.fit_sigma
        post, ll, disp = _walk_posterior(P, G, self.S, self.Obs, theta, log_prior, self.walk,
                                         fit_sigma)
        if fit_sigma:  # EM update of the walk's width per axis (kept off a degenerate 0)
            self.walk["sigma"] = float(np.clip(np.sqrt(disp / (2.0 * self.n_links)),
                                               0.5 * self.walk["h"], 2.0 * theta[0]))
        return post, ll
