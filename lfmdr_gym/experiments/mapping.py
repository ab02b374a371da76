"""Single maps as the command line makes them: one episode mapped at its checkpoints
(``lfmdr run``), or one saved history mapped (``lfmdr map``), with their files written."""

from __future__ import annotations

import csv
import os
import warnings
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lfmdr_gym.atomic import atomic_write
from lfmdr_gym.checks import check_int
from lfmdr_gym.experiments.episodes import collect_history
from lfmdr_gym.experiments.params import method_label, param_label, parse_params, user_params
from lfmdr_gym.experiments.protocol import DEFAULT_EVERY
from lfmdr_gym.experiments.scoring import evaluate, map_history, score_map
from lfmdr_gym.experiments.store import ensure_writable_dir
from lfmdr_gym.histories.history import History

__all__ = ["checkpoints_for", "map_history_file", "method_and_params", "run_episode"]


def checkpoints_for(steps: int, every: int | None, sensor: str | None) -> tuple[int, ...]:
    """Checkpoints of a single run: multiples of ``every`` up to ``steps`` (which is always one).

    With ``every`` None the sensor's default interval is used and ``steps`` is appended when it
    is not a multiple; an explicit ``every`` must divide ``steps``.
    """
    check_int("steps", steps, low=1)
    if every is None:
        step = min(DEFAULT_EVERY.get(sensor or "", 200), int(steps))
        points = list(range(step, steps + 1, step))
        if points[-1] != steps:
            points.append(int(steps))
        return tuple(points)
    check_int("every", every, low=1)
    if steps % every:
        raise ValueError(f"steps ({steps}) must be a multiple of every ({every})")
    return tuple(range(every, steps + 1, every))


def method_and_params(method: str | None, history: History, params) -> tuple[str, dict[str, Any]]:
    """The registered label that maps ``history`` (None: the default ``build_map`` chooses for
    it, :func:`mappers.default_method`: by sensor, mask, size and dropouts) and its parameters
    (with those the choice or an old label stands for, e.g. ``sparse=True`` for
    ``CAL-SMA-SPARSE``)."""
    from mappers import default_method, resolve_method
    from mappers.catalog import implied_params

    if history.dimension == 3:  # the 3-D methods are chosen by the anchors' shape, not catalogued
        return _method_and_params_3d(method, history, params)
    if method is None:
        label, implied = default_method(history, return_params=True)
    else:
        spec = resolve_method(method, history.sensor, masked=history.mask is not None)
        label, implied = spec.label, implied_params(spec)
    return label, {**implied, **user_params(label, params)}


def _method_and_params_3d(method: str | None, history: History, params) -> tuple[str, dict[str, Any]]:
    """:func:`method_and_params` of a 3-D history: ``SPATIAL-BA`` or ``COVIS-3D`` and the
    parameters given (checked against the estimator's constructor)."""
    import inspect

    from mappers.spatial.pipeline_3d import METHODS_3D, default_method_3d

    label = default_method_3d(history.sensor) if method is None else method.strip().upper()
    if label not in METHODS_3D:
        raise ValueError(f"method {method!r} does not map in 3-D; 3-D methods: {list(METHODS_3D)}")
    given = dict(params) if isinstance(params, Mapping) else parse_params(params)
    accepted = set(inspect.signature(METHODS_3D[label]).parameters)
    unknown = sorted(set(given) - accepted)
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown} for method {label!r}; it accepts "
                         f"{sorted(accepted)}")
    return label, given


def _sensor_of(env_id: str) -> str:
    from lfmdr_gym import ENV_IDS

    if env_id not in ENV_IDS:
        raise ValueError(f"unknown env id {env_id!r}; the registered LFMDR env ids are "
                         f"{list(ENV_IDS)}")
    return ENV_IDS[env_id]


