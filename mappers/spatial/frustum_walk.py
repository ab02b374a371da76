"""FRUSTUM-BA-WALK's two searches: viewpoints under a walk prior, and each tag's height.

FRUSTUM-BA (:mod:`mappers.spatial.frustum`) finds each step's planar viewpoint from that step's
sightings alone; a step sees five to ten tags, which leave its pose loose (about 0.3 m off even
on the true map of ``LFMDR-Camera3D-v0``), and the wrong viewpoints and wrong heights then explain
each other. With ``continuity=True`` (label ``"FRUSTUM-BA-WALK"``) the steps are read as a walk's,
ordered, consecutive viewpoints close together: the *walk prior* of VIS-BA-WALK
(:mod:`mappers.viewpoints.walk_prior`, a motion prior on the viewpoints' random walk, not
odometry: no step is told its move), here over the heading as well as the position.

:func:`walk_viewpoints` reads the steps as a hidden Markov model whose state is a cell of a grid
of planar viewpoints (positions ``spacing`` apart over the map's floor plan x ``headings``
evenly spaced headings), whose emission is the frustum likelihood of the step's bits given the
map (:func:`mappers.spatial.frustum.view_log_prob`), and whose move is a Gaussian random walk of
width ``step_sigma`` [m] per axis in position and ``turn_sigma`` [rad] in heading (wrapped). The
forward-backward recursion (Rabiner, *A tutorial on hidden Markov models*, Proc. IEEE 1989)
gives each step's posterior; its mean (a circular mean for the heading) is the step's viewpoint.
The transition is a separable Gaussian filter on the grid (``scipy.ndimage.gaussian_filter1d``;
wrapped along the heading); the recursion itself is a loop over the steps, written here because
:mod:`mappers.viewpoints.walk_prior`'s compiled one has no heading axis.

:func:`height_search` moves each free tag to the best height of a grid at its current floor
position, the viewpoints held: a tag low on a wall and one high on a post are both seen only
from beyond about 1.1 m, so a tag started at the wrong height is in a local minimum that the
Newton steps of its three coordinates do not leave (with the true viewpoints held, COVIS-3D's
heights refine to 0.10 m off without the search and 0.06 m with it, layout 34000).

The walk search's viewpoints are posterior means on a grid, drawn toward the map's middle; after
the last one, :func:`mappers.spatial.walk_adjustment.walk_joint_steps` moves tags and viewpoints
together under the frustum likelihood *and* the walk prior, a few rounds toward their maximum a
posteriori point (not to it: that walk is a shrunk one), so the viewpoints leave the grid without
drifting from the walk as FRUSTUM-BA's joint rounds let them (``docs/dead-ends.md``, "Camera3D
sightings").
"""

from __future__ import annotations

import math
from numbers import Integral, Real

import numpy as np
from scipy.ndimage import gaussian_filter1d
from sklearn.utils._param_validation import Interval

from mappers.spatial.frustum import (
    FrustumAdjustment,
    FrustumCamera,
    view_log_prob,
)
from mappers.spatial.walk_adjustment import WalkPrior, walk_joint_steps

__all__ = ["MAX_WALK_ENTRIES", "FrustumWalkAdjustment", "height_search", "walk_viewpoints"]

MAX_WALK_ENTRIES = 1.5e8
"""Largest steps x grid cells the walk search holds (two float32 arrays of that size: 1.2 GB)."""

_TRUNCATE = 3.0
"""The Gaussian moves reach this many widths."""


def _log_likelihoods(P, seen, viewpoints, camera: FrustumCamera, softness: float,
                     range_softness: float, miss_rate: float) -> np.ndarray:
    """(N, K): the log-likelihood of each step's bits ``seen`` (N, M) at each viewpoint (K, 3)
    given the objects ``P`` (M, 3) (:mod:`mappers.spatial.frustum_kernels`' model)."""
    a = 1.0 - miss_rate
    lq = view_log_prob(P, viewpoints, camera, softness, range_softness)
    l1, l0 = math.log(a) + lq, np.log1p(-a * np.exp(lq))
    return seen.astype(float) @ (l1 - l0).T + l0.sum(axis=1)[None, :]


