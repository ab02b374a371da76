"""FRUSTUM-BA: a 3-D map from sightings through a camera's known view (issue 34).

The 3-D analogue of VIEW-BA (:mod:`mappers.viewpoints.view_cone`). A camera on a robot that
drives a plane, at a known height above it and pitched by a known angle, with a known
horizontal and vertical field of view and range limit (the camera's mounting and intrinsics,
a sensor's calibration like VIEW-BA's view angle), sees at every step the objects inside its
view frustum and not hidden. Each step's sightings are one bit per object: the seen objects lie
inside the frustum of that step's viewpoint, the others (unless hidden or missed) outside it.
This method estimates each step's planar viewpoint ``(x, y, heading)`` as a latent variable
and the objects' 3-D positions with them, a frustum bundle adjustment. No motion model, no
odometry: the steps are independent viewpoints, found from the sightings alone; the poses are
estimated, never read. (FRUSTUM-BA-WALK, :mod:`mappers.spatial.frustum_walk`, adds a motion
prior: the steps of a walk, consecutive viewpoints close together.)

The model per (step, object) pair (:mod:`mappers.spatial.frustum_kernels`): five soft margins
(the image's four sides and the range limit), ``q`` the product of their sigmoids; a sighting
has probability ``(1 - miss_rate) q``, no sighting ``1 - (1 - miss_rate) q`` (the miss rate
absorbs occlusion and dropouts). The loss is the negative log-likelihood.

The steps:

1. **The start map**: ``COVIS-3D`` (:mod:`mappers.spatial.covisibility_3d`), or
   ``start_positions``.
2. For each softness of ``softness`` (soft to sharp, a continuation: a soft frustum sees the
   map's coarse shape, a sharp one its detail):

   a. **viewpoints** (the first softness only): per step the best of a grid of positions
      (``grid`` per side over the map's floor plan) x ``headings``, one (N, M) x (M, G)
      product as VIEW-BA's search;
   b. ``pose_iters`` damped Newton steps of each viewpoint alone (the objects held);
   c. **joint Levenberg-Marquardt** rounds of the viewpoints and the free objects, each
      viewpoint's 3 x 3 block eliminated (the Schur complement of
      :func:`mappers.viewpoints.engine.schur_step`, p = 3 pose and d = 3 object parameters,
      under :func:`mappers.viewpoints.engine.damped_step`); the anchors held (they fix the
      gauge).

Guard: if the refined loss (at the sharpest softness) is not below the start map's (its
viewpoints fitted the same way) or anything is not finite, the start map is returned with a
:class:`FrustumAdjustmentWarning`.

*Assumes*: a camera on a planar robot, its mounting and view known; a static world; one
viewpoint per step; every 0 a reading (an unmasked history). A handheld camera (6-DoF
viewpoints, as STAR-loc's) is outside this model: see ``docs/guide/3d.md``.

References: Triggs et al., *Bundle Adjustment — A Modern Synthesis* (2000), for the bundle
adjustment and its Schur complement; Böhning & Lindsay (1988) for the bound on the logistic's
curvature; Hartley & Zisserman, *Multiple View Geometry* (2003), ch. 6, for the pinhole view.
"""

from __future__ import annotations

import math
from numbers import Integral, Real

import numpy as np
from scipy.special import log_expit
from sklearn.base import BaseEstimator
from sklearn.utils._param_validation import Interval

from mappers.core.align_3d import check_anchors_3d
from mappers.core.embedding_transformer import EmbeddingTransformer
from mappers.core.validation import check_views
from mappers.spatial import frustum_kernels as kernels
from mappers.spatial.covisibility_3d import CoVisibility3D
from mappers.viewpoints import (
    VIEWPOINT_SEARCH_CONSTRAINTS,
    Damping,
    damped_step,
    free_objects,
    keep_if_better,
    schur_step,
    search_cells,
    search_poses,
)

__all__ = ["FrustumAdjustment", "FrustumAdjustmentWarning", "FrustumCamera", "view_log_prob"]

DAMPING = Damping(up=5.0, down=3.0, floor=1e-6, tries=8, accept_equal=False)
"""FRUSTUM-BA's Levenberg-Marquardt damping rule (VIEW-BA's)."""

