"""SPATIAL-BA: a 3-D map from rays (and ranges) by the 6-DoF viewpoint bundle adjustment.

Rays and ranges: the steps are registered to one another by their common objects
(:func:`mappers.spatial.registration.register_points`; pose-free, as the law of cosines makes
the distances of two objects seen in one step), placed by the anchors, then continued by rays
(:func:`~mappers.spatial.registration.register_rays`) and adjusted jointly
(:func:`mappers.spatial.adjustment.adjust_viewpoints`). Rays alone: the same adjustment started
from the anchors by resection and intersection. No odometry, no motion model: every step's pose
is estimated from what it saw.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from scipy.sparse import coo_matrix, issparse
from sklearn.base import BaseEstimator

from mappers.core.align_3d import check_anchors_3d, umeyama
from mappers.core.embedding_transformer import EmbeddingTransformer
from mappers.core.threads import thread_limit
from mappers.core.validation import check_views
from mappers.spatial.adjustment import adjust_viewpoints
from mappers.spatial.anchored import anchored_objects
from mappers.spatial.covisibility_3d import CoVisibility3D
from mappers.spatial.global_start import register_global
from mappers.spatial.incremental import register_incremental
from mappers.spatial.rays import ray_observations
from mappers.spatial.registration import MIN_RAY_ANGLE, register_points, register_rays
from mappers.spatial.regrow import intersect_by_consensus, step_ray_errors
from mappers.viewpoints import DENSE_COUPLING_MAX_BYTES

__all__ = ["SpatialAdjustment"]

REGROW_ROUNDS = 4
"""Rays alone: rounds of adjusting and growing the start at most (:meth:`SpatialAdjustment._regrow`)."""
REGROW_ITER = 20
"""Levenberg-Marquardt iterations of each round's short adjustment."""


