"""Incremental bearing bundle adjustment: BEARING-BA kept up to date as a bearing history grows.

:class:`mappers.online.mapper.OnlineMapper` updates CAL-SMA incrementally for complete bearing
histories (cheap, but centimetres from the truth on perfect bearings); ``build_map``'s default,
BEARING-BA (:mod:`mappers.viewpoints.bearing`), refines that map by estimating every step's
viewpoint. :class:`OnlineBundle` keeps the refinement's state, the objects and every step's pose,
between updates instead of refitting it from the whole history:

- *new steps*: each new step's pose is resected against the current objects (BEARING-BA's
  closed form and Gauss-Newton, batched), the objects fixed: O(k M) for k new steps;
- *joint rounds*: every ``every`` updates, or sooner once the steps have grown by 5% since the
  last (every update of a short history, whose new steps weigh most), ``rounds`` Levenberg-Marquardt rounds of BEARING-BA's joint problem (poses and
  non-anchor objects, Schur complement, Huber weights at the scale of the last refit) over all
  steps, warm from the current state (a fraction of a full fit's cost:
  ``docs/online-and-exploration.md``, "Online bearing maps");
- *refits*: a full BEARING-BA fit over the whole history, from the CAL-SMA map
  (``start_positions``), whenever the CAL-SMA map is refitted (the online mapper's geometric
  schedule, or a fold check) or objects join it: the offline map of those steps, to rounding.

Guards as BEARING-BA's: a refit that does not lower the robust angle cost below the CAL-SMA
start's, or is not finite, leaves no state (the CAL-SMA map is returned, with the refit's
warning, until the next refit); a joint round only takes steps that lower the cost, drops
viewpoints that drift out of the map's box, and a non-finite result drops the state likewise.

References: Triggs et al., *Bundle Adjustment — A Modern Synthesis* (2000).
"""

from __future__ import annotations

import warnings

import numpy as np

from mappers.viewpoints import (
    BearingAdjustment,
    bearing_angles,
    bearing_residuals,
    initial_poses,
    resect,
    robust_cost,
)

__all__ = ["OnlineBundle"]

_GROWTH = 1.05
"""A joint round is due, whatever ``every`` says, once the steps have grown by this factor since
the last round or refit (large batches)."""