MAX_FREE_OBJECTS = 1000
"""Most free objects FRUSTUM-BA takes: its joint step holds an (N, 3, 3F) block and solves a
(3F, 3F) system per round (at F = 1,000 and N = 2,000: 144 MB and 27 GFLOP a round)."""

_MAX_SEARCH_ENTRIES = 2e8
"""Largest steps x candidate viewpoints the grid search holds (float64: 1.6 GB)."""


class FrustumAdjustmentWarning(UserWarning):
    """FRUSTUM-BA kept its start map."""


class FrustumCamera:
    """The known camera of a planar robot (its calibration): ``height`` [m] of the optical
    centre above the floor, ``pitch_deg`` tilt of the optical axis above the horizontal,
    ``hfov_deg`` / ``vfov_deg`` fields of view, ``max_range`` [m] (None: no limit). The frame
    and view are those of :mod:`lfmdr_gym.sim.view3d` (``x`` right, ``y`` down, ``z``
    forward)."""

    def __init__(self, height: float, pitch_deg: float, hfov_deg: float, vfov_deg: float,
                 max_range: float | None) -> None:
        for name, value, lo, hi in (("camera_height", height, 0.0, math.inf),
                                    ("pitch_deg", pitch_deg, -90.0, 90.0),
                                    ("hfov_deg", hfov_deg, 0.0, 180.0),
                                    ("vfov_deg", vfov_deg, 0.0, 180.0)):
            if not (isinstance(value, Real) and lo < value < hi):
                raise ValueError(f"{name} must be a number in ({lo:g}, {hi:g}), got {value!r}")
        if max_range is not None and not (isinstance(max_range, Real) and max_range > 0):
            raise ValueError(f"max_range must be None or a number > 0, got {max_range!r}")
        self.height, self.pitch = float(height), math.radians(pitch_deg)
        self.t_h = math.tan(math.radians(hfov_deg) / 2.0)
        self.t_v = math.tan(math.radians(vfov_deg) / 2.0)
        self.max_range = math.inf if max_range is None else float(max_range)

    def args(self, softness: float, range_softness: float, miss_rate: float) -> tuple:
        """The kernels' camera and model arguments, in their order."""
        return (self.height, self.pitch, self.t_h, self.t_v, self.max_range, softness,
                range_softness, miss_rate)


def view_log_prob(positions, viewpoints, camera: FrustumCamera, softness: float,
                  range_softness: float) -> np.ndarray:
    """(K, M): the log of each object's soft probability ``q`` of being in the view of each
    viewpoint (``positions`` (M, 3), ``viewpoints`` (K, 3) as (x, y, heading)); the kernels'
    model as array expressions, for the grid search."""
    P = np.asarray(positions, dtype=float)
    C = np.asarray(viewpoints, dtype=float)
    rel = P[None, :, :] - np.column_stack([C[:, :2], np.full(len(C), camera.height)])[:, None, :]
    ch, sh = np.cos(C[:, 2])[:, None], np.sin(C[:, 2])[:, None]
    cp, sp = math.cos(camera.pitch), math.sin(camera.pitch)
    ah = ch * rel[..., 0] + sh * rel[..., 1]
    xc = sh * rel[..., 0] - ch * rel[..., 1]
    zc = cp * ah + sp * rel[..., 2]
    yc = sp * ah - cp * rel[..., 2]
    d = np.linalg.norm(rel, axis=2) + 1e-9
    k = 1.0 / (d * softness)
    out = (log_expit((camera.t_h * zc - xc) * k) + log_expit((camera.t_h * zc + xc) * k)
           + log_expit((camera.t_v * zc - yc) * k) + log_expit((camera.t_v * zc + yc) * k))
    ranged = (camera.max_range - d) / range_softness if math.isfinite(camera.max_range) \
        else np.full_like(d, 50.0)
    return out + log_expit(ranged)


