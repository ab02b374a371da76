"""Online mapping: the map of a robot still moving, updated as its histories grow.

The paper (Yairi 2007) calls LFMDR "basically an off-line process" and leaves an online
algorithm open (§6). :class:`OnlineMapper` takes the new steps' columns after each batch of
steps and returns the current :class:`~mappers.pipeline.Map`, the same kind of map
:func:`~mappers.pipeline.build_map` returns for the whole history. How it updates depends on the
method:

- **CAL-SMA** on complete histories (the visibility default, and the start of BEARING-BA) is
  updated incrementally (:mod:`mappers.online.cal_sma`): its statistics are a Gram matrix
  accumulated over the new columns, and the last map is the start of ``warm_rounds`` anchored
  calibrate/re-embed rounds (warm-started SMACOF: majorisation decreases stress from any start).
  An object sensed for the first time starts at the mean position of its three most similar
  mapped objects. CAL-SMA's fold check runs on every warm update while the map is young (before
  its second scheduled refit), then every ``fold_check_every`` warm updates, and whenever
  objects join the map; a warm map that looks folded is refitted from scratch once the steps
  have grown by 1.5 since the last full fit. Full refits run from scratch whenever the steps
  have grown by ``refit_growth`` since the last scheduled one (a logarithmic number of them in
  all), without CAL-SMA's random restarts: a map that still looks folded is refitted later, with
  more steps.
- **BEARING-BA** on complete bearing histories (the default) is carried on from that CAL-SMA map
  by :class:`mappers.online.bearing.OnlineBundle`: new poses resected, a warm joint round every
  ``bundle_every`` updates, a full fit whenever CAL-SMA is refitted or objects join its map.
- **VIEW-BA** on masked visibility histories (the default) is refitted with ``build_map``'s own
  fit on a schedule of its own (``refit_growth`` 1.25: its refits, from a new start map, are
  what move the map to a better basin) and carried on in between by
  :class:`mappers.online.view_cone.OnlineView`.
- **Other methods** (and masked histories, whose methods need the steps' co-observation
  patterns) keep the columns and refit with ``build_map`` on the geometric schedule; between
  refits the last map is returned with a note in ``Map.warnings`` saying which steps it covers.

A first map that fails (too few steps: a limited view's co-observations fall apart) is tried
again once the steps have grown by a tenth, not at every update. The cost of an update does not
grow with the steps for the incremental methods; what it is, and what each choice bought:
``docs/online-and-exploration.md#onlinemapper-cost-per-update``.

References: de Leeuw (1977) and Borg & Groenen, *Modern Multidimensional Scaling* (2005), on
warm-started SMACOF; Triggs et al. (2000) for the bundle adjustments carried on.
"""

from __future__ import annotations

import dataclasses
import warnings
from numbers import Integral, Real
from typing import Any

import numpy as np

from mappers.calibrated import dense_keywords, fold_score, log_floor
from mappers.catalog import resolve_method
from mappers.core.align import apply_affine, check_anchor_ids, check_anchors
from mappers.core.errors import MappingError
from mappers.core.graph import informative_pairs, knn_mask
from mappers.core.sensors import COLUMNS_PER_STEP, check_sensor, check_values, infer_sensor
from mappers.fitting import Map, _thread_limit
from mappers.online.bearing import OnlineBundle
from mappers.online.cal_sma import _OnlineCalSMA, gram_dissimilarity
from mappers.online.view_cone import OnlineView
from mappers.pipeline import _fit_map, build_map

__all__ = ["OnlineMapper"]

_INCREMENTAL = "CAL-SMA"
_BUNDLE = "BEARING-BA"  # updated incrementally from the incremental CAL-SMA map (online_bearing)
_VIEW = "VIEW-BA"  # masked visibility, updated incrementally between its refits (online_view)
_REFIT_GROWTH = 4.0  # refit_growth's default
# ... for VIEW-BA: its refits, from a new start map, are what find a better basin (chosen on the
# tuning seeds: docs/online-and-exploration.md, "With the start's disagreement check")
_VIEW_REFIT_GROWTH = 1.25
# a warm map that looks folded is refitted from scratch once the steps have grown by this factor
# since the last full fit (at most refit_growth), not at every update while it still looks folded
_FOLD_REFIT_GROWTH = 1.5
# a refitted method that found nothing to map yet is tried again once the steps have grown by this
_RETRY_GROWTH = 1.1
# Guttman updates per round in a full CAL-SMA fit (CAL-SMA's own max_iter is 100): the young
# maps' slow fits hit the cap, later fits converge before it (measured:
# docs/online-and-exploration.md#online-mapper-the-cost-of-an-update-issue-14)
_FULL_FIT_MAX_ITER = 30