def walk_viewpoints(P, seen, camera: FrustumCamera, *, softness: float, range_softness: float,
                    miss_rate: float, spacing: float, headings: int, step_sigma: float,
                    turn_sigma: float, margin: float = 0.0) -> np.ndarray:
    """Each step's viewpoint ``(x, y, heading)`` (N, 3): its posterior mean under the walk prior
    (the module's docstring), given the objects ``P`` (M, 3) and the sightings ``seen`` ((N, M)
    bool, the steps in walk order). The positions' grid spans the objects' floor plan widened by
    ``margin`` [m] with cells ``spacing`` apart."""
    P = np.asarray(P, dtype=float)
    seen = np.asarray(seen, dtype=bool)
    if not (spacing > 0 and step_sigma > 0 and turn_sigma > 0 and headings >= 4):
        raise ValueError(f"the walk search needs spacing, step_sigma, turn_sigma > 0 and "
                         f"headings >= 4, got {spacing!r}, {step_sigma!r}, {turn_sigma!r}, "
                         f"{headings!r}")
    lo, hi = P[:, :2].min(axis=0) - margin, P[:, :2].max(axis=0) + margin
    xs = np.arange(lo[0], hi[0] + spacing / 2, spacing)
    ys = np.arange(lo[1], hi[1] + spacing / 2, spacing)
    hs = np.arange(headings) * (2.0 * math.pi / headings)
    n = seen.shape[0]
    shape = (len(xs), len(ys), headings)
    if n * math.prod(shape) > MAX_WALK_ENTRIES:
        raise ValueError(f"{n} steps x {math.prod(shape)} grid viewpoints exceed "
                         f"{MAX_WALK_ENTRIES:.1e} entries: raise walk_spacing or lower headings")
    grid = np.stack(np.meshgrid(xs, ys, hs, indexing="ij"), axis=-1).reshape(-1, 3)
    E = np.empty((n,) + shape, dtype=np.float32)
    for lo_t in range(0, n, 256):  # the (steps, cells) log-likelihoods in chunks of steps
        L = _log_likelihoods(P, seen[lo_t:lo_t + 256], grid, camera, softness, range_softness,
                             miss_rate)
        E[lo_t:lo_t + 256] = np.exp(L - L.max(axis=1, keepdims=True)).reshape((-1,) + shape)
    s_cell, t_cell = step_sigma / spacing, turn_sigma / (2.0 * math.pi / headings)

    def move(f):
        f = gaussian_filter1d(f, s_cell, axis=0, mode="constant", truncate=_TRUNCATE)
        f = gaussian_filter1d(f, s_cell, axis=1, mode="constant", truncate=_TRUNCATE)
        return gaussian_filter1d(f, t_cell, axis=2, mode="wrap", truncate=_TRUNCATE)

    alpha = np.empty_like(E)
    f = E[0]
    alpha[0] = f / f.sum()
    for t in range(1, n):
        f = move(alpha[t - 1]) * E[t]
        total = f.sum()
        alpha[t] = f / total if total > 0 else E[t] / E[t].sum()  # no cell reachable: restart
    cos_h, sin_h = np.cos(hs), np.sin(hs)
    out = np.empty((n, 3))
    beta = np.ones(shape, dtype=np.float32)
    for t in range(n - 1, -1, -1):
        if t < n - 1:
            beta = move(E[t + 1] * beta)
            beta /= max(float(beta.max()), 1e-300)
        post = alpha[t] * beta
        total = float(post.sum())
        post = post / total if total > 0 else alpha[t]  # float32 underflow: the filtered one
        out[t, 0] = float(post.sum(axis=(1, 2)) @ xs)
        out[t, 1] = float(post.sum(axis=(0, 2)) @ ys)
        ph = post.sum(axis=(0, 1))
        out[t, 2] = math.atan2(float(ph @ sin_h), float(ph @ cos_h))
    return out