def _damped_block_steps(A: np.ndarray, g: np.ndarray, lam: float) -> np.ndarray:
    """Each block's Newton step ``x_i`` of ``(A_i + lam diag(A_i) + 1e-9 I) x_i = g_i``: the
    blocks ``A`` (n, k, k) damped as Levenberg-Marquardt does, the gradients ``g`` (n, k)."""
    A = A.copy()
    diag = np.arange(A.shape[-1])
    A[:, diag, diag] *= 1.0 + lam
    A[:, diag, diag] += 1e-9
    return np.linalg.solve(A, g[..., None])[..., 0]


class FrustumProblem:
    """The frustum loss of fixed sightings ``seen`` ((N, M) bool) and its Gauss-Newton steps;
    ``free_index[j]`` is object j's row among the ``n_free`` free objects, or -1 (an anchor:
    held); ``args`` the kernels' camera and model arguments (:meth:`FrustumCamera.args`)."""

    def __init__(self, seen, free_index, n_free: int, args: tuple) -> None:
        self.seen = np.ascontiguousarray(seen, dtype=bool)
        self.free_index, self.n_free, self.args = free_index, int(n_free), args
        self._none = np.full(len(free_index), -1, dtype=np.int64)

    def cost(self, P, C) -> float:
        return kernels.frustum_loss(P, C, self.seen, *self.args)

    def blocks(self, P, C, *, objects: bool = True):
        """``(loss, U, V, W, g, h)``: the normal equations' blocks; ``objects=False``: the
        viewpoints' only."""
        fi, nf = (self.free_index, self.n_free) if objects else (self._none, 0)
        n = len(C)
        U, g = np.zeros((n, 3, 3)), np.zeros((n, 3))
        V, h, W = np.zeros((nf, 3, 3)), np.zeros((nf, 3)), np.zeros((n, 3, 3 * nf))
        loss = kernels.frustum_blocks(P, C, self.seen, fi, *self.args, U, V, W, g, h)
        return loss, U, V, W, g, h

    def pose_steps(self, P, C, iters: int):
        """``(C, loss)`` after up to ``iters`` damped Newton steps of every viewpoint alone."""
        _, C, loss = self._steps(P, C, iters, "poses")
        return C, loss

    def object_steps(self, P, C, iters: int):
        """``(P, loss)`` after up to ``iters`` damped Newton steps of the free objects alone,
        the viewpoints ``C`` held (each object's 3 x 3 block: the objects do not couple)."""
        P, _, loss = self._steps(P, C, iters, "objects")
        return P, loss

    def joint(self, P, C, rounds: int):
        """``(P, C, loss)`` after up to ``rounds`` joint Levenberg-Marquardt rounds."""
        return self._steps(P, C, rounds, "joint")

    def _steps(self, P, C, iters: int, which: str):
        """``(P, C, loss)`` after up to ``iters`` damped steps of ``which``: the viewpoints
        alone (``"poses"``), the free objects alone (``"objects"``), each on its own block, or
        both (``"joint"``, the Schur-eliminated system)."""
        loss, lam = self.cost(P, C), 1e-2
        free = self.free_index >= 0
        for _ in range(iters):
            _, U, V, W, g, h = self.blocks(P, C, objects=which != "poses")

            def trial(lam, U=U, V=V, W=W, g=g, h=h, P=P, C=C):
                P2, C2 = P, C
                if which == "joint":
                    dc, dp = schur_step(U, V, W, g, h, lam)
                    P2 = P.copy()
                    P2[free] += dp
                    C2 = C + dc
                elif which == "poses":
                    C2 = C - _damped_block_steps(U, g, lam)
                else:
                    P2 = P.copy()
                    P2[free] -= _damped_block_steps(V, h, lam)
                return (P2, C2), self.cost(P2, C2)

            state, loss, lam, moved = damped_step(trial, loss, lam, DAMPING)
            if not moved:
                break
            P, C = state
        return P, C, loss


