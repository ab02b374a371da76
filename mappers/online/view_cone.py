"""Incremental view-cone adjustment: VIEW-BA kept up to date as a masked visibility history grows.

``build_map``'s default for masked visibility histories (a limited view), VIEW-BA
(:mod:`mappers.viewpoints.view_cone`), estimates every step's viewpoint and heading with the objects.
A refit costs most of a second at N = 2,000 steps, so an online mapper that only refits on a
geometric schedule would return a stale map in between. :class:`OnlineView` keeps
the adjustment's state, the objects, every step's viewpoint, the view's width and the visibility
radius, between updates instead:

- *refits*: VIEW-BA over the whole history (:func:`mappers.pipeline.build_map`'s own fit, so the
  map is the offline one of those steps), on :class:`~mappers.online.mapper.OnlineMapper`'s schedule
  (every 1.25x growth of the steps by default), and whenever an object is seen for the first
  time since the last one (it has no place yet);
- *refinements* (due only when refits are sparser than every 1.25x: ``OnlineMapper``'s
  ``refit_growth`` above its VIEW-BA default, 1.25): whenever the steps have grown by a quarter
  since the last refit or refinement, VIEW-BA over the whole history from the current objects
  instead of a start map (:meth:`OnlineView.refine`): the view's width, the radius and every
  viewpoint found afresh, then its rounds, in as many passes as the refit's estimator makes
  (its parameters copied: three by default); a refit without its start map
  (``DROPOUT-BLEND``), which does not shrink with the steps (about a third of a refit when
  VIEW-BA made one pass);
- *new steps*: each new step's viewpoint is searched on VIEW-BA's grid of candidates over the
  current objects and refined by its Newton steps, the objects fixed: O(k M G) for k new steps
  and G candidates;
- *joint rounds*: every ``every`` updates, or sooner once the steps have grown by 5 % since the
  last round (every update of a short history), ``rounds`` Levenberg-Marquardt rounds of
  VIEW-BA's joint problem (viewpoints and free objects, :class:`ConeProblem`) over all steps,
  warm from the current state: O(N M) for the blocks plus O(N F^2 + F^3) for the Schur system.

Warm rounds alone do not carry the map far: VIEW-BA's loss has many basins, and a map fitted
on few steps stays in its own as steps arrive (``docs/online-and-exploration.md``); the
refinements re-search the viewpoints and the refits redraw the start. The view's width and the
radius stay those of the last refit or refinement between them. Guards as VIEW-BA's: a refit that
keeps its start map (the view too wide, the mask not a cone, no gain) leaves no state, and the
online mapper returns that map until its next scheduled refit; a joint round only takes steps
that lower the loss; a state that is not finite is dropped likewise.
"""

from __future__ import annotations

import warnings

import numpy as np

from mappers.viewpoints import ConeProblem, ViewAdjustment

__all__ = ["OnlineView"]

_REFINE_GROWTH = 1.25  # chosen on the tuning seeds: docs/online-and-exploration.md (VIEW-BA)
"""A refinement (:meth:`OnlineView.refine`) once the steps have grown by this factor since the
last refit or refinement."""
_GROWTH = 1.05
"""A joint round is due, whatever ``every`` says, once the steps have grown by this factor since
the last round or refit."""