def height_search(P, seen, viewpoints, camera: FrustumCamera, free, heights, *, softness: float,
                  range_softness: float, miss_rate: float) -> np.ndarray:
    """``P`` (M, 3) with each ``free`` (M,) bool object moved to the height among ``heights``
    whose frustum likelihood of its sightings (the column of ``seen`` (N, M)) from the
    ``viewpoints`` (N, 3) is the largest, at its floor position."""
    P = np.array(P, dtype=float)
    heights = np.asarray(heights, dtype=float)
    seen = np.asarray(seen, dtype=bool)
    a = 1.0 - miss_rate
    for j in np.flatnonzero(free):
        cand = np.column_stack([np.full(heights.size, P[j, 0]), np.full(heights.size, P[j, 1]),
                                heights])
        lq = view_log_prob(cand, viewpoints, camera, softness, range_softness)  # (N, H)
        l1, l0 = math.log(a) + lq, np.log1p(-a * np.exp(lq))
        ll = l1[seen[:, j]].sum(axis=0) + l0[~seen[:, j]].sum(axis=0)
        P[j, 2] = heights[int(np.argmax(ll))]
    return P


class FrustumWalkAdjustment(FrustumAdjustment):
    """FRUSTUM-BA with the walk prior (label ``"FRUSTUM-BA-WALK"``; the module's docstring):
    the steps in walk order, consecutive viewpoints close together.

    For each softness of ``softness`` (soft to sharp): the viewpoints by
    :func:`walk_viewpoints` given the map, each free tag's height by :func:`height_search`
    given the viewpoints, then ``rounds`` Newton steps of the free tags (the viewpoints held),
    and, but after the sharpest softness, ``joint_rounds`` of FRUSTUM-BA's joint
    Levenberg-Marquardt rounds of tags and viewpoints (the walk search that follows sets the
    viewpoints again). After the sharpest softness, ``final_rounds`` joint rounds of tags and
    viewpoints that keep the walk prior
    (:func:`mappers.spatial.walk_adjustment.walk_joint_steps`, from the last walk search's
    posterior means toward the maximum a posteriori map and walk). The defaults (the grid, the
    softnesses, the rounds) were chosen on ``LFMDR-Camera3D-v0`` and confirmed on fresh layouts:
    ``docs/guide/3d.md`` has the figures. The result is the last viewpoints and the tags fitted
    with them. Guard as FRUSTUM-BA's: the result is
    kept only if its loss at the sharpest softness (with its viewpoints) is below the start
    map's (with the viewpoints the walk search gives it).

    Parameters: the camera's calibration and ``softness``, ``range_softness``, ``miss_rate``,
    ``rounds``, ``max_iter`` as :class:`~mappers.spatial.frustum.FrustumAdjustment`, and
        step_sigma: the walk's width per axis per step [m] (the robot's move is not told: a
            width near its step length suits; 0.15 m for a 0.2 m step).
        turn_sigma_deg: the walk's width in heading per step [deg].
        walk_spacing: the position grid's spacing [m]; walk_headings: headings on the grid.
        height_margin: the heights searched span the anchors' heights widened by this [m] on
            each side; height_step: their spacing [m].
        joint_rounds: FRUSTUM-BA's joint rounds after each softness but the last.
        final_rounds: joint rounds with the walk prior after the last softness (0: none; with
            ``softness=(0.1, 0.05, 0.03)``, ``walk_spacing=0.125``, ``walk_headings=36`` that
            is FRUSTUM-BA-WALK as it was before them).
    ``grid``, ``headings`` and ``pose_iters`` are FRUSTUM-BA's per-step search's and unused.
    """

    _parameter_constraints = {
        **FrustumAdjustment._parameter_constraints,
        "step_sigma": [Interval(Real, 0.0, None, closed="neither")],
        "turn_sigma_deg": [Interval(Real, 0.0, None, closed="neither")],
        "walk_spacing": [Interval(Real, 0.0, None, closed="neither")],
        "walk_headings": [Interval(Integral, 4, None, closed="left")],
        "height_margin": [Interval(Real, 0.0, None, closed="left")],
        "height_step": [Interval(Real, 0.0, None, closed="neither")],
        "joint_rounds": [Interval(Integral, 0, None, closed="left")],
        "final_rounds": [Interval(Integral, 0, None, closed="left")],
    }

    def __init__(self, *, camera_height: float | None = None, pitch_deg: float | None = None,
                 hfov_deg: float | None = None, vfov_deg: float | None = None,
                 max_range: float | None = None, softness=(0.1, 0.03),
                 range_softness: float = 0.1, miss_rate: float = 0.02, rounds: int = 20,
                 grid: int = 15, headings: int = 36, pose_iters: int = 3, max_iter: int = 300,
                 step_sigma: float = 0.15, turn_sigma_deg: float = 30.0,
                 walk_spacing: float = 0.25, walk_headings: int = 18,
                 height_margin: float = 0.5, height_step: float = 0.05,
                 joint_rounds: int = 10, final_rounds: int = 5):
        super().__init__(camera_height=camera_height, pitch_deg=pitch_deg, hfov_deg=hfov_deg,
                         vfov_deg=vfov_deg, max_range=max_range, softness=softness,
                         range_softness=range_softness, miss_rate=miss_rate, rounds=rounds,
                         grid=grid, headings=headings, pose_iters=pose_iters, max_iter=max_iter)
        self.step_sigma = step_sigma
        self.turn_sigma_deg = turn_sigma_deg
        self.walk_spacing = walk_spacing
        self.walk_headings = walk_headings
        self.height_margin = height_margin
        self.height_step = height_step
        self.joint_rounds = joint_rounds
        self.final_rounds = final_rounds

    def _walk(self, P, S, camera: FrustumCamera, softness: float) -> np.ndarray:
        return walk_viewpoints(P, S, camera, softness=softness,
                               range_softness=self.range_softness, miss_rate=self.miss_rate,
                               spacing=self.walk_spacing, headings=self.walk_headings,
                               step_sigma=self.step_sigma,
                               turn_sigma=math.radians(self.turn_sigma_deg))

    _label = "FRUSTUM-BA-WALK"

    def _solve(self, P, S, camera: FrustumCamera, soft: np.ndarray, problem, free, anchors):
        """For each softness: the walk's viewpoints, each free object's best height, its
        Newton steps with the viewpoints held, and (but after the last) FRUSTUM-BA's joint
        rounds; then the joint rounds with the walk prior. The start is the walk's viewpoints
        at the last softness."""
        z = anchors[:, 2]
        heights = np.arange(z.min() - self.height_margin,
                            z.max() + self.height_margin + self.height_step / 2, self.height_step)
        start_C = self._walk(P, S, camera, float(soft[-1]))
        start_loss = loss = problem(soft[-1]).cost(P, start_C)
        C = start_C
        for k, s in enumerate(soft):
            C = self._walk(P, S, camera, float(s))
            P = height_search(P, S, C, camera, free, heights, softness=float(s),
                              range_softness=self.range_softness, miss_rate=self.miss_rate)
            P, loss = problem(s).object_steps(P, C, self.rounds)
            if k < len(soft) - 1:  # the joint rounds move the map; the next walk search the
                P, C, loss = problem(s).joint(P, C, self.joint_rounds)  # viewpoints again
        if self.final_rounds:  # FRUSTUM-BA's rounds here drift from the walk: keep its prior
            prior = WalkPrior(self.step_sigma, math.radians(self.turn_sigma_deg))
            P, C, loss = walk_joint_steps(problem(soft[-1]), P, C, self.final_rounds, prior)
        return P, C, loss, start_C, start_loss