class FrustumAdjustment(EmbeddingTransformer, BaseEstimator):
    """Frustum bundle adjustment of a 3-D sightings map (module docstring).

    Parameters (the first four are the camera's calibration and must be given):
        camera_height: the optical centre's height above the robot's floor [m].
        pitch_deg: tilt of the optical axis above the horizontal [deg].
        hfov_deg, vfov_deg: the horizontal and vertical fields of view [deg].
        max_range: the range limit [m], or None (none).
        softness: the frustum's softnesses, soft to sharp (a continuation), in units of the
            tangent of an angle (0.05: about 3 degrees).
        range_softness: the range limit's softness [m].
        miss_rate: the probability that an object in view is not seen (occlusion, dropouts).
        rounds: joint Levenberg-Marquardt rounds per softness.
        grid, headings: the viewpoints' search grid (positions per side, headings).
        pose_iters: Newton steps of each viewpoint alone before each softness's rounds.
        max_iter: COVIS-3D's SMACOF updates for the start map.

    Attributes: ``embedding_`` (M, 3) the map (NaN rows: not placed); ``start_`` the start
    map; ``poses_`` (N, 3) the viewpoints ``(x, y, heading)`` found (NaN: steps left out);
    ``refined_`` whether the adjustment replaced the start map; ``loss_`` and ``start_loss_``
    per pair at the sharpest softness.
    """

    _parameter_constraints = {
        "camera_height": [Interval(Real, 0.0, None, closed="neither"), None],
        "pitch_deg": [Interval(Real, -90.0, 90.0, closed="neither"), None],
        "hfov_deg": [Interval(Real, 0.0, 180.0, closed="neither"), None],
        "vfov_deg": [Interval(Real, 0.0, 180.0, closed="neither"), None],
        "max_range": [Interval(Real, 0.0, None, closed="neither"), None],
        "softness": ["array-like"],
        "range_softness": [Interval(Real, 0.0, None, closed="neither")],
        "miss_rate": [Interval(Real, 0.0, 1.0, closed="neither")],
        "rounds": [Interval(Integral, 0, None, closed="left")],
        **VIEWPOINT_SEARCH_CONSTRAINTS,
        "max_iter": [Interval(Integral, 1, None, closed="left")],
    }

    def __init__(self, *, camera_height: float | None = None, pitch_deg: float | None = None,
                 hfov_deg: float | None = None, vfov_deg: float | None = None,
                 max_range: float | None = None,
                 softness=(0.1, 0.05), range_softness: float = 0.1,
                 miss_rate: float = 0.1, rounds: int = 30, grid: int = 15, headings: int = 36,
                 pose_iters: int = 3, max_iter: int = 300):
        self.camera_height = camera_height
        self.pitch_deg = pitch_deg
        self.hfov_deg = hfov_deg
        self.vfov_deg = vfov_deg
        self.max_range = max_range
        self.softness = softness
        self.range_softness = range_softness
        self.miss_rate = miss_rate
        self.rounds = rounds
        self.grid = grid
        self.headings = headings
        self.pose_iters = pose_iters
        self.max_iter = max_iter

    def fit(self, X, y=None, *, anchor_ids=None, anchor_positions=None, mask=None,
            start_positions=None):
        """Map the sightings ``X`` (M, N) of 0/1 in 3-D (see the module's docstring)."""
        self._validate_params()
        soft = np.asarray(self.softness, dtype=float).ravel()
        if soft.size == 0 or not np.all(soft > 0):
            raise ValueError(f"softness must be one or more numbers > 0, got {self.softness!r}")
        if mask is not None and not np.all(mask):
            raise ValueError("FRUSTUM-BA reads every step's sightings (a 0 is a reading: not in "
                             "view, hidden or missed); this history is masked: map it with "
                             "COVIS-3D")
        X = check_views(self, X)
        if not np.all((X == 0) | (X == 1)):
            raise ValueError("FRUSTUM-BA maps visibility histories: an (M, N) array of 0/1")
        if anchor_ids is None or anchor_positions is None:
            raise ValueError("FRUSTUM-BA needs anchors: anchor_ids and anchor_positions (A, 3)")
        ids, pos = check_anchors_3d(anchor_ids, anchor_positions, X.shape[0], fit="affine")
        missing = [k for k in ("camera_height", "pitch_deg", "hfov_deg", "vfov_deg")
                   if getattr(self, k) is None]
        if missing:
            raise ValueError(f"FRUSTUM-BA needs the camera's calibration: give {missing} (and "
                             "max_range, None for no limit); e.g. LFMDR-Camera3D-v0's env.camera")
        camera = FrustumCamera(self.camera_height, self.pitch_deg, self.hfov_deg,
                               self.vfov_deg, self.max_range)
        if start_positions is None:
            P0 = CoVisibility3D(max_iter=self.max_iter).fit_transform(
                X, anchor_ids=ids, anchor_positions=pos)
        else:
            P0 = np.array(start_positions, dtype=float)
            if P0.shape != (X.shape[0], 3):
                raise ValueError(f"start_positions must have shape ({X.shape[0]}, 3), got "
                                 f"{P0.shape}")
        P0[ids] = pos
        self.start_ = P0.copy()
        self._adjust(P0, ids, X.T > 0.5, camera, soft)
        return self

    def _adjust(self, P0, ids, seen, camera: FrustumCamera, soft: np.ndarray) -> None:
        """Adjust the start ``P0`` (the anchors in place) to the sightings ``seen`` (N, M) by
        :meth:`_solve` on the placed objects; keep it if it explains them better."""
        placed = np.all(np.isfinite(P0), axis=1)
        free = free_objects(placed, ids, self._label, 3, MAX_FREE_OBJECTS, "COVIS-3D")
        use = np.flatnonzero(placed)
        free_index = np.full(len(use), -1, dtype=np.int64)
        n_free = int(free[use].sum())
        free_index[free[use]] = np.arange(n_free)
        S = np.ascontiguousarray(seen[:, use])
        P = np.ascontiguousarray(P0[use], dtype=float)

        def problem(s):
            return FrustumProblem(S, free_index, n_free,
                                  camera.args(float(s), self.range_softness, self.miss_rate))

        P, C, loss, start_C, start_loss = self._solve(P, S, camera, soft, problem,
                                                      free_index >= 0, P0[ids])
        n_pairs = max(S.size, 1)
        self.loss_, self.start_loss_ = loss / n_pairs, start_loss / n_pairs
        out = np.full(P0.shape, np.nan)
        out[use] = P
        out[ids] = P0[ids]
        self.refined_, self.embedding_ = keep_if_better(
            out, P0.copy(), placed, self.loss_ if np.isfinite(loss) else np.inf,
            self.start_loss_, "sightings", FrustumAdjustmentWarning)
        self.poses_ = C if self.refined_ else start_C

    _label = "FRUSTUM-BA"

    def _solve(self, P, S, camera: FrustumCamera, soft: np.ndarray, problem, free, anchors):
        """``(P, C, loss, start_C, start_loss)``: the placed objects and the viewpoints after the
        grid search and, for each softness of ``soft``, pose steps and joint rounds
        (``problem(s)`` is the :class:`FrustumProblem` at softness ``s``; ``free`` marks the free
        objects, ``anchors`` the anchors' positions)."""
        C = self._search(P, S, camera, float(soft[0]))
        start_C, start_loss = problem(soft[-1]).pose_steps(P, C.copy(), self.pose_iters)
        loss = start_loss
        for s in soft:
            prob = problem(s)
            C, loss = prob.pose_steps(P, C, self.pose_iters)
            P, C, loss = prob.joint(P, C, self.rounds)
        return P, C, loss, start_C, start_loss

    def _search(self, P, S, camera: FrustumCamera, softness: float) -> np.ndarray:
        """Each step's best viewpoint among the grid's candidates (floor positions over the
        objects' plan x headings), the objects held: ``(N, 3)``."""
        cand = search_poses(search_cells(P[:, :2], self.grid), self.headings)
        if S.shape[0] * len(cand) > _MAX_SEARCH_ENTRIES:
            raise ValueError(f"{S.shape[0]} steps x {len(cand)} candidate viewpoints exceed "
                             f"{_MAX_SEARCH_ENTRIES:.0e} entries: lower grid or headings")
        a = 1.0 - self.miss_rate
        lq = view_log_prob(P, cand, camera, softness, self.range_softness)
        l1, l0 = math.log(a) + lq, np.log1p(-a * np.exp(lq))
        score = S.astype(float) @ (l1 - l0).T + l0.sum(axis=1)[None, :]
        return cand[score.argmax(axis=1)].copy()