class OnlineMapper:
    """The map of M objects, updated as batches of steps arrive (see the module docstring).

    Args:
        anchor_ids: (A,) ids of the anchor objects, A >= 3 (checked against M at the first
            update).
        anchor_positions: (A, 2) their known positions [m]; not collinear.
        sensor: ``"visibility"``, ``"bearing"`` or ``"range"``; None = inferred from the first
            update that senses anything (pass it when you know it).
        method: a label of :data:`mappers.METHODS`; None = ``build_map``'s default for the
            sensor and the kind of history. CAL-SMA on complete visibility and bearing
            histories, BEARING-BA (started from CAL-SMA) on complete bearing ones, and VIEW-BA
            on masked visibility ones (between its refits) are updated incrementally; other
            methods are refitted on the schedule.
        refit_growth: a full refit whenever the steps have grown by this factor (> 1) since the
            last scheduled one; None: 4, or 1.25 for VIEW-BA (masked visibility).
        warm_rounds: CAL-SMA rounds of the warm-started update between full refits.
        warm_tol: relative stress decrease at which a warm round's Guttman updates stop, in
            [0, 1) (CAL-SMA's own ``tol`` is 1e-6; from a nearly converged start 1e-4 halves
            the updates and leaves the maps as accurate).
        fold_check_every: CAL-SMA's fold check on every this many warm updates (integer >= 1;
            1 = every update) once the map is past its second scheduled refit (``refit_growth``
            squared times the steps of the first map); before that, and whenever objects join
            the map, on every warm update.
        bundle_every: BEARING-BA (complete bearing) and VIEW-BA (masked visibility): a warm
            joint round of the bundle adjustment every this many updates (integer >= 1), sooner
            once the steps have grown by 5 % since the last.
        bundle_rounds: Levenberg-Marquardt rounds per warm joint round (integer >= 1).
        random_state: seed handed to the method, as ``build_map``'s.
        **params: the method's parameters, as for ``build_map``.

    Attributes:
        n_steps: steps received so far; n_full_fits: full refits so far (the scheduled ones and
        those a fold check asked for); n_fold_refits: those a fold check asked for; map: the
        last map (None before the first update).

    What an update costs: ``docs/online-and-exploration.md#onlinemapper-cost-per-update``.
    """

    def __init__(self, anchor_ids, anchor_positions, *, sensor: str | None = None,
                 method: str | None = None, refit_growth: float | None = None,
                 warm_rounds: int = 1,
                 warm_tol: float = 1e-4, fold_check_every: int = 5, bundle_every: int = 5,
                 bundle_rounds: int = 1, random_state: int | None = 0, **params: Any) -> None:
        pos = np.asarray(anchor_positions, dtype=float)
        ids = check_anchor_ids(anchor_ids, np.iinfo(np.int64).max)
        check_anchors(ids, pos, int(ids.max()) + 1)  # shapes, finiteness, collinearity
        if refit_growth is not None and (isinstance(refit_growth, bool)
                                         or not isinstance(refit_growth, Real)
                                         or not refit_growth > 1):
            raise ValueError(f"refit_growth must be a number > 1 or None, got {refit_growth!r}")
        if isinstance(warm_rounds, bool) or not isinstance(warm_rounds, Integral) or warm_rounds < 1:
            raise ValueError(f"warm_rounds must be an integer >= 1, got {warm_rounds!r}")
        if isinstance(warm_tol, bool) or not isinstance(warm_tol, Real) or not 0 <= warm_tol < 1:
            raise ValueError(f"warm_tol must be a number in [0, 1), got {warm_tol!r}")
        if (isinstance(fold_check_every, bool) or not isinstance(fold_check_every, Integral)
                or fold_check_every < 1):
            raise ValueError(f"fold_check_every must be an integer >= 1, got {fold_check_every!r}")
        for name, value in (("bundle_every", bundle_every), ("bundle_rounds", bundle_rounds)):
            if isinstance(value, bool) or not isinstance(value, Integral) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        self.anchor_ids, self.anchor_positions = ids, pos
        self.sensor = check_sensor(sensor, allow_none=True)
        self.method, self.params = method, dict(params)
        self._refit_growth = refit_growth  # None: the method's (set when it is resolved)
        self.refit_growth = _REFIT_GROWTH if refit_growth is None else float(refit_growth)
        self.warm_rounds = int(warm_rounds)
        self.warm_tol, self.fold_check_every = float(warm_tol), int(fold_check_every)
        self.bundle_every, self.bundle_rounds = int(bundle_every), int(bundle_rounds)
        self.random_state = random_state
        self.n_steps, self.n_full_fits, self.map = 0, 0, None
        self._m: int | None = None
        self._masked: bool | None = None
        self._spec = None
        self._gram: np.ndarray | None = None
        self._n_columns = 0
        self._blocks: list[tuple[np.ndarray, np.ndarray | None]] = []
        self._last_full = 0  # steps at the last full fit
        self._last_scheduled = 0  # ... at the last one of the schedule (not a fold check's)
        self._first_map: int | None = None  # steps of the first map
        self._fit_notes: tuple[str, ...] = ()
        self._Y: np.ndarray | None = None  # last embedding (M, 2), NaN rows for unmapped
        self._retry_at = 0  # steps at which a first map that failed is tried again
        self._warm_est: _OnlineCalSMA | None = None  # keeps the last Guttman pseudo-inverse
        self._since_check, self._m_checked = 0, 0  # warm updates since the last fold check
        self.n_fold_refits = 0
        self._bundle: OnlineBundle | None = None  # BEARING-BA's state (complete bearing)
        self._view: OnlineView | None = None  # VIEW-BA's state (masked visibility)
        self._cal: dict = {}  # CAL-SMA's parameters (the method's, or BEARING-BA's start's)

    # ------------------------------------------------------------------ inputs
    def _check_batch(self, columns, mask):
        try:
            C = np.array(columns, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"columns must be a numeric (M, k) array: {exc}") from exc
        if C.ndim != 2 or C.shape[1] < 1:
            raise ValueError(f"columns must be a 2-D (objects x new columns) array with at least "
                             f"one column, got shape {C.shape}")
        if self._m is None:
            if C.shape[0] < 3:
                raise ValueError(f"columns need at least 3 objects (rows), got {C.shape[0]}")
            check_anchor_ids(self.anchor_ids, C.shape[0])
        elif C.shape[0] != self._m:
            raise ValueError(f"columns must have {self._m} rows (one per object, as in the first "
                             f"update), got {C.shape[0]}")
        if mask is not None:
            mask = np.asarray(mask)
            if mask.dtype != bool or mask.shape != C.shape:
                raise ValueError(f"mask must be a boolean array of the columns' shape {C.shape}, "
                                 f"got {mask.dtype} {mask.shape}")
        if not np.all(np.isfinite(C if mask is None else C[mask])):
            raise ValueError("columns contain NaN or inf (in observed entries)")
        if mask is not None:
            C = np.where(mask, C, 0.0)
        if self.sensor is not None and C.shape[1] % COLUMNS_PER_STEP[self.sensor]:
            raise ValueError(f"{self.sensor} columns come in groups of "
                             f"{COLUMNS_PER_STEP[self.sensor]} per step, got {C.shape[1]} columns")
        return C, mask

    def _kind(self, mask) -> bool:
        """Fix the kind of history at the first update; later masks must agree."""
        masked = mask is not None and not mask.all()
        if self._masked is None:
            self._masked = mask is not None
        elif masked and not self._masked:
            raise ValueError("mask given after a first update without one: the kind of history "
                             "(complete or masked) is fixed by the first update; pass a mask "
                             "(all True where complete) from the first update on")
        return self._masked

    def _resolve(self) -> None:
        """Choose the method once the sensor is known; replay the batches held until then."""
        spec = resolve_method(self.method, self.sensor, masked=self._masked)
        self._merged = spec.resolved_params(self.params)
        if "random_state" in spec.parameters and "random_state" not in self.params:
            self._merged["random_state"] = self.random_state
        self._spec = spec
        self._cal = self._merged
        start = self._merged.get("start")
        if (spec.label == _BUNDLE and self.sensor == "bearing" and not self._masked
                and (start is None or start.strip().upper() == _INCREMENTAL)):
            cal = resolve_method(_INCREMENTAL, self.sensor)
            self._cal = cal.resolved_params({})
            if "random_state" in cal.parameters:
                self._cal["random_state"] = self._merged.get("random_state", self.random_state)
            self._bundle = OnlineBundle(self._merged, self.anchor_ids, self.anchor_positions,
                                        every=self.bundle_every, rounds=self.bundle_rounds)
        if spec.label == _VIEW and self._masked:
            self._view = OnlineView(every=self.bundle_every, rounds=self.bundle_rounds)
            if self._refit_growth is None:
                self.refit_growth = _VIEW_REFIT_GROWTH
        blocks, self._blocks = self._blocks, []
        self.n_steps = 0
        for C, mask in blocks:
            if C.shape[1] % COLUMNS_PER_STEP[self.sensor]:
                raise ValueError(f"{self.sensor} columns come in groups of "
                                 f"{COLUMNS_PER_STEP[self.sensor]} per step, got {C.shape[1]}")
            self._add(C, mask)

    @property
    def incremental(self) -> bool:
        """Whether updates are incremental (CAL-SMA on complete histories, BEARING-BA from it on
        complete bearing ones, VIEW-BA between its refits on masked visibility ones) rather
        than refits."""
        return self._gram_path or self._view is not None

    @property
    def _gram_path(self) -> bool:
        """CAL-SMA's statistics kept as a Gram matrix (complete histories)."""
        return self._spec is not None and not self._masked and (
            (self._spec.label == _INCREMENTAL and not self._spec.is_scalable(self._merged))
            or self._bundle is not None)

    def _add(self, C, mask) -> None:
        if self._view is not None:  # new viewpoints placed against the current objects
            self._view.add(C, np.ones(C.shape, dtype=bool) if mask is None else mask)
        if self._gram_path:
            if self._bundle is not None:  # checked before anything is kept
                theta, seen = self._bundle.angles(C)
                self._bundle.add(C, theta, seen)
            G = C @ C.T
            self._gram = G if self._gram is None else self._gram + G
            self._n_columns += C.shape[1]
        else:
            self._blocks.append((C, mask))
        self.n_steps += C.shape[1] // COLUMNS_PER_STEP[self.sensor]

    # ------------------------------------------------------------------ API
    def update(self, columns, mask=None) -> Map:
        """Add the new steps' columns (M, k) (and their (M, k) bool mask, True = observed) and
        return the current map.

        ``k`` is a whole number of steps (``COLUMNS_PER_STEP[sensor]`` columns each), in step
        order, as in a history's matrix. Until three anchors and three objects have been sensed
        (or the method finds nothing to map yet) the map has every object unmapped, with a note
        in ``warnings``.
        """
        C, mask = self._check_batch(columns, mask)
        if self.sensor is not None:
            check_values(C, mask, self.sensor)  # e.g. no negative range
        self._kind(mask)
        self._m = C.shape[0]
        if self._spec is None:
            if self.sensor is None and np.any(C != 0):
                self.sensor = infer_sensor(C, mask)
            if self.sensor is None:  # nothing sensed yet: hold the batch until the sensor is known
                self._blocks.append((C, mask))
                self.map = self._empty("nothing sensed yet")
                return self.map
            self._blocks.append((C, mask))
            self._resolve()
        else:
            self._add(C, mask)
        full = (self.n_steps >= self._retry_at if self._Y is None
                else self.n_steps >= self.refit_growth * self._last_scheduled)
        fits = self.n_full_fits
        self.map = self._update_incremental(full) if self._gram_path else self._update_refit(full)
        if self._bundle is not None:
            self.map = self._update_bundle(self.map, self.n_full_fits > fits)
        return self.map

    def _empty(self, why: str) -> Map:
        m = self._m
        label = self._spec.label if self._spec is not None else str(self.method)
        return Map(positions=np.full((m, 2), np.nan), unmapped=tuple(range(m)),
                   embedding=np.full((m, 2), np.nan), method=label,
                   params=dict(getattr(self, "_merged", self.params)),
                   sensor=self.sensor or "unknown",
                   warnings=(f"online map after {self.n_steps} steps: {why}",))

    # ------------------------------------------------------------------ updates
    def _usable(self, has_data: np.ndarray):
        """Mapped rows and the anchors among them, or the reason there is no map yet."""
        mapped = np.flatnonzero(has_data)
        ok = has_data[self.anchor_ids]
        if ok.sum() < 3 or mapped.size < 3:
            return None, f"{int(ok.sum())} anchors and {mapped.size} objects sensed so far"
        return mapped, None

    def _estimator(self, k: int, *, warm: bool) -> _OnlineCalSMA:
        """CAL-SMA with the method's parameters: a full fit (no random restarts: a map that
        still looks folded is refitted later, with more steps; at most ``_FULL_FIT_MAX_ITER``
        Guttman updates per round), or ``warm_rounds`` rounds whose Guttman updates stop at
        ``warm_tol``."""
        kw = dense_keywords(self._cal)
        kw.pop("n_neighbors", None)
        if warm:
            kw.update(n_rounds=self.warm_rounds, tol=self.warm_tol)
        else:
            kw["max_iter"] = _FULL_FIT_MAX_ITER  # (not one of CAL-SMA's registry parameters)
        return _OnlineCalSMA(dissimilarity="precomputed", n_neighbors=k, n_init=0, **kw)

    def _start(self, mapped: np.ndarray, D: np.ndarray) -> np.ndarray:
        """The last map for objects it had; a new object at the mean of its three most similar
        mapped objects (a small offset keeps two newcomers apart)."""
        S = self._Y[mapped].copy()
        old = np.isfinite(S[:, 0])
        for r in np.flatnonzero(~old):
            near = np.flatnonzero(old)[np.argsort(D[r, old], kind="stable")[:3]]
            S[r] = S[near].mean(axis=0) + 1e-3 * (r + 1) * np.array([1.0, -1.0])
        return S

    def _update_incremental(self, full: bool) -> Map:
        G = self._gram
        mapped, why = self._usable(np.diag(G) > 0)
        if mapped is None:
            return self._empty(why)
        m = mapped.size
        kind = "cosine" if self.sensor == "visibility" and self._n_columns >= 2 else "euclidean"
        D = gram_dissimilarity(G[np.ix_(mapped, mapped)], self._n_columns, kind)
        valid = informative_pairs(D)
        if not valid.any():  # CAL-SMA's own condition: nothing to calibrate
            return self._empty("no two objects sensed together yet")
        if not full and np.isnan(self._Y[mapped]).all():
            full = True
        scheduled = full
        is_anchor = np.isin(self.anchor_ids, mapped)
        local = np.searchsorted(mapped, self.anchor_ids[is_anchor])
        pos = self.anchor_positions[is_anchor]
        k = self._cal.get("n_neighbors")
        k = (12 if kind == "cosine" else 10) if k is None else k
        notes = []
        with _thread_limit(m):
            if not full:
                Y, score = self._warm(D, valid, mapped, local, pos, kind, min(k, m - 1))
                if score is not None:  # the warm map looks folded
                    next_fit = min(_FOLD_REFIT_GROWTH, self.refit_growth) * self._last_full
                    if self.n_steps >= next_fit:  # refit from CAL-SMA's deterministic starts
                        full, self.n_fold_refits = True, self.n_fold_refits + 1
                    else:
                        notes.append(f"online map looks folded (fold score {score:.3f}); refit "
                                     f"from scratch at {int(np.ceil(next_fit))} steps")
            if full:
                est = self._estimator(min(k, m - 1), warm=False)
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    Y = est.fit_transform(D, anchor_ids=local, anchor_positions=pos)
                notes = list(dict.fromkeys(f"{_INCREMENTAL}: {w.category.__name__}: {w.message}"
                                           for w in caught))
                self._last_full, self.n_full_fits = self.n_steps, self.n_full_fits + 1
                if scheduled:  # a fold check's refit leaves the schedule where it was
                    self._last_scheduled = self.n_steps
                    if self._first_map is None:
                        self._first_map = self.n_steps
                self._since_check, self._m_checked = 0, m
        if k > m - 1:
            notes.append(f"n_neighbors {k} > {m - 1} objects mapped so far: used {m - 1}")
        self._Y = np.full((self._m, 2), np.nan)
        self._Y[mapped] = Y
        return self._map(Y, mapped, local, pos, {**self._cal, "n_neighbors": k}, notes)

    def _update_bundle(self, start: Map, refitted: bool) -> Map:
        """BEARING-BA from the CAL-SMA map ``start``: a full fit when CAL-SMA was refitted (or
        objects joined its map), else the new steps' poses (resected in :meth:`_add`) and, when
        due, a warm joint round; the CAL-SMA map, with the refit's warning, where the refinement
        was not kept."""
        bundle = self._bundle
        placed = np.isfinite(start.positions[:, 0])
        if not placed.any():
            return start
        cal_notes = [f"start map ({_INCREMENTAL}): {w}" for w in start.warnings]
        joined = bundle.start_placed is None or np.any(placed & ~bundle.start_placed)
        with _thread_limit(self._m):
            if refitted or joined:
                bundle.refit(start.positions)
            elif bundle.due():
                bundle.joint_round()
        if bundle.state is None:  # the refinement was not kept: the CAL-SMA map
            return dataclasses.replace(start, method=self._spec.label, params=dict(self._merged),
                                       warnings=(*cal_notes, *bundle.notes))
        return self._adjusted_map(bundle.positions(), np.flatnonzero(placed),
                                  [*cal_notes, *bundle.notes])

    def _adjusted_map(self, positions: np.ndarray, mapped: np.ndarray, notes: list) -> Map:
        """The Map of a viewpoint adjustment's objects ``positions`` (M, 2) on the rows
        ``mapped`` (the anchors held at their positions)."""
        is_anchor = np.isin(self.anchor_ids, mapped)
        local = np.searchsorted(mapped, self.anchor_ids[is_anchor])
        return self._map(positions[mapped], mapped, local, self.anchor_positions[is_anchor],
                         dict(self._merged), notes)

    def _warm(self, D, valid, mapped, local, pos, kind, k) -> tuple[np.ndarray, float | None]:
        """``warm_rounds`` CAL-SMA rounds from the last map, and its fold score if CAL-SMA's
        fold check (run on every warm update of a young map, then every ``fold_check_every``,
        and whenever objects joined the map) finds it folded, else None."""
        if self._warm_est is None:
            self._warm_est = self._estimator(k, warm=True)
        est, m = self._warm_est, len(D)
        loc = knn_mask(D, valid, k)
        S = self._start(mapped, D)
        S[local] = pos
        Y, _, _, _, Dh = est._refine(D, S, loc, local)
        self._since_check += 1
        # a young map (before the second scheduled refit) is checked at every update: early maps
        # are the ones that fold
        young = self.n_steps < self.refit_growth**2 * self._first_map
        if self._since_check < self.fold_check_every and m == self._m_checked and not young:
            return Y, None
        self._since_check, self._m_checked = 0, m
        # as CAL-SMA's fit: never through a smaller neighbourhood than the default one
        k_check = min(max(k, 12 if kind == "cosine" else 10), m - 1)
        if k_check != k:
            loc_check = knn_mask(D, valid, k_check)
            Dh, _ = est._calibrate(D, Y, loc_check, log_floor(D[loc_check]))
        score = fold_score(Y, D, k_check, Dh)
        return Y, (score if score > est.fold_threshold else None)

    def _map(self, Y, mapped, local, pos, params, notes) -> Map:
        # CAL-SMA held the anchors fixed: the least-squares affine fit (the identity, to
        # rounding) needs no collinearity check, the anchors' known positions passed one
        T = np.linalg.lstsq(np.column_stack([Y[local], np.ones(len(local))]), pos, rcond=None)[0]
        positions = np.full((self._m, 2), np.nan)
        embedding = np.full((self._m, 2), np.nan)
        embedding[mapped] = Y
        positions[mapped] = apply_affine(Y, T)
        is_mapped = np.zeros(self._m, dtype=bool)
        is_mapped[mapped] = True
        unmapped = tuple(int(i) for i in np.flatnonzero(~is_mapped))
        lost = self.anchor_ids[~is_mapped[self.anchor_ids]]
        if lost.size:
            notes.append(f"anchors {lost.tolist()} have empty histories and were not used for the fit")
        return Map(positions=positions, unmapped=unmapped, embedding=embedding,
                   method=self._spec.label, params=params, sensor=self.sensor,
                   warnings=tuple(notes), affine=T,
                   anchor_ids=tuple(int(i) for i in self.anchor_ids[np.isin(self.anchor_ids, mapped)]))

    def _update_refit(self, full: bool) -> Map:
        scheduled, view = full, self._view
        if not full and view is not None and view.state is not None:
            if not view.joined():  # VIEW-BA's state carried on: the new steps are placed
                return self._update_view()
            full = True  # an object seen for the first time has no place: refit
        if not full and self._Y is None:  # the first map failed: tried again at _retry_at
            return self.map
        if not full:
            stale = f"online map of the first {self._last_full} of {self.n_steps} steps " \
                    f"(next refit at {int(np.ceil(self.refit_growth * self._last_scheduled))})"
            return dataclasses.replace(self.map, warnings=(*self._fit_notes, stale))
        X, mask = self._history()
        seen = np.any((X != 0) if mask is None else (mask & (X != 0)), axis=1)
        mapped, why = self._usable(seen)
        k = self._merged.get("n_neighbors")
        if mapped is None or (isinstance(k, Integral) and k >= mapped.size):
            return self._empty(why or f"n_neighbors {k} needs more than {mapped.size} objects")
        try:
            if view is None:
                result = build_map(X, self.anchor_ids, self.anchor_positions, self._spec.label,
                                   sensor=self.sensor, mask=mask, **self._merged)
            else:  # build_map's own fit, whose estimator holds VIEW-BA's state
                params = dict(self._merged)
                seed = params.pop("random_state", self.random_state)
                with _thread_limit(self._m):
                    result, est, rows = _fit_map(X, self.anchor_ids, self.anchor_positions,
                                                 self._spec.label, self.sensor, mask, None, None,
                                                 seed, params)
                    view.start(est, X, np.ones(X.shape, bool) if mask is None else mask, rows,
                               np.asarray(result.anchor_ids))
        except MappingError as exc:
            if view is not None:  # no refit, no state: the last map until the next refit
                view.state = None
            if self.map is None or not np.isfinite(self.map.positions).any():
                # tried again once the steps have grown a little (a try may cost as much as a fit)
                self._retry_at = int(np.ceil(_RETRY_GROWTH * self.n_steps))
                return self._empty(f"the method found nothing to map yet ({exc}); tried again "
                                   f"at {self._retry_at} steps")
            return dataclasses.replace(self.map, warnings=(
                *self.map.warnings, f"refit at {self.n_steps} steps failed, map kept: {exc}"))
        self._last_full = self.n_steps
        if scheduled:  # a refit for objects that joined leaves the schedule where it was
            self._last_scheduled = self.n_steps
        self.n_full_fits += 1
        self._Y = result.embedding
        self._fit_notes = result.warnings
        return result

    def _history(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The whole history kept so far, ``(X, mask)`` (mask None: complete), as one block (the
        next refit concatenates less)."""
        X = np.concatenate([C for C, _ in self._blocks], axis=1)
        if len(self._blocks) > 1:
            mask = None
            if self._masked:  # a batch given without a mask observed everything
                mask = np.concatenate([np.ones(C.shape, bool) if mk is None else mk
                                       for C, mk in self._blocks], axis=1)
            self._blocks = [(X, mask)]
        return self._blocks[0]

    def _update_view(self) -> Map:
        """VIEW-BA's map carried on from its last refit: a warm joint round when due."""
        view = self._view
        note = None
        if view.refine_due():
            X, mask = self._history()
            with _thread_limit(self._m):
                self._fit_notes = view.refine(X, mask, self.anchor_ids, self.anchor_positions)
        elif view.due():
            with _thread_limit(self._m):
                note = view.joint_round()
        if note is not None:
            self._fit_notes = (*self._fit_notes, note)
        if view.state is None:
            return self._update_refit(False)
        P = view.positions(self._m)
        return self._adjusted_map(P, np.flatnonzero(np.isfinite(P[:, 0])), list(self._fit_notes))