class OnlineBundle:
    """BEARING-BA's state (objects, every step's pose) updated as steps arrive (module docstring).

    Args:
        params: BEARING-BA's parameters (``start`` None or CAL-SMA: the online CAL-SMA map is the
            start).
        anchor_ids, anchor_positions: the anchors, held fixed.
        every: a warm joint round every this many updates.
        rounds: Levenberg-Marquardt rounds per joint round.

    Attributes:
        n_refits, n_rounds: full BEARING-BA fits and warm joint rounds so far.
    """

    def __init__(self, params: dict, anchor_ids, anchor_positions, *, every: int = 5,
                 rounds: int = 1) -> None:
        self.est = BearingAdjustment(**params)
        self.lm = BearingAdjustment(**{**params, "max_rounds": rounds})
        self.ids, self.pos = anchor_ids, anchor_positions
        self.every = every
        self._blocks: list[np.ndarray] = []
        self.n_steps = 0
        self.n_refits = self.n_rounds = 0
        self.state: dict | None = None
        self.notes: tuple[str, ...] = ()
        self.start_placed: np.ndarray | None = None  # the start's mapped objects at the refit
        self._updates = 0  # updates since the last round or refit
        self._steps_at_round = 0

    # ------------------------------------------------------------------ steps
    def angles(self, columns: np.ndarray):
        """The new steps' bearings (theta, seen), (k, M); a ValueError for non-unit pairs."""
        return bearing_angles(columns)

    def add(self, columns: np.ndarray, theta: np.ndarray, seen: np.ndarray) -> None:
        """Keep the new steps' columns and, with a state, resect their poses."""
        self._blocks.append(columns)
        if self.state is not None:
            self._resect_new(theta, seen)
        self.n_steps += len(theta)
        self._updates += 1

    def _resect_new(self, theta, seen) -> None:
        s, est = self.state, self.est
        k = len(theta)
        seen = seen & s["placed"][None, :]
        seen &= (seen.sum(1) >= est.min_step_objects)[:, None]
        t, i = np.nonzero(seen)
        obs = (t, i, theta[t, i])
        C, phi, ok0 = initial_poses(s["P"], obs, k)  # as BEARING-BA's own resection
        C, phi, ok = resect(s["P"], C, phi, obs, np.ones(len(t)), 3)
        ok &= ok0 & self.lm._inside(C)
        keep = ok[t] & ~s["weak"][i]
        keep &= (np.bincount(t[keep], minlength=k) >= est.min_step_objects)[t]
        ok = np.zeros(k, dtype=bool)
        ok[t[keep]] = True
        s["C"] = np.concatenate([s["C"], np.where(ok[:, None], C, 0.0)])
        s["phi"] = np.concatenate([s["phi"], np.where(ok, phi, 0.0)])
        s["obs"] = tuple(np.concatenate([a, b[keep]])
                         for a, b in zip(s["obs"], (t + self.n_steps, i, obs[2]), strict=True))

    # ------------------------------------------------------------------ fits
    def refit(self, start: np.ndarray) -> None:
        """A full BEARING-BA fit of the whole history from ``start`` (M, 2), NaN rows unmapped."""
        X = np.concatenate(self._blocks, axis=1)
        self._blocks = [X]
        self.start_placed = np.isfinite(start[:, 0])
        est = self.est
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            est.fit(X, anchor_ids=self.ids, anchor_positions=self.pos, start_positions=start)
        self.notes = tuple(dict.fromkeys(f"{w.category.__name__}: {w.message}" for w in caught))
        self.n_refits += 1
        self._updates, self._steps_at_round = 0, self.n_steps
        self.state = None
        if not est.refined_:
            return
        theta, seen = bearing_angles(X)
        placed = np.all(np.isfinite(est.embedding_), axis=1)
        weak = np.zeros(len(placed), dtype=bool)
        weak[est.kept_] = True
        free = placed & ~weak
        free[self.ids] = False
        pose_ok = np.isfinite(est.poses_[:, 0])
        # the observations BEARING-BA weighted at the end of its fit
        seen = seen & placed[None, :]
        seen &= (seen.sum(1) >= est.min_step_objects)[:, None]
        seen &= pose_ok[:, None] & ~weak[None, :]
        t, i = np.nonzero(seen)
        self.lm._box = est._box
        self.state = {"P": np.where(placed[:, None], est.embedding_, 0.0), "placed": placed,
                      "free": free, "weak": weak, "scale": est.scale_,
                      "C": np.where(pose_ok[:, None], est.poses_[:, :2], 0.0),
                      "phi": np.where(pose_ok, est.poses_[:, 2], 0.0),
                      "obs": (t, i, theta[t, i])}

    def due(self) -> bool:
        """Whether a warm joint round is due at this update."""
        return self.state is not None and (
            self._updates >= self.every or self.n_steps >= _GROWTH * max(self._steps_at_round, 1))

    def joint_round(self) -> None:
        """Warm Levenberg-Marquardt rounds over all steps (BEARING-BA's ``_joint``)."""
        s = self.state
        obs = s["obs"]
        P, C, phi, wb, _ = self.lm._joint(s["P"], s["C"], s["phi"], obs, np.ones(len(obs[0])),
                                          s["free"], s["scale"])
        self.n_rounds += 1
        self._updates, self._steps_at_round = 0, self.n_steps
        if not (np.all(np.isfinite(P)) and np.all(np.isfinite(C)) and np.all(np.isfinite(phi))):
            self.state = None
            self.notes = (*self.notes, f"BearingAdjustmentWarning: a joint round at {self.n_steps} "
                          "steps gave a map that is not finite: the CAL-SMA map is kept until the "
                          "next refit")
            return
        keep = wb > 0  # viewpoints that drifted out of the map's box left the problem
        s.update(P=P, C=C, phi=phi, obs=tuple(a[keep] for a in obs))

    def cost(self) -> float:
        """The state's robust angle cost (BEARING-BA's, at the last refit's scale)."""
        s = self.state
        res, _ = bearing_residuals(s["P"], s["C"], s["phi"], s["obs"])
        return float(np.sum(robust_cost(res, s["scale"], self.est.loss)))

    def positions(self) -> np.ndarray:
        """The current objects (M, 2), NaN rows unplaced."""
        s = self.state
        return np.where(s["placed"][:, None], s["P"], np.nan)