class OnlineView:
    """VIEW-BA's state (objects, viewpoints) updated as masked visibility steps arrive.

    Args:
        every: a warm joint round every this many updates.
        rounds: Levenberg-Marquardt rounds per joint round.

    :meth:`start` takes the state of a fitted :class:`ViewAdjustment`; :meth:`add` places new
    steps; :meth:`joint_round` refines all of them with the objects; :meth:`refine` fits VIEW-BA
    again from the current objects.

    Attributes:
        n_refits, n_rounds: VIEW-BA fits taken and warm joint rounds so far.
        state: None, or the objects ``P`` (U, 2) of the global rows ``cols``, the viewpoints
            ``C`` of the steps that observed any of them, and their observed / seen sets (the view
            width and the radius are those of ``est``, the fit the state came from).
    """

    def __init__(self, *, every: int = 5, rounds: int = 1) -> None:
        self.every, self.rounds = int(every), int(rounds)
        self.n_refits = self.n_rounds = 0
        self.n_steps = 0
        self.state: dict | None = None
        self.est: ViewAdjustment | None = None  # the fit the state came from
        self.has_data: np.ndarray | None = None  # (M,) objects seen so far
        self._fitted = None  # ... at the last refit
        self._updates = 0
        self._steps_at_round = 0
        self._steps_at_refine = 0

    # ------------------------------------------------------------------ refits
    def start(self, est: ViewAdjustment, X: np.ndarray, mask: np.ndarray, mapped: np.ndarray,
              anchors: np.ndarray) -> None:
        """Take the state of ``est``, VIEW-BA fitted on the rows ``mapped`` of the whole history
        ``X`` / ``mask`` ((M, N)); ``anchors``: its anchors' global rows."""
        self.n_refits += 1
        self.n_steps = X.shape[1]
        self.has_data = np.zeros(X.shape[0], dtype=bool)
        self.has_data[mapped] = True  # the fit's rows: the objects with data
        self._fitted = self.has_data.copy()
        self._updates, self._steps_at_round = 0, self.n_steps
        self._steps_at_refine = self.n_steps
        self.state = None
        if not getattr(est, "refined_", False):
            return
        self.est = est
        placed = np.all(np.isfinite(est.embedding_), axis=1)
        cols = mapped[placed]
        free = ~np.isin(cols, anchors)
        free_index = np.full(len(cols), -1, dtype=np.int64)
        free_index[free] = np.arange(int(free.sum()))
        steps = np.isfinite(est.poses_[:, 0])
        obs = mask.T[:, cols]
        seen = (X.T[:, cols] > 0.5) & obs
        self.state = {"P": np.ascontiguousarray(est.embedding_[placed]), "cols": cols,
                      "free_index": free_index, "n_free": int(free.sum()),
                      "C": est.poses_[steps].copy(), "obs": [obs[steps]], "seen": [seen[steps]],
                      "lam": 1e-2, "candidates": None}

    def refine_due(self) -> bool:
        """Whether a refinement is due (the steps grown by ``_REFINE_GROWTH`` since the last)."""
        return self.state is not None and self.n_steps >= _REFINE_GROWTH * self._steps_at_refine

    def refine(self, X, mask, anchor_ids, anchor_positions) -> tuple[str, ...]:
        """VIEW-BA over the whole history from the current objects (no start map drawn): the
        view's width, the radius and every viewpoint found afresh, then its rounds."""
        m = X.shape[0]
        rows = np.flatnonzero(self.has_data)
        start = self.positions(m)[rows]
        held = np.isin(anchor_ids, rows)
        local = np.searchsorted(rows, anchor_ids[held])
        est = ViewAdjustment(**self.est.get_params())
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                est.fit(X[rows], mask=mask[rows], anchor_ids=local,
                        anchor_positions=anchor_positions[held], start_positions=start)
            except ValueError as exc:  # VIEW-BA refused the history: the state carries on
                self._steps_at_refine = self.n_steps
                return (f"VIEW-BA: a refinement at {self.n_steps} steps failed ({exc}); the "
                        "map is carried on",)
        if est.refined_:
            self.start(est, X, mask, rows, anchor_ids[held])
        else:  # no lower loss than the current objects' (or not a cone): the state carries on
            self._steps_at_refine = self.n_steps
        return tuple(dict.fromkeys(f"VIEW-BA: {w.category.__name__}: {w.message}" for w in caught))

    def _problem(self, obs, seen) -> ConeProblem:
        return self.est._problem(obs, seen, self.state["free_index"], self.state["n_free"])

    # ------------------------------------------------------------------ steps
    def add(self, columns: np.ndarray, mask: np.ndarray) -> None:
        """Place the new steps' viewpoints ((M, k) columns and mask) against the current objects:
        VIEW-BA's grid search, then its Newton steps."""
        self.n_steps += columns.shape[1]
        self._updates += 1
        if self.has_data is not None:
            self.has_data |= np.any(mask & (columns != 0), axis=1)
        s = self.state
        if s is None:
            return
        obs = mask.T[:, s["cols"]]
        keep = obs.any(axis=1)  # a step that observed no placed object has no viewpoint
        if not keep.any():
            return
        obs = obs[keep]
        seen = (columns.T[keep][:, s["cols"]] > 0.5) & obs
        prob, R = self._problem(obs, seen), self.est.radius_
        if s["candidates"] is None:
            s["candidates"] = self.est._candidates(s["P"])
        C = self.est._search(s["P"], prob.obs, prob.seen, prob.half, R, *s["candidates"])
        loss = prob.cost(s["P"], C, R)
        for _ in range(self.est.pose_iters):
            C, loss = prob.pose_step(s["P"], C, R, loss)
        s["C"] = np.concatenate([s["C"], C])
        s["obs"].append(prob.obs)
        s["seen"].append(prob.seen)

    def joined(self) -> bool:
        """Whether an object has been seen for the first time since the last refit."""
        return self.has_data is not None and bool(np.any(self.has_data & ~self._fitted))

    def due(self) -> bool:
        """Whether a warm joint round is due at this update."""
        return self.state is not None and (
            self._updates >= self.every or self.n_steps >= _GROWTH * max(self._steps_at_round, 1))

    def joint_round(self) -> str | None:
        """Warm Levenberg-Marquardt rounds over all steps; a note when the state was dropped."""
        s = self.state
        obs, seen = np.concatenate(s["obs"]), np.concatenate(s["seen"])
        s["obs"], s["seen"] = [obs], [seen]
        prob = self._problem(obs, seen)
        P, C, R, lam = s["P"], s["C"], self.est.radius_, s["lam"]
        loss = prob.cost(P, C, R)
        for _ in range(self.rounds):
            P, C, loss, lam, moved = prob.lm_round(P, C, R, loss, lam)
            if not moved:
                break
        self.n_rounds += 1
        self._updates, self._steps_at_round = 0, self.n_steps
        if not (np.isfinite(loss) and np.all(np.isfinite(P)) and np.all(np.isfinite(C))):
            self.state = None
            return (f"ViewAdjustmentWarning: a joint round at {self.n_steps} steps gave a map "
                    "that is not finite: the last refit's map is kept until the next refit")
        if P is not s["P"]:
            s["candidates"] = None  # the objects moved: the grid's candidates are redrawn
        s.update(P=P, C=C, lam=lam)
        return None

    def positions(self, m: int) -> np.ndarray:
        """The current objects (m, 2), NaN rows unplaced."""
        out = np.full((m, 2), np.nan)
        out[self.state["cols"]] = self.state["P"]
        return out