class SpatialAdjustment(EmbeddingTransformer, BaseEstimator):
    """The 6-DoF viewpoint bundle adjustment as an estimator (see the module's docstring).

    Args:
        bearing_noise: the rays' angle noise [rad] (default 1 degree).
        range_noise, range_growth: a range's noise [m], ``range_noise + range_growth * r**2``.
        loss, loss_scale: the robust loss ("cauchy", "huber" or None) at that many noise units.
        max_iter: Levenberg-Marquardt iterations at most.
        tol: stop when an iteration lowers the cost by less than this share of it. 1e-6: on
            ``LFMDR-Camera3D-v0`` (rays and ranges, 1 degree, 2 cm) the map's error is the same
            to 1e-5 m as with 1e-10, in a third of the iterations (``benchmarks/bench_camera3d.py``).
        gain_tol: each adjustment (the start's pieces, the rays' regrowing rounds, the final one)
            also stops when an iteration lowers the cost by at most this share of the cost it
            started from (:func:`mappers.spatial.adjustment.adjust_viewpoints`). 1e-4: on
            ``LFMDR-Camera3D-v0`` (seeds 35000-35009, 1 degree, 2 cm) the maps' mean error is
            the same to 1e-5 m as with 0 (rays 0.00550 m, rays and ranges 0.00345 m), in a
            quarter less CPU for rays alone, whose final adjustment otherwise creeps on for up
            to a hundred iterations (a weakly fixed pose).
        fit_range_scale: estimate one factor of all ranges (a stereo calibration's scale error).
        anchor_noise: None: the anchors are held fixed; a number [m]: they are adjusted under a
            prior of that deviation, and the adjusted map is then placed on them by the
            least-squares similarity (Umeyama 1991): the map keeps the shape and, with ranges,
            the scale its sightings give it, then one scale factor takes it to the anchors'
            (a stereo camera's ranges on STAR-loc are 1.5-3 % short).
        max_ray_error: an adjusted object whose rays miss it by more than this median angle
            [rad], that lies behind the sensor in most of its sightings, or (rays alone) whose
            rays diverge by less than 10 degrees (its depth along them is not fixed) was not
            placed consistently: it is left unmapped (NaN, listed in ``inconsistent_``) rather than
            reported where the adjustment left it.
        dense_coupling_bytes: the adjustment's pose-point coupling is dense up to this many
            bytes, sparse above (:func:`mappers.spatial.adjustment.adjust_viewpoints`).
        start: rays alone, how the adjustment is started: ``"anchors"`` resection and
            intersection grown from the anchors (:func:`~mappers.spatial.registration.register_rays`);
            (default); ``"global"`` global structure from motion, the anchors only placing it
            (:func:`mappers.spatial.global_start.register_global`), then grown as from the
            anchors (from the anchors alone where its structure holds fewer than three);
            ``"incremental"`` incremental structure from motion with merging: many two-step
            seeds grown in their own frames, merged by their shared objects, placed by the
            anchors (:func:`mappers.spatial.incremental.register_incremental`), then grown as
            from the anchors (from the anchors alone where no piece holds three). Rays with
            ranges always start from the registered frames. Measured in ``docs/guide/3d.md``:
            no start wins everywhere, so the default stays.

    Attributes (after fit): ``embedding_`` (M, 3) world positions, NaN for objects it could not
    place or placed inconsistently (``inconsistent_``, see ``max_ray_error``); ``rotations_`` (N, 3, 3) and ``positions_`` (N, 3) the steps' poses (NaN: step not
    used); ``range_scale_``; ``n_iter_``; ``observations_``, ``adjusted_`` (the
    :class:`~mappers.spatial.adjustment.AdjustmentResult` before the similarity onto the
    anchors), ``anchor_ids_`` and ``similarity_`` (rotation, scale, translation taking
    ``adjusted_`` to the output; the identity without ``anchor_noise``): what the model
    covariances need (:mod:`mappers.spatial.marginals`); ``unanchored_`` the ids of the objects
    no chain of sightings links to three anchors not on one line, which no map can place from
    its sightings (:mod:`mappers.spatial.anchored`; always unmapped), and ``notes_`` saying so.
    """

    def __init__(self, *, bearing_noise: float = float(np.deg2rad(1.0)), range_noise: float = 0.02,
                 range_growth: float = 0.0, loss: str | None = "cauchy", loss_scale: float = 3.0,
                 max_iter: int = 200, tol: float = 1e-6, fit_range_scale: bool = False,
                 anchor_noise: float | None = None, max_ray_error: float = float(np.deg2rad(5.0)),
                 dense_coupling_bytes: float = DENSE_COUPLING_MAX_BYTES, start: str = "anchors",
                 gain_tol: float = 1e-4):
        self.bearing_noise = bearing_noise
        self.range_noise = range_noise
        self.range_growth = range_growth
        self.loss = loss
        self.loss_scale = loss_scale
        self.max_iter = max_iter
        self.tol = tol
        self.fit_range_scale = fit_range_scale
        self.anchor_noise = anchor_noise
        self.max_ray_error = max_ray_error
        self.dense_coupling_bytes = dense_coupling_bytes
        self.start = start
        self.gain_tol = gain_tol

    def fit(self, X, y=None, *, anchor_ids=None, anchor_positions=None, mask=None, masks=None):
        """Fit to a 3-D bearing history ``X`` (M, 3N) or fused histories ``{"bearing": rays,
        "range": ranges (M, N)}`` (``masks`` keyed alike), with 3-D anchors (held fixed)."""
        # the matrices are small (6 x 6 poses, 3F x 3F objects): one BLAS thread is fastest
        with thread_limit(1):
            return self._fit(X, mask, masks, anchor_ids, anchor_positions)

    def _fit(self, X, mask, masks, anchor_ids, anchor_positions):
        if isinstance(X, Mapping) and not issparse(X):  # (a DOK sparse matrix is a dict)
            if "bearing" not in X:
                raise ValueError(f"SPATIAL-BA maps rays: fused histories need a 'bearing' entry, "
                                 f"got {sorted(X)}")
            masks = dict(masks or {})
            obs = ray_observations(X["bearing"], masks.get("bearing"), X.get("range"),
                                   masks.get("range"))
        else:
            obs = ray_observations(check_views(self, X, mask), mask)
        if anchor_ids is None or anchor_positions is None:
            raise ValueError("SPATIAL-BA needs anchors: anchor_ids and anchor_positions (A, 3)")
        ids, pos = check_anchors_3d(anchor_ids, anchor_positions, obs.n_objects)
        seen = coo_matrix((np.ones(obs.obj.size), (obs.obj, obs.step)),
                          shape=(obs.n_objects, obs.n_steps))
        self.unanchored_ = np.flatnonzero(~anchored_objects(seen, ids, pos))
        self.notes_ = (f"objects {self.unanchored_.tolist()} share no chain of sightings with "
                       "three anchors not on one line: their sightings fix no place for them",) \
            if self.unanchored_.size else ()
        if self.start not in ("anchors", "global", "incremental"):
            raise ValueError(f"start must be 'anchors', 'global' or 'incremental', got "
                             f"{self.start!r}")
        if not (isinstance(self.tol, (int, float)) and self.tol >= 0):
            raise ValueError(f"tol must be a number >= 0, got {self.tol!r}")
        if np.isfinite(obs.range).any():
            refine = {"bearing_noise": self.bearing_noise, "range_noise": self.range_noise,
                      "range_growth": self.range_growth, "loss": self.loss,
                      "loss_scale": self.loss_scale, "max_iter": self.max_iter, "tol": self.tol,
                      "dense_coupling_bytes": self.dense_coupling_bytes,
                      "gain_tol": self.gain_tol}
            start = register_rays(obs, ids, pos, start=register_points(obs, ids, pos, refine))
        else:
            start = self._rays_start(obs, ids, pos, self.start, self.bearing_noise)
        if not np.isfinite(start[2][:, 0]).any():
            raise ValueError("SPATIAL-BA could not place any step: no step sees three placed "
                             "objects (anchors, or objects placed from them) not on one line")
        fixed = np.zeros(obs.n_objects, dtype=bool)
        fixed[ids] = True
        if not np.isfinite(obs.range).any():
            start = self._regrow(obs, ids, pos, fixed, start)
        res = adjust_viewpoints(obs, *start, fixed, bearing_noise=self.bearing_noise,
                                range_noise=self.range_noise, range_growth=self.range_growth,
                                loss=self.loss, loss_scale=self.loss_scale,
                                max_iter=self.max_iter, tol=self.tol,
                                fit_range_scale=self.fit_range_scale,
                                anchor_noise=self.anchor_noise,
                                dense_coupling_bytes=self.dense_coupling_bytes,
                                gain_tol=self.gain_tol)
        # what the model covariances re-linearise (mappers.spatial.marginals): the sightings
        # with the ranges as finally scaled, the adjustment before any similarity, the anchors
        self.observations_ = obs._replace(range=obs.range * res.range_scale)
        self.adjusted_, self.anchor_ids_ = res, ids
        self.similarity_ = (np.eye(3), 1.0, np.zeros(3))
        if self.anchor_noise is not None:  # the map's own shape, placed on the anchors
            Rs, scale, t = umeyama(res.points[ids], pos, True)
            res = res._replace(points=scale * res.points @ Rs.T + t,
                               rotations=Rs @ res.rotations,
                               positions=scale * res.positions @ Rs.T + t)
            self.similarity_scale_ = scale
            self.similarity_ = (Rs, scale, t)
        self.inconsistent_ = _inconsistent(obs, res, self.max_ray_error, ids)
        points = res.points.copy()
        points[self.inconsistent_] = np.nan
        points[self.unanchored_] = np.nan  # any place there would be a guess
        self.embedding_ = points
        self.rotations_, self.positions_ = res.rotations, res.positions
        self.range_scale_, self.n_iter_ = res.range_scale, res.n_iter
        return self

    @staticmethod
    def _rays_start(obs, ids, pos, how, noise):
        """Rays alone: ``how`` = "global": the global structure from motion
        (:func:`~mappers.spatial.global_start.register_global`), "incremental": the merged
        pieces (:func:`~mappers.spatial.incremental.register_incremental`), grown by resection
        and intersection; "anchors" or where the global one places nothing: resection and
        intersection from the anchors; where that leaves steps
        unplaced, the sightings' 3-D map (COVIS-3D) stands in for the objects' positions to
        resect them roughly (their rays to it within 30 degrees), and the objects are intersected
        again from those steps."""
        if how in ("global", "incremental"):
            fn = register_global if how == "global" else register_incremental
            P, R, C = fn(obs, ids, pos, noise=noise)
            if np.isfinite(C[:, 0]).any():
                return register_rays(obs, ids, pos, start=(P, R, C))
        start = register_rays(obs, ids, pos)
        # a step that sees fewer than three objects can never be resected: the share is of
        # those that can
        posable = np.bincount(obs.step, minlength=obs.n_steps) >= 3
        if np.isfinite(start[2][posable, 0]).mean() > 0.5:
            return start
        seen = np.zeros((obs.n_objects, obs.n_steps))
        seen[obs.obj, obs.step] = 1.0
        try:
            rough = CoVisibility3D().fit_transform(seen, anchor_ids=ids, anchor_positions=pos)
        except ValueError:
            return start
        _, R, C = register_rays(obs, ids, pos, start=(rough, *start[1:]),
                                max_rms=np.deg2rad(30.0), rounds=1)
        fresh = np.full_like(rough, np.nan)
        return register_rays(obs, ids, pos, start=(fresh, R, C))

    def _regrow(self, obs, ids, pos, fixed, start):
        """Rays alone: up to ``REGROW_ROUNDS`` rounds of a short adjustment, the steps whose rays
        miss the adjusted map by a median angle above ``max_ray_error`` unposed, the objects
        left out intersected by consensus within that angle, the steps resected again
        (:mod:`mappers.spatial.regrow`); until a round places nothing new."""
        P, R, C = start
        posable = int((np.bincount(obs.step, minlength=obs.n_steps) >= 3).sum())
        for _ in range(REGROW_ROUNDS):
            placed, posed = np.isfinite(P[:, 0]).sum(), np.isfinite(C[:, 0]).sum()
            if placed == obs.n_objects and posed >= posable:
                break
            res = adjust_viewpoints(obs, P, R, C, fixed, bearing_noise=self.bearing_noise,
                                    loss=self.loss, loss_scale=self.loss_scale,
                                    max_iter=REGROW_ITER, tol=1e-4,
                                    anchor_noise=self.anchor_noise,
                                    dense_coupling_bytes=self.dense_coupling_bytes,
                                    gain_tol=self.gain_tol)
            P, R, C = res.points, res.rotations.copy(), res.positions.copy()
            if self.anchor_noise is not None:
                P = P.copy()
                P[ids] = pos
            off = step_ray_errors(obs, P, R, C) > self.max_ray_error
            R[off], C[off] = np.nan, np.nan
            P = intersect_by_consensus(obs, P, R, C, self.max_ray_error)
            P, R, C = register_rays(obs, ids, pos, start=(P, R, C))
            if np.isfinite(P[:, 0]).sum() <= placed and np.isfinite(C[:, 0]).sum() <= posed:
                break
        return P, R, C