def run_episode(
    env_id: str,
    steps: int,
    method: str | None = None,
    *,
    seed: int | None = 0,
    every: int | None = None,
    params: Iterable[str] | Mapping[str, Any] | None = None,
    out: str | os.PathLike | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
    policy: str = "random-walk",
) -> list[dict[str, Any]]:
    """One episode driven by the exploration policy named ``policy`` (:data:`lfmdr_gym.POLICIES`),
    mapped with ``method`` (None: the default for its history) at every
    checkpoint; rows of scores per checkpoint (``warnings``: the map's ``Map.warnings``).
    ``env_kwargs``: env keywords such as
    ``{"fov_deg": 90}`` (checked; a sensing limit makes the history masked). With ``out``:
    writes ``history.npz``, ``scores.csv``, ``map.csv`` and ``map.png`` (the map at the last
    checkpoint) there."""
    sensor = _sensor_of(env_id)
    points = checkpoints_for(steps, every, sensor)
    if out is not None:
        out = ensure_writable_dir(out)
    history = collect_history(env_id, steps, seed, env_kwargs=env_kwargs, policy=policy)
    method, params = method_and_params(method, history, params)
    rows, last = [], None
    for n in points:
        result = evaluate(history.head(n), method, params)
        last = result.pop("map")
        rows.append({"n_steps": n, "method": method, "param": param_label(params), **result,
                     "warnings": tuple(last.warnings) if last is not None else ()})
    if out is not None:
        history.save(out / "history.npz")
        _write_csv(out / "scores.csv", rows)
        if last is not None:
            r = rows[-1]
            _write_map(out, last.positions, history,
                       f"{env_id}, {method_label(method, params)}, N={steps}: "
                       f"MPE {r['mpe']:.3f} m, MOE {r['moe']:.2f} %", notes=last.warnings)
    return rows


def map_history_file(
    path: str | os.PathLike,
    method: str | None = None,
    *,
    params: Iterable[str] | Mapping[str, Any] | None = None,
    n_steps: int | None = None,
    out: str | os.PathLike | None = None,
    uncertainty: bool | str = False,
) -> dict[str, Any]:
    """Map a saved history (``method`` None: the default for its sensor and kind); scores when
    its ground truth is known; writes ``map.csv`` + ``map.png``. ``uncertainty``: as
    ``build_map``'s (``map.csv``'s ``cov_*`` columns and ``map.png``'s 95 % ellipses).

    Returns a dict with ``map`` (the ``mappers.Map``), ``history`` and, when every object's true
    position is in the file, ``mpe``, ``moe``, ``mpe_nonanchor``.
    """
    history = History.load(path)
    if n_steps is not None:
        history = history.head(n_steps)
    method, params = method_and_params(method, history, params)
    out = ensure_writable_dir(out if out is not None else Path(path).with_suffix(""))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = map_history(history, method, params, uncertainty=uncertainty)
    info: dict[str, Any] = {"map": result, "history": history, "method": method,
                            "param": param_label(params), "out": out}
    title = f"{Path(path).name}, {method_label(method, params)}, N={history.n_steps}"
    if np.all(np.isfinite(history.object_positions)):
        info.update(score_map(result.positions, result.unmapped, history))
        title += f": MPE {info['mpe']:.3f} m, MOE {info['moe']:.2f} %"
    info["figure"] = _write_map(out, result.positions, history, title, notes=result.warnings,
                                covariances=getattr(result, "covariances", None))
    return info


def _write_csv(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    """Rows as CSV; a tuple of texts (a map's warnings) is one cell, joined by " | "."""
    with atomic_write(path) as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows({k: " | ".join(v) if isinstance(v, tuple) else v for k, v in r.items()}
                         for r in rows)


def _write_map(out: Path, positions: np.ndarray, history: History, title: str,
               notes: Sequence[str] = (), covariances: np.ndarray | None = None) -> Path:
    """``map.csv`` (object, estimate, truth, anchor flag; ``z`` and ``true_z`` too for a 3-D
    map; the ``covariances``' ``cov_*`` columns when given) and ``map.png`` (``notes``, the
    map's warnings, below it; the 95 % ellipses; a 3-D map in three orthographic views);
    returns the figure."""
    import lfmdr_gym.experiments.figures as figures
    from lfmdr_gym.experiments.map_files import covariance_columns

    anchors = {int(i) for i in history.anchor_ids}
    d = np.asarray(positions).shape[1]
    axes, cov = "xyz"[:d], [] if covariances is None else covariance_columns(d)
    with atomic_write(out / "map.csv") as fh:
        writer = csv.writer(fh)
        writer.writerow(["object", *axes, *(f"true_{a}" for a in axes), "anchor",
                         *(name for name, _, _ in cov)])
        for j, (est, tru) in enumerate(zip(positions, history.object_positions, strict=True)):
            writer.writerow([j, *(f"{v:.6g}" for v in est), *(f"{v:.6g}" for v in tru), int(j in anchors),
                             *(f"{covariances[j, a, b]:.6g}" for _, a, b in cov)])
    if d == 3:
        return figures.plot_views_3d(positions, history.object_positions, history.anchor_ids,
                                     out / "map.png", title=title, notes=notes,
                                     covariances=covariances)
    return figures.plot_map(positions, history, out / "map.png", title=title, notes=notes,
                            covariances=covariances)
