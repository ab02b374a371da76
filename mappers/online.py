"""Online mapping: the map of a robot still moving, updated as its histories grow.

The paper calls LFMDR "basically an off-line process" and leaves an online algorithm open (§6).
:class:`OnlineMapper` takes the new steps' columns after each batch of steps and returns the
current :class:`~mappers.pipeline.Map`, the same kind of map :func:`~mappers.pipeline.build_map`
returns for the whole history.

For the default method of complete visibility and bearing histories, CAL-SMA
(:mod:`mappers.calibrated`; ``build_map``'s complete bearing default is BEARING-BA, which the
online mapper does not use unless named), the update is incremental:

- Statistics: CAL-SMA needs only the dissimilarities of the L2-normalised rows (paper eq. 7),
  and both its cosine (visibility) and RMS Euclidean (bearing) dissimilarities are functions of
  the Gram matrix ``G = X X^T`` and the column count. ``G`` is accumulated as ``C C^T`` over the
  new columns ``C``: O(M^2 k) for k new columns, never a pass over the whole history, and no
  column is kept.
- Embedding: the last map is the start of a short CAL-SMA refinement (``warm_rounds``
  calibrate/re-embed rounds, anchors held fixed); objects sensed for the first time start at the
  mean position of their three most similar mapped objects. CAL-SMA's fold guard still runs: a
  warm map that looks folded is refitted from its deterministic starts.
- Full refits: from scratch (CAL-SMA's two deterministic starts and all its rounds) whenever the
  number of steps has grown by the factor ``refit_growth`` since the last full fit, so a map
  whose early shape was poor is rebuilt a logarithmic number of times in all.

Cost per update, with M objects: O(M^2 k) for the statistics plus O(M^2 log M) for the
neighbours plus ``warm_rounds`` rounds of anchored weighted SMACOF (O(M^2) per Guttman update,
a few updates per round), independent of the number of steps so far. A full refit costs what
``build_map`` costs (``2 x n_rounds`` rounds); with ``refit_growth = g`` there are about
``log_g(N / N_0)`` of them over a run of N steps, N_0 the steps of the first map. ``benchmarks/bench_online.py`` measures both
against rebuilding the map.

Other methods (and masked histories, whose methods need the steps' co-observation patterns)
keep the columns and refit with :func:`~mappers.pipeline.build_map` on the same geometric
schedule; between refits the last map is returned with a note in ``Map.warnings`` saying which
steps it covers.

References: de Leeuw (1977) and Borg & Groenen, *Modern Multidimensional Scaling* (2005), on
warm-started SMACOF (majorisation decreases stress from any start).
"""

from __future__ import annotations

import dataclasses
import warnings
from numbers import Integral, Real
from typing import Any

import numpy as np

from mappers.align import apply_affine, check_anchor_ids, check_anchors
from mappers.graph import informative_pairs
from mappers.pipeline import Map, _thread_limit, build_map
from mappers.registry import MappingError, resolve_method
from mappers.sensors import COLUMNS_PER_STEP, check_sensor, infer_sensor

__all__ = ["OnlineMapper", "gram_dissimilarity", "online_default"]

_INCREMENTAL = "CAL-SMA"


def online_default(sensor: str, masked: bool) -> str | None:
    """The label :class:`OnlineMapper` uses when none is given, None where it is ``build_map``'s
    default: CAL-SMA (updated incrementally) for complete bearing histories, whose ``build_map``
    default BEARING-BA refits from the whole history."""
    return _INCREMENTAL if sensor == "bearing" and not masked else None


def gram_dissimilarity(gram: np.ndarray, n_columns: int, kind: str) -> np.ndarray:
    """CAL-SMA's dissimilarity of the L2-normalised history rows, from their Gram matrix.

    ``gram`` is ``X X^T`` of the raw rows (no empty row), ``n_columns`` the columns of ``X``.
    ``kind`` ``"cosine"`` gives ``1 - cos``; ``"euclidean"`` gives ``||y_i - y_j|| / sqrt(D)``
    of the unit rows ``y``: the values :func:`mappers.calibrated.history_dissimilarity` gives.
    """
    norms = np.sqrt(np.diag(gram))
    cos = np.clip(gram / np.outer(norms, norms), -1.0, 1.0)
    if kind == "cosine":
        delta = 1.0 - cos
    elif kind == "euclidean":
        delta = np.sqrt(np.maximum(2.0 - 2.0 * cos, 0.0) / n_columns)
    else:
        raise ValueError(f"kind must be 'cosine' or 'euclidean', got {kind!r}")
    delta = 0.5 * (delta + delta.T)
    np.fill_diagonal(delta, 0.0)
    return np.maximum(delta, 0.0)