def _inconsistent(obs, res, max_error: float, anchors) -> np.ndarray:
    """Ids of the placed, non-anchor objects whose sightings from the posed steps miss them by a
    median angle above ``max_error``, or that lie behind the sensor in most of them."""
    P, R, C = res.points, res.rotations, res.positions
    use = np.all(np.isfinite(P[obs.obj]), axis=1) & np.isfinite(C[obs.step, 0])
    v = np.einsum("kji,kj->ki", R[obs.step[use]], P[obs.obj[use]] - C[obs.step[use]])
    cos = np.einsum("kj,kj->k", v, obs.ray[use]) / np.maximum(np.linalg.norm(v, axis=1), 1e-12)
    angle = np.arccos(np.clip(cos, -1.0, 1.0))
    world = np.einsum("kij,kj->ki", R[obs.step[use]], obs.ray[use])  # the rays in the world
    ranged = np.isfinite(obs.range[use])
    bad = []
    for i in np.unique(obs.obj[use]):
        mine = obs.obj[use] == i
        a = angle[mine]
        # rays alone fix an object's depth only where its rays diverge (as an intersection)
        parallel = not ranged[mine].any() and np.min(world[mine] @ world[mine].T) > np.cos(
            MIN_RAY_ANGLE)
        if i not in anchors and (np.median(a) > max_error or np.mean(a > np.pi / 2) > 0.5
                                 or parallel):
            bad.append(int(i))
    return np.array(bad, dtype=np.int64)