class OnlineMapper:
    """The map of M objects, updated as batches of steps arrive (see the module docstring).

    Args:
        anchor_ids: (A,) ids of the anchor objects, A >= 3 (checked against M at the first
            update).
        anchor_positions: (A, 2) their known positions [m]; not collinear.
        sensor: ``"visibility"``, ``"bearing"`` or ``"range"``; None = inferred from the first
            update that senses anything (pass it when you know it).
        method: a label of :data:`mappers.METHODS`; None = ``build_map``'s default for the
            sensor and the kind of history, except CAL-SMA for complete bearing histories
            (``build_map``'s BEARING-BA needs the whole history at every refit): CAL-SMA, for
            complete visibility and bearing, is updated incrementally.
        refit_growth: a full refit whenever the steps have grown by this factor (> 1) since the
            last one.
        warm_rounds: CAL-SMA rounds of the warm-started update between full refits.
        random_state: seed handed to the method, as ``build_map``'s.
        **params: the method's parameters, as for ``build_map``.

    Attributes:
        n_steps: steps received so far; n_full_fits: full refits so far; map: the last map
        (None before the first update).
    """

    def __init__(self, anchor_ids, anchor_positions, *, sensor: str | None = None,
                 method: str | None = None, refit_growth: float = 4.0, warm_rounds: int = 1,
                 random_state: int | None = 0, **params: Any) -> None:
        pos = np.asarray(anchor_positions, dtype=float)
        ids = check_anchor_ids(anchor_ids, np.iinfo(np.int64).max)
        check_anchors(ids, pos, int(ids.max()) + 1)  # shapes, finiteness, collinearity
        if isinstance(refit_growth, bool) or not isinstance(refit_growth, Real) or not refit_growth > 1:
            raise ValueError(f"refit_growth must be a number > 1, got {refit_growth!r}")
        if isinstance(warm_rounds, bool) or not isinstance(warm_rounds, Integral) or warm_rounds < 1:
            raise ValueError(f"warm_rounds must be an integer >= 1, got {warm_rounds!r}")
        self.anchor_ids, self.anchor_positions = ids, pos
        self.sensor = check_sensor(sensor, allow_none=True)
        self.method, self.params = method, dict(params)
        self.refit_growth, self.warm_rounds = float(refit_growth), int(warm_rounds)
        self.random_state = random_state
        self.n_steps, self.n_full_fits, self.map = 0, 0, None
        self._m: int | None = None
        self._masked: bool | None = None
        self._spec = None
        self._gram: np.ndarray | None = None
        self._n_columns = 0
        self._blocks: list[tuple[np.ndarray, np.ndarray | None]] = []
        self._last_full = 0
        self._fit_notes: tuple[str, ...] = ()
        self._Y: np.ndarray | None = None  # last embedding (M, 2), NaN rows for unmapped

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
        spec = resolve_method(self.method or online_default(self.sensor, bool(self._masked)),
                              self.sensor, masked=self._masked)
        self._merged = spec.resolved_params(self.params)
        if "random_state" in spec.parameters and "random_state" not in self.params:
            self._merged["random_state"] = self.random_state
        self._spec = spec
        blocks, self._blocks = self._blocks, []
        self.n_steps = 0
        for C, mask in blocks:
            if C.shape[1] % COLUMNS_PER_STEP[self.sensor]:
                raise ValueError(f"{self.sensor} columns come in groups of "
                                 f"{COLUMNS_PER_STEP[self.sensor]} per step, got {C.shape[1]}")
            self._add(C, mask)

    @property
    def incremental(self) -> bool:
        """Whether updates are incremental (CAL-SMA on complete histories) rather than refits."""
        return self._spec is not None and self._spec.label == _INCREMENTAL and not self._masked

    def _add(self, C, mask) -> None:
        if self.incremental:
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
        full = self._Y is None or self.n_steps >= self.refit_growth * self._last_full
        self.map = self._update_incremental(full) if self.incremental else self._update_refit(full)
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

    def _estimator(self, kind: str, m: int, init):
        from mappers.calibrated import CalibratedSMACOF

        kw = dict(self._merged)
        k = kw.pop("n_neighbors", None)
        k = (12 if kind == "cosine" else 10) if k is None else k
        if init is not None:
            kw["n_rounds"] = self.warm_rounds
        return CalibratedSMACOF(dissimilarity="precomputed", n_neighbors=min(k, m - 1), init=init,
                                **kw), k

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
        if not informative_pairs(D).any():  # CAL-SMA's own condition: nothing to calibrate
            return self._empty("no two objects sensed together yet")
        if not full and np.isnan(self._Y[mapped]).all():
            full = True
        est, k = self._estimator(kind, m, None if full else self._start(mapped, D))
        local = np.searchsorted(mapped, self.anchor_ids[np.isin(self.anchor_ids, mapped)])
        pos = self.anchor_positions[np.isin(self.anchor_ids, mapped)]
        with warnings.catch_warnings(record=True) as caught, _thread_limit(m):
            warnings.simplefilter("always")
            Y = est.fit_transform(D, anchor_ids=local, anchor_positions=pos)
        notes = list(dict.fromkeys(f"{_INCREMENTAL}: {w.category.__name__}: {w.message}"
                                   for w in caught))
        if k > m - 1:
            notes.append(f"n_neighbors {k} > {m - 1} objects mapped so far: used {m - 1}")
        if full:
            self._last_full, self.n_full_fits = self.n_steps, self.n_full_fits + 1
        self._Y = np.full((self._m, 2), np.nan)
        self._Y[mapped] = Y
        return self._map(Y, mapped, local, pos, {**self._merged, "n_neighbors": k}, notes)

    def _map(self, Y, mapped, local, pos, params, notes) -> Map:
        # CAL-SMA held the anchors fixed: the least-squares affine fit (the identity, to
        # rounding) needs no collinearity check, the anchors' known positions passed one
        T = np.linalg.lstsq(np.column_stack([Y[local], np.ones(len(local))]), pos, rcond=None)[0]
        positions = np.full((self._m, 2), np.nan)
        embedding = np.full((self._m, 2), np.nan)
        embedding[mapped] = Y
        positions[mapped] = apply_affine(Y, T)
        unmapped = tuple(int(i) for i in np.setdiff1d(np.arange(self._m), mapped))
        lost = np.setdiff1d(self.anchor_ids, mapped)
        if lost.size:
            notes.append(f"anchors {lost.tolist()} have empty histories and were not used for the fit")
        return Map(positions=positions, unmapped=unmapped, embedding=embedding,
                   method=self._spec.label, params=params, sensor=self.sensor,
                   warnings=tuple(notes), affine=T,
                   anchor_ids=tuple(int(i) for i in self.anchor_ids[np.isin(self.anchor_ids, mapped)]))

    def _update_refit(self, full: bool) -> Map:
        if not full:
            stale = f"online map of the first {self._last_full} of {self.n_steps} steps " \
                    f"(next refit at {int(np.ceil(self.refit_growth * self._last_full))})"
            return dataclasses.replace(self.map, warnings=(*self._fit_notes, stale))
        X = np.concatenate([C for C, _ in self._blocks], axis=1)
        if len(self._blocks) > 1:  # keep one block: the next refit concatenates less
            mask = None
            if self._masked:
                mask = np.concatenate([np.ones(C.shape, bool) if mk is None else mk
                                       for C, mk in self._blocks], axis=1)
            self._blocks = [(X, mask)]
        mask = self._blocks[0][1]
        seen = np.any((X != 0) if mask is None else (mask & (X != 0)), axis=1)
        mapped, why = self._usable(seen)
        k = self._merged.get("n_neighbors")
        if mapped is None or (isinstance(k, Integral) and k >= mapped.size):
            return self._empty(why or f"n_neighbors {k} needs more than {mapped.size} objects")
        try:
            result = build_map(X, self.anchor_ids, self.anchor_positions, self._spec.label,
                               sensor=self.sensor, mask=mask, **self._merged)
        except MappingError as exc:
            if self.map is None or not np.isfinite(self.map.positions).any():
                return self._empty(f"the method found nothing to map yet ({exc})")
            return dataclasses.replace(self.map, warnings=(
                *self.map.warnings, f"refit at {self.n_steps} steps failed, map kept: {exc}"))
        self._last_full, self.n_full_fits = self.n_steps, self.n_full_fits + 1
        self._Y = result.embedding
        self._fit_notes = result.warnings
        return result
